"""Whether a law gets a compiled step (numpy and the standard library only here).

The compiled steps themselves (``compiled.py``) need numba. A law asks for one only where numba
is already loaded in the process (by the plant, in the main job and the in-process studies):
importing numba (~0.5 s) would cost more than a law of a few microseconds a step saves in most
runs of a controller alone, and the controller FMUs also run in a Python with nothing but numpy.
``DRILLCOSIM_COMPILED_STEP=0`` switches compiled steps off (the Python law, the reference).
"""

from __future__ import annotations

import os
import sys
from collections.abc import Callable
from typing import Any

__all__ = ["ENV", "FALLBACK", "INTERNAL", "OK", "REFUSED", "compiled_law", "enabled"]

ENV = "DRILLCOSIM_COMPILED_STEP"

#: The codes a law's compiled core returns (``controller/law.py``, rule 4).
OK = 0
FALLBACK = 1  # run this step in Python (nothing changed)
REFUSED = 2  # the Python law refuses this step (nothing changed)
INTERNAL = 9  # an exception inside the compiled code (a bug; numba's wrapper would return 0)


def enabled() -> bool:
    """Whether compiled steps are on: ``$DRILLCOSIM_COMPILED_STEP`` is not ``0`` (default on)."""
    return os.environ.get(ENV, "1").strip() != "0"


def compiled_law(entry: str, pack: Callable[[], tuple[object, list[Any]]]) -> Any:
    """A :class:`controller.compiled.CompiledLaw` of the C entry point ``entry`` (a registered
    law's ``KIND``) and its context ``pack``; None with compiled steps switched off or numba not
    loaded in this process."""
    if not enabled() or "numba" not in sys.modules:
        return None
    try:
        from . import compiled
    except ImportError:  # pragma: no cover - numba loaded but unusable
        return None
    return compiled.CompiledLaw(compiled.addresses()[entry], pack)
