"""Import a package vendored into an FMU from a stable per-user copy (numba's cache needs one).

The compiled kernels and steps are numba functions with ``cache=True``; numba keys its cache by
the source path, and fmpy (like most importers) unzips every FMU into a new temporary folder,
which would recompile them (seconds) on every use. :func:`import_vendored` therefore copies the
vendored package once to a per-user folder named by its content hash,
``$DRILLCOSIM_CACHE/<name>-<sha256[:16]>/<name>/`` (default ``$XDG_CACHE_HOME/drillcosim`` or
``~/.cache/drillcosim``), and imports it from there. The copy is made in a temporary folder
beside it and renamed with ``os.replace`` (atomic; a concurrent creator that wins the race is
accepted). If the folder cannot be written, the package is imported from ``resources/``
(correct, only slower to start) and a warning is returned for the adapter to log.

Module-level code of an FMU reads no files of a particular unzip folder after import: the
wrapper imports a slave module once per process, and the first instance's folder may be deleted
while later instances run.
"""

from __future__ import annotations

import hashlib
import importlib
import importlib.util
import json
import os
import shutil
import sys
import tempfile
from collections.abc import Sequence
from pathlib import Path
from types import ModuleType

__all__ = ["cache_file", "cache_root", "import_vendored", "read_memo", "stable_copy",
           "write_atomic", "write_memo"]

_COMPLETE = "COMPLETE"  # marker written last into a stable copy


def _package_source(name: str, beside: str) -> Path:
    """Folder of the vendored package ``name``: beside the adapter file ``beside`` (the FMU's
    ``resources/``), or (at build time) in the staging folder the build puts on ``sys.path``.
    (Not beside this module: one copy of it serves every FMU of a process.)"""
    here = Path(beside).resolve().parent / name
    if (here / "__init__.py").is_file():
        return here
    for entry in sys.path:
        cand = Path(entry or ".") / name
        if (cand / "__init__.py").is_file():
            return cand.resolve()
    raise ImportError(f"vendored package {name} not found beside {beside}")


def _content_hash(src: Path) -> str:
    """SHA-256 (hex) over the relative paths and bytes of the package's ``.py`` files."""
    digest = hashlib.sha256()
    for path in sorted(src.rglob("*.py")):
        if "__pycache__" in path.parts:
            continue
        digest.update(path.relative_to(src).as_posix().encode() + b"\0")
        digest.update(path.read_bytes() + b"\0")
    return digest.hexdigest()


def cache_root() -> Path:
    """Per-user folder of the stable package copies: $DRILLCOSIM_CACHE or ~/.cache/drillcosim."""
    env = os.environ.get("DRILLCOSIM_CACHE")
    if env:
        return Path(env)
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(base) / "drillcosim"


def stable_copy(src: Path) -> Path:
    """Copy the package folder ``src`` once to ``cache_root()/<name>-<hash>/<name>/``; return
    the parent (to put on ``sys.path``).

    Raises
    ------
    OSError
        If the cache folder cannot be created or written.
    """
    name = src.name
    final = cache_root() / f"{name}-{_content_hash(src)[:16]}"
    if (final / _COMPLETE).is_file():
        return final
    final.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{final.name}-", dir=final.parent))
    try:
        # copyfile, not copy2: CPython 3.12+ copies with CopyFile2 on Windows, which wine 8
        # lacks (the process aborts there); the copy needs the bytes, not the file times
        shutil.copytree(src, tmp / name, ignore=shutil.ignore_patterns("__pycache__", "*.pyc"),
                        copy_function=shutil.copyfile)
        (tmp / _COMPLETE).write_text(str(src) + "\n")
        try:
            os.replace(tmp, final)
        except OSError:
            if not (final / _COMPLETE).is_file():  # not a lost race: a real problem
                raise
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return final


def import_vendored(name: str, beside: str, submodules: Sequence[str] = (),
                    only_with: str | None = None) -> tuple[ModuleType, str]:
    """Import the vendored package ``name`` (and its ``submodules``) from its stable copy.

    Parameters
    ----------
    name : str
        The vendored import name (``_dcs_<package>_<version>_<hash>``).
    beside : str
        The adapter's ``__file__``: the package lies beside it in ``resources/``.
    submodules : sequence of str
        Submodules imported with it.
    only_with : str, optional
        Make the stable copy only if this module can be imported (e.g. ``"numba"``: a package
        whose compiled code is optional needs no copy where it cannot compile); otherwise the
        package is imported from ``resources/``.

    Returns
    -------
    module, str
        The package and a warning for the instance to log ("" if none).
    """
    warning = ""
    if name not in sys.modules:
        src = _package_source(name, beside)
        base = src.parent
        if only_with is None or importlib.util.find_spec(only_with) is not None:
            try:
                base = stable_copy(src)
            except OSError as exc:
                warning = (f"cannot write the numba cache folder {cache_root()} ({exc}); "
                           f"importing {name} from {src.parent}: every new unzip folder "
                           f"recompiles the compiled code (set $DRILLCOSIM_CACHE)")
        sys.path.insert(0, str(base))
        try:
            importlib.import_module(name)
            for sub in submodules:
                importlib.import_module(f"{name}.{sub}")
        finally:
            sys.path.remove(str(base))  # submodules resolve through the package's __path__
    return sys.modules[name], warning


def cache_file(package: ModuleType, name: str) -> Path:
    """The file ``name`` beside the imported vendored ``package`` (in its stable copy's folder,
    which is named by the package's content hash: what it holds is of this code only)."""
    return Path(package.__file__).resolve().parent.parent / name


def read_memo(path: Path) -> dict[str, float]:
    """The ``{key: number}`` memo at ``path`` ({} if missing or unreadable: it is recomputed)."""
    try:
        data = json.loads(Path(path).read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return {}
    if not isinstance(data, dict):
        return {}
    return {k: float(v) for k, v in data.items() if isinstance(v, (int, float))}


def write_memo(path: Path, memo: dict[str, float]) -> bool:
    """Write ``memo`` to ``path`` atomically (floats round-trip); whether it was written."""
    return write_atomic(path, json.dumps(memo, sort_keys=True).encode())


def write_atomic(path: Path, data: bytes) -> bool:
    """Write ``data`` to ``path`` through a temporary file beside it and ``os.replace``
    (readers see the old file or the new one, never a part); whether it was written."""
    path = Path(path)
    try:
        fd, tmp = tempfile.mkstemp(prefix=f".{path.name}-", dir=path.parent)
        try:
            with os.fdopen(fd, "wb") as fh:
                fh.write(data)
            os.replace(tmp, path)
        finally:
            if os.path.exists(tmp):
                os.unlink(tmp)
    except OSError:
        return False
    return True
