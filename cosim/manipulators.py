"""Write-only manipulators: scenario events and fault injection.

A manipulator's ``before_step(execution)`` runs before every step; it may only
write (``execution.set_value``). A value written to a connected input is
overwritten at that FMU's next exchange, so manipulate parameters or
unconnected inputs.
"""

from __future__ import annotations

from .system import ParameterValue, split_variable


class ScheduledChange:
    """Set ``'fmu.var'`` to ``value`` at ``time`` (effective from the step starting there).

    Parameters
    ----------
    time : float
        Event time [s], on the base-step grid.
    ref : str
        ``'fmu.var'`` to write.
    value : float, int, bool or str
        New value.
    """

    def __init__(self, time: float, ref: str, value: ParameterValue):
        split_variable(ref, "ScheduledChange.ref")
        self.time, self.ref, self.value = time, ref, value
        self._tick: int | None = None

    def before_step(self, execution) -> None:
        """Apply the change when the execution reaches the event tick."""
        if self._tick is None:
            self._tick = execution.ticks_until(self.time)
        if execution.tick == self._tick:
            execution.set_value(self.ref, self.value)
