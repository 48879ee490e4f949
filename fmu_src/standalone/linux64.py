"""The linux64 runtime of a self-contained FMU: the building interpreter, made relocatable.

What is copied, and where (the runtime folder is ``resources/dcs_runtime/linux64/``):

* ``lib/<INSTSONAME>``: the building interpreter's shared libpython (a Python built without
  ``--enable-shared`` has none: the build says so and stops);
* ``lib/python3X.zip``: its standard library, compiled to ``.pyc`` (sourceless, as the
  Windows embeddable distribution ships it; stored, not deflated, so the interpreter needs no
  zlib to start), without the folders no FMU imports (:data:`STDLIB_EXCLUDED`);
* ``lib/python3.X/lib-dynload/``: its extension modules but those in
  :data:`EXTENSIONS_DROPPED` (optional ones whose standard-library users fall back without
  them, and ones that link libraries a target may lack);
* ``lib/python3.X/site-packages/``: the distributions the FMU requires and what they require,
  the files :mod:`.selection` picks, each ``.py`` with a ``__pycache__`` ``.pyc`` compiled
  with unchecked hashes (a zip's extraction changes file times, which would make timestamp
  ``.pyc`` files stale and recompiled at every start);
* ``lib/``: the shared libraries the shipped extension modules link that are neither shipped
  beside them (``<name>.libs``) nor part of the baseline every Linux has (:data:`BASELINE`:
  glibc's libraries, libgcc_s, libstdc++: the manylinux policy's list); the wrapper loads them
  before the interpreter (``preload`` lines), so the extension modules find them by soname.

The interpreter is started with ``home`` = the runtime folder (``sys.prefix``), the environment
ignored and no site module (the wrapper, ``dcs_python.c``); ``sys.path`` is the zip, the
``lib-dynload`` folder and ``site-packages`` (a ``path`` line of the MANIFEST). The target needs
a glibc at least as new as the building machine's (the copied files link against it).
"""

from __future__ import annotations

import compileall
import hashlib
import importlib.metadata as metadata
import json
import os
import py_compile
import re
import shutil
import subprocess
import sys
import sysconfig
import tempfile
import zipfile
from pathlib import Path

from drillcosim._toolchain import user_cache

from .manifest import write_manifest
from .selection import distributions, imported_packages, select

__all__ = ["BASELINE", "EXTENSIONS_DROPPED", "PACKAGE_FILES_DROPPED", "STDLIB_EXCLUDED",
           "assemble"]

#: Libraries every Linux target has (the manylinux policy's baseline); never shipped.
BASELINE = frozenset({
    "linux-vdso.so.1", "ld-linux-x86-64.so.2", "libc.so.6", "libm.so.6", "libdl.so.2",
    "librt.so.1", "libpthread.so.0", "libutil.so.1", "libresolv.so.2", "libnsl.so.1",
    "libgcc_s.so.1", "libstdc++.so.6"})

#: Standard-library folders (first component) that no FMU imports.
STDLIB_EXCLUDED = frozenset({
    "test", "idlelib", "tkinter", "turtledemo", "ensurepip", "lib2to3", "pydoc_data",
    "site-packages", "dist-packages", "distutils", "venv", "sqlite3", "dbm", "curses",
    "__pycache__"})

#: Extension modules not shipped (name before the first dot), and why.
EXTENSIONS_DROPPED: dict[str, str] = {
    "_hashlib": "hashlib falls back to its own _sha2/_md5/_blake2 without libcrypto",
    "_ssl": "no network; links libssl",
    "_bz2": "optional in shutil/tarfile/zipfile; links libbz2",
    "_lzma": "optional in shutil/tarfile/zipfile; links liblzma",
    "_uuid": "optional in uuid; links libuuid",
    "_sqlite3": "sqlite3 is not shipped",
    "_tkinter": "tkinter is not shipped",
    "readline": "interactive only", "_curses": "interactive only",
    "_curses_panel": "interactive only", "_dbm": "dbm is not shipped",
    "_gdbm": "dbm is not shipped", "nis": "system databases", "spwd": "system databases",
    "_crypt": "links libcrypt", "ossaudiodev": "audio", "audioop": "audio",
}
#: Files of the shipped distributions left out (a prefix of their path), and why.
PACKAGE_FILES_DROPPED: dict[str, str] = {
    "numba/np/ufunc/tbbpool": "numba's TBB threading layer (parallel=True only); links libtbb",
    "numba/np/ufunc/omppool": "numba's OpenMP threading layer (parallel=True only); links "
                              "libgomp",
}
_TEST_EXTENSIONS = re.compile(r"^(_test|_xx|xx|_ctypes_test)")


