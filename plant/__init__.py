"""drillcosim: plant package.

Importing the package first drops numba's on-disk cache of this package when any of its sources
changed. numba (``njit(cache=True)``) keys a cached function on its own file's timestamp only,
while a caller's cached machine code contains the callees it inlined or linked from other files:
after an edit to ``kernels.py`` the cached integrators in ``integrators.py`` would go on running
the old right-hand side. One hash over all sources of the package decides instead.
"""

from __future__ import annotations

import hashlib
import os
from pathlib import Path


def drop_stale_numba_cache(package_dir: Path, depends_on: tuple[Path, ...] = ()) -> None:
    """Delete ``package_dir/__pycache__/*.nbi|*.nbc`` unless they were built from the current
    sources of ``package_dir`` and of the packages in ``depends_on`` (whose compiled functions
    the package's cached machine code inlines or links, e.g. the analysis package's numba
    functions calling this package's kernels).

    Best effort: a read-only tree is left alone (numba then caches elsewhere or not at all).
    """
    digest = hashlib.sha256()
    for folder in (package_dir, *depends_on):
        for src in sorted(folder.glob("*.py")):
            digest.update(src.name.encode())
            digest.update(src.read_bytes())
    stamp_value = digest.hexdigest()
    cache = package_dir / "__pycache__"
    stamp = cache / "numba_sources.sha256"
    try:
        if stamp.read_text() == stamp_value:
            return
    except OSError:
        pass
    try:
        for f in list(cache.glob("*.nbi")) + list(cache.glob("*.nbc")):
            f.unlink(missing_ok=True)
        cache.mkdir(exist_ok=True)
        tmp = cache / f".numba_sources.{os.getpid()}.tmp"
        tmp.write_text(stamp_value)
        os.replace(tmp, stamp)
    except OSError:
        pass


_drop_stale_numba_cache = drop_stale_numba_cache  # the name the cache guard's tests use
drop_stale_numba_cache(Path(__file__).resolve().parent)
