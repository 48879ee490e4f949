"""Self-contained FMUs: ``drillcosim build --standalone`` (FMUs that carry their own Python).

A regular FMU of ours runs its model in a Python of the machine it runs on (the host's own in a
Python host, else one the wrapper finds: ``fmu_src/wrapper``). A *self-contained* FMU is the
same FMU with a Python runtime for each platform it carries in
``resources/dcs_runtime/<platform>/``: the interpreter, its standard library and the packages
its slave imports (:mod:`.linux64`: the building interpreter made relocatable; win64: the
embeddable CPython and the unpacked wheels), and a ``MANIFEST`` with every file's size and
SHA-256 (:mod:`.manifest`). Nothing is needed on the target but the FMI host.

Which Python runs the slave (the wrapper, ``dcs_python.c``):

* in a host without Python, the FMU's own runtime, tried before any other candidate; before
  anything of it is loaded, the MANIFEST and every file's size and SHA-256 are checked (once per
  process and runtime; the sizes again at each later instantiation): a missing or damaged file
  is ONE message and fmi2Instantiate returns NULL, never a crash in the loader nor an abort in
  ``Py_InitializeEx``. It is started with the environment ignored, no site module and
  ``sys.path`` its own;
* in a Python host (fmpy, libcosimpy), the host's interpreter with the host's packages, exactly
  as a regular FMU: the runtime is not loaded. One process cannot run two libpythons (both
  define the same C symbols; the extension modules bind to the first), and the runtime's
  compiled packages are built for its own interpreter's ABI, not the host's. The host must
  then have what ``resources/python_requires.txt`` lists;
* a second self-contained FMU in a process whose interpreter a first one started: its runtime
  joins when it is compatible (the same interpreter and standard library, every package both
  carry byte-identical: FMUs of one ``drillcosim build --standalone`` are), its ``sys.path``
  entries appended; otherwise its fmi2Instantiate fails with one line saying why (one process
  runs one Python).

The assembled runtime is cached per content (:func:`runtime_folder`: the building interpreter,
the shipped distributions' RECORDs, the selection and this package's code), so building
several FMUs, or building again, assembles it once.
"""

from __future__ import annotations

import hashlib
import json
import os
import shutil
import sys
import tempfile
import zipfile
from collections.abc import Sequence
from pathlib import Path

from drillcosim._toolchain import user_cache

from .manifest import MANIFEST, read_manifest
from .selection import IMPORTED, distributions

__all__ = ["PLATFORMS", "RUNTIME_DIR", "make_standalone", "runtime_folder", "runtimes"]

RUNTIME_DIR = "resources/dcs_runtime"  #: where an FMU carries its runtimes
PLATFORMS = ("linux64", "win64")       #: platforms a runtime can be made for
_HERE = Path(__file__).resolve().parent


def _runtime_key(platform: str, requires: Sequence[str]) -> str:
    """Content key of a runtime: what it is made of and how."""
    from .win64 import EMBEDDED, WHEELS

    digest = hashlib.sha256()
    digest.update(json.dumps([platform, sorted(requires), sys.version, sys.executable]).encode())
    if platform == "win64":
        digest.update(json.dumps([EMBEDDED, WHEELS]).encode())
    for dist in distributions(requires) if platform == "linux64" else ():
        record = dist.read_text("RECORD") or ""
        digest.update(f"{dist.metadata['Name']} {dist.version}\n".encode() + record.encode())
    for path in sorted(_HERE.glob("*.py")) + [IMPORTED]:
        digest.update(path.name.encode() + b"\0" + path.read_bytes())
    return digest.hexdigest()[:20]