def _ldd(path: Path) -> dict[str, str]:
    """soname -> resolved path of every library ``path`` needs (``ldd``; "" if not found)."""
    proc = subprocess.run(["ldd", str(path)], capture_output=True, text=True)
    found = {}
    for line in proc.stdout.splitlines():
        match = re.match(r"\s*(\S+)\s+=>\s+(\S+)?", line)
        if match:
            found[match.group(1)] = match.group(2) if match.group(2) != "not" else ""
    return found


def _compile_stdlib(stdlib: Path, target: Path) -> None:
    """The standard library as sourceless ``.pyc`` files in the zip ``target`` (stored)."""
    with zipfile.ZipFile(target, "w", zipfile.ZIP_STORED) as zf, \
            tempfile.TemporaryDirectory() as tmp:
        for src in sorted(stdlib.rglob("*.py")):
            rel = src.relative_to(stdlib)
            if rel.parts[0] in STDLIB_EXCLUDED or "__pycache__" in rel.parts or \
                    rel.parts[0].startswith(("config-", "lib-dynload")):
                continue
            out = Path(tmp) / "m.pyc"
            try:
                py_compile.compile(str(src), cfile=str(out), dfile=rel.as_posix(),
                                   doraise=True,
                                   invalidation_mode=py_compile.PycInvalidationMode.UNCHECKED_HASH)
            except py_compile.PyCompileError:
                continue  # e.g. lib2to3's test data: not importable code
            info = zipfile.ZipInfo(rel.with_suffix(".pyc").as_posix(), (1980, 1, 1, 0, 0, 0))
            info.external_attr = 0o644 << 16
            zf.writestr(info, out.read_bytes())


def _copy(src: Path, dst: Path) -> None:
    dst.parent.mkdir(parents=True, exist_ok=True)
    shutil.copyfile(src, dst)
    shutil.copymode(src, dst)


def _part(name: str, key_text: str, build) -> Path:
    """A cached part of runtimes (``<user cache>/runtimes/parts/<name>-<key>``): built once by
    ``build(folder)`` and copied into every runtime that needs it, so that equal parts are
    equal bytes in every FMU (what lets two self-contained FMUs share one interpreter)."""
    digest = hashlib.sha256(key_text.encode())
    for path in sorted(Path(__file__).resolve().parent.glob("*.py")):
        digest.update(path.read_bytes())
    final = user_cache() / "runtimes" / "parts" / f"{name}-{digest.hexdigest()[:16]}"
    if (final / ".complete").is_file():
        return final
    final.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{final.name}-", dir=final.parent))
    try:
        build(tmp)
        (tmp / ".complete").write_text(key_text + "\n")
        try:
            os.replace(tmp, final)
        except OSError:
            if not (final / ".complete").is_file():
                raise
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return final


def _libpython() -> tuple[Path, str]:
    libdir = Path(sysconfig.get_config_var("LIBDIR") or "")
    soname = sysconfig.get_config_var("INSTSONAME") or ""
    libpython = libdir / soname
    if ".so" not in soname or not libpython.is_file():
        raise RuntimeError(f"the building Python ({sys.executable}) has no shared libpython "
                           f"(looked for {libpython}): build the self-contained FMUs with a "
                           f"Python built with --enable-shared (Debian's python3, pyenv with "
                           f"PYTHON_CONFIGURE_OPTS=--enable-shared)")
    return libpython, soname


