"""Arrays cached on disk by content, in the per-user cache folder.

Results that cost seconds and are a pure function of their inputs (a plant's linearization, an
open-loop baseline run) are kept in ``<user cache>/<kind>/<key>.npz``
(:func:`drillcosim._toolchain.user_cache`). The key is the SHA-256 of everything the result depends
on: the caller's identity (parameters, settings), the hash of the source code that computes it
(:func:`source_hash`) and the versions of numpy and scipy (their LAPACK decides the last bits).
Equal inputs give the same file; any change gives another one. A file is written atomically and
read with ``allow_pickle=False`` (loading it runs no code from it); a file that cannot be read,
or lacks an array, is computed again and replaced.
"""

from __future__ import annotations

import functools
import hashlib
import io
import json
import os
import tempfile
import zipfile
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

import numpy as np

from drillcosim._toolchain import user_cache
from drillcosim.cosim.master.files import atomic_write

__all__ = ["cache_key", "cached_arrays", "cached_file", "is_cached", "load_arrays",
           "source_hash"]


@functools.lru_cache(maxsize=32)
def source_hash(*paths: str) -> str:
    """Hash of the source files at ``paths`` (files, or folders: their files, caches left out),
    computed once per process."""
    from drillcosim.fmu_src.build import build_hash

    digest = hashlib.sha256()
    for p in map(Path, paths):
        if p.is_dir():
            digest.update(build_hash([p]).encode())
        else:
            digest.update(p.name.encode() + b"\0" + p.read_bytes() + b"\0")
    return digest.hexdigest()


def cache_key(ident: Any) -> str:
    """SHA-256 (hex) of ``ident`` (JSON; ``repr`` for what JSON cannot hold) and the numpy and
    scipy versions."""
    import scipy

    text = json.dumps([ident, np.__version__, scipy.__version__], sort_keys=True, default=repr)
    return hashlib.sha256(text.encode()).hexdigest()


def _path(kind: str, key: str) -> Path:
    return user_cache() / kind / f"{key}.npz"


def _load(path: Path) -> dict[str, np.ndarray] | None:
    """Every array of ``path`` (read in full: a damaged file fails here), or None."""
    try:
        with np.load(path, allow_pickle=False) as saved:
            return {name: saved[name] for name in saved.files}
    except (OSError, ValueError, KeyError, EOFError, zipfile.BadZipFile):
        return None             # missing, cut short or damaged


def _store(path: Path, arrays: Mapping[str, np.ndarray]) -> Path | None:
    buf = io.BytesIO()
    np.savez(buf, **{name: np.asarray(a) for name, a in arrays.items()})
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        return atomic_write(path, buf.getvalue())
    except OSError:             # a read-only cache: the result stands, uncached
        return None


def cached_arrays(kind: str, ident: Any, compute: Callable[[], Mapping[str, np.ndarray]]
                  ) -> dict[str, np.ndarray]:
    """The arrays ``compute()`` returns for ``ident``, from the cache or computed and stored.

    Parameters
    ----------
    kind : str
        Sub-folder of the cache (one per kind of result, e.g. ``"loop_models"``).
    ident : JSON-ready
        Everything the result depends on (include :func:`source_hash` of the code).
    compute : callable
        ``() -> {name: array}`` (numeric or structured arrays; no objects).

    Returns
    -------
    dict of str -> numpy.ndarray
    """
    path = _path(kind, cache_key(ident))
    got = _load(path)
    if got is None:
        got = {name: np.asarray(a) for name, a in compute().items()}
        _store(path, got)
    return got


def cached_file(kind: str, ident: Any, compute: Callable[[], Mapping[str, np.ndarray]]
                ) -> Path:
    """:func:`cached_arrays`, returning the file that holds them (for another process to read:
    :func:`load_arrays`); a read-only cache gets a temporary file."""
    path = _path(kind, cache_key(ident))
    if _load(path) is None:
        arrays = compute()
        if _store(path, arrays) is None:
            fd, name = tempfile.mkstemp(prefix=f"drillcosim_{kind}_", suffix=".npz")
            os.close(fd)
            path = Path(name)
            np.savez(path, **arrays)
    return path


def is_cached(kind: str, ident: Any) -> bool:
    """Does the cache hold a readable file for ``ident``?"""
    return _load(_path(kind, cache_key(ident))) is not None


def load_arrays(path: str | Path) -> dict[str, np.ndarray]:
    """The arrays of a file of :func:`cached_file` (no pickles: loading runs no code)."""
    got = _load(Path(path))
    if got is None:
        raise OSError(f"{path}: missing or damaged cache file")
    return got
