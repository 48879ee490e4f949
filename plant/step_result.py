"""The outcome of one plant step, shared by the Python step (:mod:`plant.simulator`) and the
compiled one (:mod:`plant.compiled_step`), which both return it."""

from __future__ import annotations

import math
from dataclasses import dataclass

__all__ = ["StepResult"]


@dataclass(frozen=True)
class StepResult:
    """Outcome of a step: ``ok`` and, on failure, a message naming time and quantity."""

    ok: bool
    message: str = ""
    time: float = math.nan
    quantity: str = ""
    value: float = math.nan