def _build_base(root: Path) -> None:
    """The interpreter: libpython, the standard library zip, its licence, lib-dynload."""
    version = f"{sys.version_info[0]}.{sys.version_info[1]}"
    libpython, soname = _libpython()
    stdlib_dir = root / "lib" / f"python{version}"
    _copy(libpython, root / "lib" / soname)
    stdlib = Path(sysconfig.get_paths()["stdlib"])
    _compile_stdlib(stdlib, root / "lib" / f"python{version.replace('.', '')}.zip")
    if (stdlib / "LICENSE.txt").is_file():
        _copy(stdlib / "LICENSE.txt", stdlib_dir / "LICENSE.txt")
    dynload = Path(sysconfig.get_config_var("DESTSHARED") or stdlib / "lib-dynload")
    for ext in sorted(dynload.glob("*.so")):
        name = ext.name.split(".")[0]
        if name not in EXTENSIONS_DROPPED and not _TEST_EXTENSIONS.match(name):
            _copy(ext, stdlib_dir / "lib-dynload" / ext.name)


def _build_distribution(root: Path, dist: metadata.Distribution) -> None:
    """The selected files of one distribution under ``root/<site-packages>``, compiled."""
    site = root / _site_packages()
    base = Path(dist.locate_file(""))
    for rel in select((str(f) for f in dist.files or []), imported_packages(),
                      lambda rel: (base / rel).read_bytes()):
        if not rel.startswith(tuple(PACKAGE_FILES_DROPPED)):
            _copy(base / rel, site / rel)
    compileall.compile_dir(str(site), quiet=2, workers=1, ddir="",
                           invalidation_mode=py_compile.PycInvalidationMode.UNCHECKED_HASH)


def _site_packages() -> str:
    return f"lib/python{sys.version_info[0]}.{sys.version_info[1]}/site-packages"


def assemble(root: Path, requires: tuple[str, ...]) -> dict[str, object]:
    """Write the linux64 runtime for the modules ``requires`` into the empty folder ``root``
    and its MANIFEST; return a summary (Python, packages, bundled libraries).

    The runtime is made of cached parts (:func:`_part`): the interpreter, and each shipped
    distribution.

    Raises
    ------
    RuntimeError
        The building interpreter has no shared libpython, or a shipped extension module needs
        a library that cannot be found.
    """
    libpython, soname = _libpython()
    st = libpython.stat()
    parts = [_part("python", json.dumps([sys.version, sys.executable, str(libpython),
                                         st.st_size, st.st_mtime_ns]), _build_base)]
    shipped = {}
    for dist in distributions(requires):
        name = dist.metadata["Name"]
        shipped[name] = dist.version
        record = hashlib.sha256((dist.read_text("RECORD") or "").encode()).hexdigest()
        parts.append(_part(f"{name}-{dist.version}", json.dumps(
            [sys.version, name, dist.version, record, sorted(imported_packages())]),
            lambda folder, d=dist: _build_distribution(folder, d)))
    for part in parts:
        shutil.copytree(part, root, dirs_exist_ok=True,
                        ignore=shutil.ignore_patterns(".complete"))
    # the libraries the shipped ELF files need beyond the baseline and the runtime itself
    lib, site = root / "lib", root / _site_packages()
    preload: dict[str, Path] = {}
    site_real = str(site.resolve())
    # (a library of a <name>.libs folder is reached through the extension modules' RPATH)
    for elf in sorted(p for p in root.rglob("*.so*")
                      if p.is_file() and not p.parent.name.endswith(".libs")):
        for name, where in _ldd(elf).items():
            if name in BASELINE or name in preload or (lib / name).exists():
                continue
            if where and str(Path(where).resolve()).startswith(site_real):
                continue
            if not where:
                raise RuntimeError(f"{elf.name} needs {name}, which is not found")
            preload[name] = Path(where)
    for name, where in preload.items():
        _copy(where, lib / name)
    items = [("platform", "linux64"), ("python", sys.version.split()[0]),
             ("library", f"lib/{soname}"), ("program", "bin/python3"), ("home", ".")]
    items += [("preload", f"lib/{name}") for name in preload]
    items += [("path", _site_packages()), ("site", _site_packages())]
    write_manifest(root, items)
    return {"python": sys.version.split()[0], "packages": shipped,
            "bundled_libraries": sorted(preload)}
