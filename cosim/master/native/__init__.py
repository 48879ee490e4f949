"""The master's stepping loop in C (``steps.c``; and the recorder's CSV text, ``rows.c``),
and how it is built and loaded.

:class:`~.runner.NativeLoop` runs chunks of base steps of an
:class:`~cosim.master.execution.Execution` in C, calling the components' C entry points (an
FMU's ``fmi2SetReal`` / ``fmi2DoStep`` / ``fmi2GetReal``, or a compiled step) with the
algorithm, delay lines and recording of the Python loop, operation for operation: both give
the same numbers bit for bit. The execution chooses it where it applies
(:meth:`~.runner.NativeLoop.for_execution`); Python runs between chunks (progress,
manipulators, recording flush, errors).

The library is compiled at first use with the system C compiler
(:func:`drillcosim._toolchain.compile_shared`) into the user cache, named by a hash of its
source and flags (``<user cache>/master/dcs_steps-<hash>.so``), and loaded with ctypes. Without
a compiler the Python loop runs (a warning is logged once). ``DRILLCOSIM_MASTER_LOOP=python``
in the environment also selects the Python loop.
"""

from __future__ import annotations

import ctypes
import hashlib
import logging
import os
import tempfile
from pathlib import Path

from drillcosim._toolchain import CFLAGS, compile_shared, user_cache

__all__ = ["SOURCE", "SOURCES", "library", "library_path"]

SOURCE = Path(__file__).resolve().with_name("steps.c")
#: every C file of the library: the stepping loop and the recorder's CSV rows (``rows.c``)
SOURCES = (SOURCE, SOURCE.with_name("rows.c"))
#: no fused multiply-add: the C expressions round exactly as Python's
FLAGS = ("-ffp-contract=off",)
LIBS = ("-lm",)
_log = logging.getLogger(__name__)
_loaded: dict[str, ctypes.CDLL | None] = {}


def library_path() -> Path:
    """Where the compiled library of this source and these flags lives in the user cache."""
    digest = hashlib.sha256()
    for source in SOURCES:
        digest.update(source.read_bytes())
    digest.update("\0".join((*CFLAGS, *FLAGS, *LIBS, os.environ.get("CC") or "gcc")).encode())
    return user_cache() / "master" / f"dcs_steps-{digest.hexdigest()[:16]}.so"


def _build(target: Path) -> None:
    target.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=".dcs_steps-", suffix=".so", dir=target.parent)
    os.close(fd)
    try:
        compile_shared("the master's native stepping loop", SOURCES, tmp, flags=FLAGS,
                       libs=LIBS)
        os.replace(tmp, target)       # atomic: concurrent first uses each write their own
    finally:
        if os.path.exists(tmp):
            os.unlink(tmp)


def library() -> ctypes.CDLL | None:
    """The loaded library (built at first use), or None where it cannot be built."""
    path = library_path()
    key = str(path)
    if key not in _loaded:
        lib = None
        try:
            if not path.is_file():
                _build(path)
            lib = ctypes.CDLL(key)
            lib.dcs_run_steps.argtypes = (ctypes.c_void_p, ctypes.c_int64)
            lib.dcs_run_steps.restype = ctypes.c_int
            lib.dcs_format_rows.argtypes = (ctypes.c_void_p, ctypes.c_int64, ctypes.c_int32,
                                            ctypes.c_char_p, ctypes.c_int64)
            lib.dcs_format_rows.restype = ctypes.c_int64
        except (OSError, RuntimeError) as exc:
            _log.warning("the master's native stepping loop is not available, the Python "
                         "loop runs: %s", " ".join(str(exc).split())[:500])
        _loaded[key] = lib
    return _loaded[key]
