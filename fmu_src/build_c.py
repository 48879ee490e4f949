"""Build ``StrainControllerC.fmu``, the strain controller in C99: ``python -m drillcosim.fmu_src.build_c``.

The FMU is made from ``fmu_src/c_controller/`` (no Python at run time):

* ``modelDescription.xml`` - written by hand, the same variables as ``StrainController.fmu``;
* ``sources/`` - every file the binary is compiled from, in one flat folder (listed in
  ``<SourceFiles>``), so an importer on another platform can compile it (e.g.
  ``fmpy.util.compile_platform_binary``): ``model.c`` (the law), ``fmi2_cosimulation.c`` (the
  FMI 2.0 entry points), ``config.h``, ``model.h``, the registry of live handles and the FMU
  state format shared with the native wrapper (``fmu_src/wrapper/dcs_registry.c``/``.h``,
  ``dcs_state_format.c``/``.h``, one implementation each), the FMI 2.0 headers and
  ``dcs_build.h``, written at staging: the build identifier (:func:`fmu_src.build.build_hash` of
  the other sources and modelDescription.xml) that the FMU's serialized states carry;
* ``binaries/linux64/StrainControllerC.so`` - compiled from that very ``sources/`` folder (staged
  first) with the compiler and flags of the native wrapper (``$CC`` or ``gcc``,
  :data:`fmu_src.wrapper.CFLAGS`: ``-std=c99 -Wall -Wextra -Werror``), plus
  ``-ffp-contract=off`` so no multiply-add is fused (the Python law rounds every operation; with
  fusion the two would differ in the last bit on FMA hardware);
* ``documentation/licenses/fmi2-headers.txt`` - the headers' BSD-2-Clause license;
* ``resources/dcs_build.json`` - ``{"build": <the build identifier>}``, as the Python FMUs'.

A compiler warning is an error. The FMU is written atomically (temporary file + ``os.replace``).
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import sys
import tempfile
import zipfile
from collections.abc import Sequence
from pathlib import Path

__all__ = ["MODEL_IDENTIFIER", "SOURCE_DIR", "build_c_controller", "build_id", "compile_library",
           "main", "stage_sources"]

#: The C sources of the controller FMU.
SOURCE_DIR = Path(__file__).resolve().parent / "c_controller"
#: The native wrapper's folder: the registry of live handles and the FMI 2.0 headers.
WRAPPER_DIR = Path(__file__).resolve().parent / "wrapper"
MODEL_IDENTIFIER = "StrainControllerC"
#: The C files compiled (the ``<SourceFiles>`` of modelDescription.xml), by name in ``sources/``.
C_FILES = ("model.c", "fmi2_cosimulation.c", "dcs_registry.c", "dcs_state_format.c")
#: Every file of ``sources/`` and where it comes from (and ``dcs_build.h``, written).
SOURCES: dict[str, Path] = {
    **{n: SOURCE_DIR / n for n in ("model.c", "fmi2_cosimulation.c", "config.h", "model.h")},
    **{n: WRAPPER_DIR / n for n in ("dcs_registry.c", "dcs_registry.h", "dcs_state_format.c",
                                    "dcs_state_format.h")},
    **{n: WRAPPER_DIR / "fmi2" / n
       for n in ("fmi2Functions.h", "fmi2FunctionTypes.h", "fmi2TypesPlatform.h")},
}
EXTRA_CFLAGS = ("-ffp-contract=off",)


BUILD_HEADER = "dcs_build.h"


def stage_sources(dest: Path | str) -> Path:
    """Copy the files of the FMU's ``sources/`` (:data:`SOURCES`) into ``dest`` (created) and
    write ``dcs_build.h``: ``DCS_BUILD_ID``, the build identifier (:func:`build_id`).

    Returns
    -------
    pathlib.Path
        ``dest``.
    """
    dest = Path(dest)
    dest.mkdir(parents=True, exist_ok=True)
    for name, path in SOURCES.items():
        shutil.copyfile(path, dest / name)
    (dest / BUILD_HEADER).write_text(
        "/* Written by fmu_src/build_c.py: the build identifier its FMU states carry. */\n"
        f'#define DCS_BUILD_ID "{build_id()}"\n')
    return dest


def build_id() -> str:
    """The build identifier of the FMU: :func:`fmu_src.build.build_hash` of :data:`SOURCES`
    and modelDescription.xml (the same sources and interface give the same identifier)."""
    from drillcosim.fmu_src.build import build_hash

    with tempfile.TemporaryDirectory(prefix=f"{MODEL_IDENTIFIER}-id-") as tmp:
        folder = Path(tmp) / "sources"
        folder.mkdir()
        for name, path in {**SOURCES, "modelDescription.xml": SOURCE_DIR /
                           "modelDescription.xml"}.items():
            shutil.copyfile(path, folder / name)
        return build_hash([folder])


def compile_library(out: Path | str, cc: str | None = None, flags: Sequence[str] = (),
                    sources: Path | str | None = None) -> Path:
    """Compile the controller into the shared library ``out``.

    Parameters
    ----------
    out : path-like
        Target ``.so``.
    cc : str, optional
        C compiler (default ``$CC`` or ``gcc``).
    flags : sequence of str
        Extra compiler flags (e.g. sanitizers), after :data:`fmu_src.wrapper.CFLAGS` and
        ``-ffp-contract=off``.
    sources : path-like, optional
        A staged ``sources/`` folder (:func:`stage_sources`) to compile; default: one staged
        in a temporary folder.

    Returns
    -------
    pathlib.Path
        ``out``.

    Raises
    ------
    RuntimeError
        No compiler, or the compiler failed or printed a warning (its output included).
    """
    from drillcosim.fmu_src.wrapper import compile_shared

    if sources is None:
        with tempfile.TemporaryDirectory(prefix=f"{MODEL_IDENTIFIER}-sources-") as tmp:
            return compile_library(out, cc, flags, stage_sources(tmp))
    sources = Path(sources)
    return compile_shared(MODEL_IDENTIFIER, [sources / f for f in C_FILES], out,
                          flags=(*EXTRA_CFLAGS, f"-I{sources}", *flags),
                          libs=("-lm", "-lpthread"), cc=cc)


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
        sources = stage_sources(work / "sources")
        library = compile_library(work / f"{MODEL_IDENTIFIER}.so", cc, sources=sources)
        part = work / target.name
        with zipfile.ZipFile(part, "w", zipfile.ZIP_DEFLATED) as zf:
            zf.write(SOURCE_DIR / "modelDescription.xml", "modelDescription.xml")
            zf.write(library, f"binaries/linux64/{MODEL_IDENTIFIER}.so")
            for name in (*SOURCES, BUILD_HEADER):
                zf.write(sources / name, f"sources/{name}")
            zf.writestr("resources/dcs_build.json", json.dumps({"build": build_id()}) + "\n")
            zf.write(WRAPPER_DIR / "fmi2" / "LICENSE.txt", "documentation/licenses/fmi2-headers.txt")
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
