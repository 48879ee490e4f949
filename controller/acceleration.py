"""Whether a law gets a compiled step: numba installed and compiled steps on (numpy only here).

The compiled steps themselves (``compiled.py``) import numba; this module imports them only
when asked, so the package keeps running in a Python that has nothing but numpy.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

__all__ = ["compiled_law"]


def compiled_law(entry: str, pack: Callable[[], tuple[object, list[Any]]]) -> Any:
    """A :class:`controller.compiled.CompiledLaw` of the C entry point ``entry`` (a name in
    ``compiled``: ``"strain_step"``, ``"top_drive_step"``) and its context ``pack``; None
    without numba or with compiled steps switched off (``DRILLCOSIM_COMPILED_STEP=0``)."""
    try:
        from . import compiled
    except ImportError:  # a Python with only numpy: the law runs in Python
        return None
    if not compiled.enabled():
        return None
    return compiled.CompiledLaw(getattr(compiled, entry).address, pack)
