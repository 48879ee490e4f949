"""Output limits: an observer that stops the run when an exchanged output leaves its bound.

A study stops a point whose actuator force exceeds a cap as it stops a divergence: the
:class:`OutputLimit` raises :class:`~cosim.master.errors.DivergenceError` naming the output,
the time and the value after the first step at whose end ``not |value| <= bound`` (NaN
included). It reads the master's exchange buffer (no FMI call), and the native loop
(:mod:`cosim.master.native`) checks the same bound in C.
"""

from __future__ import annotations

from collections.abc import Sequence

from .errors import DivergenceError

__all__ = ["OutputLimit"]


class OutputLimit:
    """Observer: raise :class:`DivergenceError` when ``not |ref| <= bound`` after a step.

    Parameters
    ----------
    refs : sequence of str
        ``'fmu.var'`` outputs, exchanged ones (connection sources or read outputs of the
        execution).
    bound : float
        Largest allowed magnitude [the outputs' unit], > 0.
    """

    def __init__(self, refs: Sequence[str], bound: float):
        if not bound > 0:
            raise ValueError(f"OutputLimit.bound: > 0, got {bound!r}")
        self.refs = list(refs)
        self.bound = float(bound)
        self._index: list[tuple[int, str]] = []

    def on_start(self, execution) -> None:
        """Resolve the outputs to indices of the exchange buffer."""
        index = execution.algorithm.y_index
        missing = [r for r in self.refs if r not in index]
        if missing:
            raise ValueError(f"OutputLimit.refs: not exchanged or read by the execution: "
                             f"{missing}")
        self._y = execution.algorithm.y
        self._index = [(index[r], r) for r in self.refs]

    def on_step(self, execution) -> None:
        """Raise if an output is beyond the bound."""
        y, bound = self._y, self.bound
        for i, ref in self._index:
            if not abs(y[i]) <= bound:
                raise DivergenceError(ref, execution.time, y[i])
