"""Build ``StrainControllerC.fmu``, the strain controller in C99: ``python -m drillcosim.fmu_src.build_c``.

The FMU is made from ``fmu_src/c_controller/`` (no Python at run time):

* ``modelDescription.xml`` - written by hand, the same variables as ``StrainController.fmu``;
* ``binaries/linux64/StrainControllerC.so`` - ``model.c`` (the law) and
  ``fmi2_cosimulation.c`` (the FMI 2.0 entry points) compiled with the compiler and flags of
  the native wrapper (``$CC`` or ``gcc``, :data:`fmu_src.wrapper.CFLAGS`: ``-std=c99 -Wall
  -Wextra -Werror``), plus ``-ffp-contract=off`` so no multiply-add is fused (the Python law
  rounds every operation; with fusion the two would differ in the last bit on FMA hardware);
* ``sources/`` - the C files and the FMI 2.0 headers (listed in ``<SourceFiles>``), so an
  importer on another platform can compile it (e.g. ``fmpy.util.compile_platform_binary``);
* ``documentation/licenses/fmi2-headers.txt`` - the headers' BSD-2-Clause license.

A compiler warning is an error. The FMU is written atomically (temporary file + ``os.replace``).
"""

from __future__ import annotations

import argparse
import os
import shutil
import sys
import tempfile
import zipfile
from collections.abc import Sequence
from pathlib import Path

__all__ = ["MODEL_IDENTIFIER", "SOURCE_DIR", "build_c_controller", "main"]

#: The C sources of the controller FMU.
SOURCE_DIR = Path(__file__).resolve().parent / "c_controller"
MODEL_IDENTIFIER = "StrainControllerC"
C_FILES = ("model.c", "fmi2_cosimulation.c")
HEADERS = ("config.h", "model.h")
FMI_HEADERS = ("fmi2Functions.h", "fmi2FunctionTypes.h", "fmi2TypesPlatform.h")
EXTRA_CFLAGS = ("-ffp-contract=off",)


def compile_library(out: Path | str, cc: str | None = None) -> Path:
    """Compile the controller into the shared library ``out``.

    Parameters
    ----------
    out : path-like
        Target ``.so``.
    cc : str, optional
        C compiler (default ``$CC`` or ``gcc``).

    Returns
    -------
    pathlib.Path
        ``out``.

    Raises
    ------
    RuntimeError
        No compiler, or the compiler failed or printed a warning (its output included).
    """
    from drillcosim.fmu_src.wrapper import HERE as WRAPPER_DIR
    from drillcosim.fmu_src.wrapper import compile_shared

    return compile_shared(MODEL_IDENTIFIER, [SOURCE_DIR / f for f in C_FILES], out,
                          flags=(*EXTRA_CFLAGS, f"-I{WRAPPER_DIR / 'fmi2'}"), libs=("-lm",),
                          cc=cc)


def build_c_controller(out_dir: Path | str, cc: str | None = None) -> Path:
    """Build ``StrainControllerC.fmu`` into ``out_dir`` (created if missing).

    Returns
    -------
    pathlib.Path
        The FMU.
    """
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    target = out_dir / f"{MODEL_IDENTIFIER}.fmu"
    work = Path(tempfile.mkdtemp(prefix=f".{MODEL_IDENTIFIER}-", dir=out_dir))
    try:
        library = compile_library(work / f"{MODEL_IDENTIFIER}.so", cc)
        part = work / target.name
        with zipfile.ZipFile(part, "w", zipfile.ZIP_DEFLATED) as zf:
            zf.write(SOURCE_DIR / "modelDescription.xml", "modelDescription.xml")
            zf.write(library, f"binaries/linux64/{MODEL_IDENTIFIER}.so")
            for name in (*C_FILES, *HEADERS):
                zf.write(SOURCE_DIR / name, f"sources/{name}")
            fmi2 = Path(__file__).resolve().parent / "wrapper" / "fmi2"  # the official headers
            for name in FMI_HEADERS:  # beside the C files: #include "fmi2Functions.h" resolves
                zf.write(fmi2 / name, f"sources/{name}")
            zf.write(fmi2 / "LICENSE.txt", "documentation/licenses/fmi2-headers.txt")
        os.replace(part, target)
    finally:
        shutil.rmtree(work, ignore_errors=True)
    return target


def main(argv: Sequence[str] | None = None) -> int:
    """Command-line entry point; returns the exit status."""
    from drillcosim.fmu_src.build import default_out

    parser = argparse.ArgumentParser(prog="python -m drillcosim.fmu_src.build_c",
                                     description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=None,
                        help="output folder (default: the FMU folder of `drillcosim build`)")
    args = parser.parse_args(argv)
    try:
        path = build_c_controller(args.out or default_out())
    except RuntimeError as exc:
        print(f"python -m drillcosim.fmu_src.build_c: {exc}", file=sys.stderr)
        return 1
    print(f"built {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
