"""Build ``StrainControllerC.fmu``, the strain controller in C99: ``python -m drillcosim.fmu_src.build_c``.

The FMU is made from ``fmu_src/c_controller/`` (no Python at run time):

* ``modelDescription.xml`` - written by hand, the same variables as ``StrainController.fmu``;
* ``sources/`` - every file the binary is compiled from, in one flat folder (listed in
  ``<SourceFiles>``), so an importer on another platform can compile it (e.g.
  ``fmpy.util.compile_platform_binary``): ``model.c`` (the law), ``fmi2_cosimulation.c`` (the
  FMI 2.0 entry points), ``config.h``, ``model.h``, the registry of live handles and the FMU
  state format shared with the native wrapper (``fmu_src/wrapper/dcs_registry.c``/``.h``,
  ``dcs_lock.h``, ``dcs_state_format.c``/``.h``, one implementation each), the FMI 2.0 headers
  and ``dcs_build.h``, written at staging: the build identifier (:func:`fmu_src.build.build_hash`
  of the other sources and modelDescription.xml) that the FMU's serialized states carry;
* ``binaries/linux64/StrainControllerC.so`` and ``binaries/win64/StrainControllerC.dll`` (the
  platforms of :func:`fmu_src.platforms.select`: by default every one whose compiler is found) -
  compiled from that very ``sources/`` folder (staged first) with the compilers and flags of the
  native wrapper (``$CC`` or ``gcc``; mingw-w64 for win64; :data:`fmu_src.wrapper.CFLAGS`:
  ``-std=c99 -Wall -Wextra -Werror``), plus ``-ffp-contract=off`` so no multiply-add is fused
  (the Python law rounds every operation; with fusion the two would differ in the last bit on
  FMA hardware);
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

from drillcosim.fmu_src.platforms import Selection, select

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
    **{n: WRAPPER_DIR / n for n in ("dcs_registry.c", "dcs_registry.h", "dcs_lock.h",
                                    "dcs_state_format.c", "dcs_state_format.h")},
    **{n: WRAPPER_DIR / "fmi2" / n
       for n in ("fmi2Functions.h", "fmi2FunctionTypes.h", "fmi2TypesPlatform.h")},
}
EXTRA_CFLAGS = ("-ffp-contract=off",)


BUILD_HEADER = "dcs_build.h"


def _platforms(names: str | Sequence[str] | None) -> Selection:
    """:func:`fmu_src.platforms.select`, no compiler for this machine a RuntimeError."""
    try:
        return select(names)
    except ValueError as exc:
        if names is not None:
            raise
        raise RuntimeError(f"building {MODEL_IDENTIFIER} needs a C compiler: {exc}") from None


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
                    sources: Path | str | None = None, platform: str = "linux64") -> Path:
    """Compile the controller into the shared library ``out``.

    Parameters
    ----------
    out : path-like
        Target ``.so`` (``.dll``).
    cc : str, optional
        C compiler (default: the platform's, ``$CC`` or ``gcc`` for linux64).
    flags : sequence of str
        Extra compiler flags (e.g. sanitizers), after :data:`fmu_src.wrapper.CFLAGS` and
        ``-ffp-contract=off``.
    sources : path-like, optional
        A staged ``sources/`` folder (:func:`stage_sources`) to compile; default: one staged
        in a temporary folder.
    platform : str
        ``linux64`` (default) or ``win64`` (:mod:`fmu_src.platforms`).

    Returns
    -------
    pathlib.Path
        ``out``.

    Raises
    ------
    RuntimeError
        No compiler, or the compiler failed or printed a warning (its output included).
    """
    from drillcosim.fmu_src.platforms import PLATFORMS
    from drillcosim.fmu_src.wrapper import compile_shared

    if sources is None:
        with tempfile.TemporaryDirectory(prefix=f"{MODEL_IDENTIFIER}-sources-") as tmp:
            return compile_library(out, cc, flags, stage_sources(tmp), platform)
    sources = Path(sources)
    target = PLATFORMS[platform]
    return compile_shared(f"{MODEL_IDENTIFIER} ({platform})", [sources / f for f in C_FILES], out,
                          flags=(*target.flags, *EXTRA_CFLAGS, f"-I{sources}", *flags),
                          libs=target.c_libs, cc=cc or target.cc)


def build_c_controller(out_dir: Path | str, cc: str | None = None,
                       platforms: Selection | str | Sequence[str] | None = None) -> Path:
    """Build ``StrainControllerC.fmu`` into ``out_dir`` (created if missing).

    Parameters
    ----------
    out_dir : path-like
    cc : str, optional
        The compiler of the linux64 binary (default ``$CC`` or ``gcc``).
    platforms : Selection, str or sequence of str, optional
        Binary platforms (default: every one whose compiler is found).

    Returns
    -------
    pathlib.Path
        The FMU.

    Raises
    ------
    RuntimeError
        No compiler for this machine, or a compiler failed or warned.
    """
    selection = platforms if isinstance(platforms, Selection) else _platforms(platforms)
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    target = out_dir / f"{MODEL_IDENTIFIER}.fmu"
    work = Path(tempfile.mkdtemp(prefix=f".{MODEL_IDENTIFIER}-", dir=out_dir))
    try:
        sources = stage_sources(work / "sources")
        libraries = {p: compile_library(work / f"{MODEL_IDENTIFIER}-{p.name}{p.suffix}",
                                        cc if p.name == "linux64" else None, sources=sources,
                                        platform=p.name)
                     for p in selection.platforms}
        part = work / target.name
        with zipfile.ZipFile(part, "w", zipfile.ZIP_DEFLATED) as zf:
            zf.write(SOURCE_DIR / "modelDescription.xml", "modelDescription.xml")
            for platform, library in libraries.items():
                zf.write(library, platform.library_name(MODEL_IDENTIFIER))
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
    parser.add_argument("--platforms", default=None, metavar="LIST",
                        help="binary platforms, comma-separated (linux64,win64); default: "
                        "every one whose C compiler is found")
    args = parser.parse_args(argv)
    try:
        selection = _platforms(args.platforms)
    except ValueError as exc:
        parser.error(str(exc))
    try:
        path = build_c_controller(args.out or default_out(), platforms=selection)
    except RuntimeError as exc:
        print(f"python -m drillcosim.fmu_src.build_c: {exc}", file=sys.stderr)
        return 1
    print(f"built {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
