"""The time grid: integer ticks of the base step, and the one rule that decides whether a time is
on the grid.

The master counts time in ticks (base steps H). A time given in seconds (a stop time, a
controller period, a recording interval, a transport delay, a state-space law's sample period
against the controllers' period) is on the grid of a step when it is a whole number of steps:
:func:`grid_ticks` is that rule, the only one (config, master, execution, delay lines and the
state-space check ask it). The tolerance is relative, :data:`RTOL` of the ratio (at least of 1):
times written in decimal (0.1 s of 0.25 ms steps) are not exact binary multiples, and their
float ratio is off by a few ulps, far inside it.

Seconds of a tick count are an exact rational product rounded once (:func:`seconds`): 120000
steps of 0.25 ms are 30.0 s, not the sum of 120000 rounded steps.
"""

from __future__ import annotations

import math
from fractions import Fraction

__all__ = ["RTOL", "grid_ticks", "integer_multiple", "on_grid", "seconds", "split_ticks",
           "step_fraction"]

#: Relative tolerance of the on-grid rule (of ``seconds / step``, at least of 1).
RTOL = 1e-9


def grid_ticks(seconds: float, step: float) -> int | None:
    """``seconds / step`` as a whole number of steps (>= 0) if it is one within :data:`RTOL`
    relative, else None. The on-grid rule.

    Parameters
    ----------
    seconds : float
        A time or duration [s], >= 0.
    step : float
        The grid's step [s], > 0.
    """
    ratio = seconds / step
    if not math.isfinite(ratio) or ratio < 0:
        return None
    n = round(ratio)
    return n if abs(ratio - n) <= RTOL * max(1.0, ratio) else None


def on_grid(seconds: float, step: float) -> bool:
    """Whether ``seconds`` [s] is a whole number of steps of ``step`` [s] (:func:`grid_ticks`)."""
    return grid_ticks(seconds, step) is not None


def integer_multiple(period: float, step: float) -> int | None:
    """``period / step`` if it is a positive whole number (:func:`grid_ticks`), else None."""
    n = grid_ticks(period, step)
    return n if n else None


def split_ticks(duration: float, step: float) -> tuple[int, float]:
    """``duration / step`` as whole steps and the fraction of one more, in [0, 1): ``(n, 0.0)``
    on the grid (:func:`grid_ticks`), else ``(floor, remainder)`` (a delay line's split)."""
    n = grid_ticks(duration, step)
    if n is not None:
        return n, 0.0
    ratio = duration / step
    whole = math.floor(ratio)
    return whole, ratio - whole


def step_fraction(step: float) -> Fraction:
    """The step [s] as a fraction: the simplest one (denominator <= 1e12) that rounds to it,
    else its exact binary value (0.25e-3 -> 1/4000)."""
    frac = Fraction(step).limit_denominator(10**12)
    return frac if float(frac) == step else Fraction(step)


def seconds(ticks: int, step: float | Fraction, start: float = 0.0) -> float:
    """The time of tick ``ticks`` [s]: ``start + ticks * step`` with the product exact
    (:func:`step_fraction`) and rounded once."""
    frac = step if isinstance(step, Fraction) else step_fraction(step)
    return start + ticks * frac.numerator / frac.denominator
