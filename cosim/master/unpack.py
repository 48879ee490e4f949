"""Where FMUs are unpacked: once per content, in the user cache, shared by every run.

An FMU is unpacked into ``<user cache>/unpacked/<hash of the file>/`` (written to a temporary
folder beside it and renamed into place, so a folder under its final name is always complete;
concurrent first uses each unpack, one rename wins). Later runs of the same file reuse it:
no unzipping, and Python's byte-code caches of a pythonfmu FMU's sources (``resources/``) are
written there once instead of the sources being compiled at every start. Nothing is deleted
after a run; folders unused for a week beyond the newest :data:`KEEP` are pruned. Where the
cache cannot be written, an FMU is unpacked into a temporary folder the caller deletes
(:func:`unpack` says which).
"""

from __future__ import annotations

import hashlib
import logging
import os
import shutil
import tempfile
import time
import zipfile
from pathlib import Path

from drillcosim._toolchain import user_cache

__all__ = ["KEEP", "unpack"]

#: Unpacked FMUs always kept (the most recently used).
KEEP = 32
_WEEK = 7 * 24 * 3600.0
_log = logging.getLogger(__name__)


def _digest(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()[:24]


def _prune(root: Path) -> None:
    """Delete folders unused for a week beyond the newest :data:`KEEP` (errors ignored)."""
    try:
        entries = sorted((e for e in os.scandir(root) if e.is_dir() and not
                          e.name.startswith(".")), key=lambda e: e.stat().st_mtime, reverse=True)
        now = time.time()
        for e in entries[KEEP:]:
            if now - e.stat().st_mtime > _WEEK:
                shutil.rmtree(e.path, ignore_errors=True)
    except OSError:
        pass


def unpack(fmu: str | Path) -> tuple[str, bool]:
    """Unpack ``fmu``; return ``(folder, owned)``.

    ``owned`` is True when the folder is a temporary one the caller must delete (the cache is
    not writable), False for the shared cache folder (leave it).

    Raises
    ------
    OSError, zipfile.BadZipFile
        The file cannot be read or is not a zip archive.
    """
    path = Path(fmu)
    root = user_cache() / "unpacked"
    try:
        target = root / _digest(path)
        if (target / "modelDescription.xml").is_file():
            os.utime(target)                   # recently used: kept by the pruning
            return str(target), False
        root.mkdir(parents=True, exist_ok=True)
        tmp = Path(tempfile.mkdtemp(prefix=".unpack-", dir=root))
    except OSError as exc:
        _log.debug("FMU cache %s not usable (%s): unpacking to a temporary folder", root, exc)
        return _unpack_temporary(path), True
    try:
        with zipfile.ZipFile(path) as zf:
            zf.extractall(tmp)
        os.rename(tmp, target)
    except OSError:
        if (target / "modelDescription.xml").is_file():    # another process was first
            shutil.rmtree(tmp, ignore_errors=True)
            return str(target), False
        if not (tmp / "modelDescription.xml").is_file():   # not unpacked at all
            shutil.rmtree(tmp, ignore_errors=True)
            raise
        return str(tmp), True                  # a broken cache folder: use our own copy
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    _prune(root)
    return str(target), False


def _unpack_temporary(path: Path) -> str:
    folder = tempfile.mkdtemp(prefix="fmu_")
    with zipfile.ZipFile(path) as zf:
        zf.extractall(folder)
    return folder
