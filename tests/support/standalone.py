"""Self-contained FMUs for the tests: made once per content, unzipped once per session.

:func:`standalone_copy` writes the self-contained copy of a built FMU into a cache keyed by
the FMU's content (every member's bytes, not the zip's times) and the runtime's content key
(:func:`drillcosim.fmu_src.standalone.runtime_folder` caches the runtime itself): a test session
whose FMUs and building Python did not change reuses the copies of the one before.
"""

from __future__ import annotations

import hashlib
import os
import shutil
import zipfile
from pathlib import Path

from drillcosim._toolchain import user_cache
from drillcosim.fmu_src.standalone import make_standalone, runtime_folder

__all__ = ["bare_env", "content_key", "linked_copy", "standalone_copy"]


def content_key(fmu: Path) -> str:
    """SHA-256 over the FMU's member names and bytes (not the zip's metadata)."""
    digest = hashlib.sha256()
    with zipfile.ZipFile(fmu) as zf:
        for name in sorted(zf.namelist()):
            digest.update(name.encode() + b"\0" + zf.read(name) + b"\0")
    return digest.hexdigest()[:20]


def standalone_copy(fmu: Path, platforms: tuple[str, ...] = ("linux64",)) -> Path:
    """The self-contained copy of ``fmu`` with runtimes for ``platforms`` (cached by content;
    its runtime members stored, not deflated: the FMU is read the same way, and zipped ~10x
    faster: the controller's 100 MB runtime took 0.5 s of CPU stored, 6.0 s deflated)."""
    with zipfile.ZipFile(fmu) as zf:
        requires = tuple(zf.read("resources/python_requires.txt").decode().split())
    runtime = "-".join(runtime_folder(p, requires).name for p in platforms)
    out = user_cache() / "test-standalone" / f"{content_key(fmu)}-{runtime}-stored" / fmu.name
    if not out.is_file():  # the runtime stored, not deflated: the zip is made in seconds
        make_standalone(fmu, out, platforms, compression=zipfile.ZIP_STORED)
    return out


def linked_copy(src: Path, dst: Path) -> Path:
    """A copy of the folder ``src`` made of hard links (fast; replace a file before changing
    it: writing through a link changes the original)."""
    shutil.copytree(src, dst, copy_function=os.link)
    return dst


def bare_env(home: Path, **extra: str) -> dict[str, str]:
    """An environment with no Python anywhere: PATH an empty folder, no PYTHONHOME,
    PYTHONPATH or LD_LIBRARY_PATH; the numba and drillcosim caches of this session kept (they
    hold compiled code, not Python)."""
    empty = home / "empty-path"
    empty.mkdir(parents=True, exist_ok=True)
    env = {"HOME": str(home), "PATH": str(empty), "LANG": "C.UTF-8",
           "DRILLCOSIM_CACHE": str(user_cache())}
    if os.environ.get("NUMBA_CACHE_DIR"):
        env["NUMBA_CACHE_DIR"] = os.environ["NUMBA_CACHE_DIR"]
    env.update(extra)
    return env