def runtime_folder(platform: str, requires: Sequence[str]) -> Path:
    """The assembled runtime for ``platform`` and the modules ``requires``, from the cache
    (``<user cache>/runtimes/<platform>-<key>``), assembled first if missing (atomically).

    Raises
    ------
    ValueError
        A platform no runtime can be made for here.
    RuntimeError
        The runtime cannot be assembled (the reason in one line).
    """
    if platform not in PLATFORMS:
        raise ValueError(f"no self-contained runtime for platform {platform!r}: "
                         f"available {', '.join(PLATFORMS)}")
    from . import linux64, win64

    final = user_cache() / "runtimes" / f"{platform}-{_runtime_key(platform, requires)}"
    if (final / MANIFEST).is_file():
        return final
    final.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{final.name}-", dir=final.parent))
    try:
        if platform == "win64":
            summary = win64.assemble(tmp, tuple(requires), *win64.fetch())
        else:
            summary = linux64.assemble(tmp, tuple(requires))
        (tmp.parent / f"{final.name}.json").write_text(json.dumps(summary, indent=1) + "\n")
        try:
            os.replace(tmp, final)
        except OSError:
            if not (final / MANIFEST).is_file():
                raise
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return final


def make_standalone(fmu: Path | str, out: Path | str,
                    platforms: Sequence[str] | None = None, *,
                    compression: int = zipfile.ZIP_DEFLATED) -> Path:
    """Write ``out``: the FMU ``fmu`` with a Python runtime for each of ``platforms`` (default:
    every platform the FMU carries a binary for, ``binaries/<platform>/``).

    The modules the runtime must provide are the FMU's ``resources/python_requires.txt``; an
    FMU without one runs no Python (the C controller) and is copied as it is. ``compression``
    is the runtime members' zip method: deflated (what ``drillcosim build --standalone``
    ships), or ``zipfile.ZIP_STORED`` where the size does not matter (the tests: deflating
    the plant's 350 MB runtime is most of the time it takes to make the FMU).

    Returns
    -------
    Path
        ``out`` (written through a temporary file and renamed: atomic).
    """
    fmu, out = Path(fmu), Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    with zipfile.ZipFile(fmu) as src:
        if "resources/python_requires.txt" not in src.namelist():
            shutil.copyfile(fmu, out)
            return out
        requires = tuple(src.read("resources/python_requires.txt").decode().split())
        if platforms is None:
            platforms = [p for p in PLATFORMS
                         if any(n.startswith(f"binaries/{p}/") for n in src.namelist())]
        folders = {p: runtime_folder(p, requires) for p in platforms}
        fd, tmp = tempfile.mkstemp(prefix=f".{out.name}-", dir=out.parent)
        os.close(fd)
        mask = os.umask(0o022)
        os.umask(mask)
        os.chmod(tmp, 0o666 & ~mask)  # as a file written with open() would be
        try:
            with zipfile.ZipFile(tmp, "w", zipfile.ZIP_DEFLATED) as dst:
                for info in src.infolist():
                    if not info.filename.startswith(RUNTIME_DIR + "/"):
                        dst.writestr(info, src.read(info.filename),
                                     compress_type=zipfile.ZIP_DEFLATED)
                for platform, folder in folders.items():
                    for path in sorted(p for p in folder.rglob("*") if p.is_file()):
                        name = f"{RUNTIME_DIR}/{platform}/{path.relative_to(folder).as_posix()}"
                        dst.write(path, name, compress_type=compression)
            os.replace(tmp, out)
        finally:
            if os.path.exists(tmp):
                os.unlink(tmp)
    return out


def runtimes(fmu: Path | str) -> dict[str, dict[str, str]]:
    """The runtimes an FMU carries: platform -> its MANIFEST's items (``python``, ...) plus
    ``files`` and ``bytes`` (unpacked); {} for a regular FMU.

    Raises
    ------
    ValueError
        A MANIFEST that is damaged.
    """
    found: dict[str, dict[str, str]] = {}
    with zipfile.ZipFile(fmu) as zf:
        for name in zf.namelist():
            parts = name.split("/")
            if name.startswith(RUNTIME_DIR + "/") and len(parts) == 4 and parts[3] == MANIFEST:
                with tempfile.TemporaryDirectory() as tmp:
                    path = Path(tmp) / MANIFEST
                    path.write_bytes(zf.read(name))
                    items, files = read_manifest(path)
                info = dict(items)
                info["files"] = str(len(files))
                info["bytes"] = str(sum(size for _digest, size in files.values()))
                found[parts[2]] = info
    return found

