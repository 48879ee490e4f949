"""Write-only manipulators: scenario events and fault injection.

A manipulator's ``before_step(execution)`` runs before every step; it may only
write (``execution.set_value``). A value written to a connected input is
overwritten at that FMU's next exchange, so manipulate parameters or
unconnected inputs.

A manipulator that also says when it acts, ``next_action_tick(execution, tick)`` (the first
tick >= ``tick`` whose ``before_step`` may write, None: never), lets the master run the steps
in between in its native loop (:mod:`cosim.master.native`), calling ``before_step`` at that
tick only; one without it keeps the master in its Python loop.
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
        if execution.tick == self._event_tick(execution):
            execution.set_value(self.ref, self.value)

    def next_action_tick(self, execution, tick: int) -> int | None:
        """The event tick if it is not before ``tick``, else None."""
        event = self._event_tick(execution)
        return event if event >= tick else None

    def _event_tick(self, execution) -> int:
        if self._tick is None:
            self._tick = execution.ticks_until(self.time)
        return self._tick


class InjectFault:
    """Fault injection: write ``value`` to ``'fmu.var'`` before every step in [start, stop).

    Unlike :class:`ScheduledChange` the value is written again before each step,
    so it persists while the FMU (or an importer) would reset it. At ``stop``
    (if given) ``restore`` is written once, when not None. Typical faults: a NaN
    or huge value on an unconnected input, a parameter that makes an FMU
    discard its steps.

    Parameters
    ----------
    start : float
        First step affected [s], on the base-step grid.
    ref : str
        ``'fmu.var'`` to write.
    value : float, int, bool or str
        Faulty value.
    stop : float, optional
        First step no longer affected [s]; default: until the end.
    restore : float, int, bool or str, optional
        Value written at ``stop``.
    """

    def __init__(self, start: float, ref: str, value: ParameterValue,
                 stop: float | None = None, restore: ParameterValue | None = None):
        split_variable(ref, "InjectFault.ref")
        if stop is not None and not stop > start:
            raise ValueError(f"InjectFault.stop: > start = {start} s, got {stop!r} s")
        self.start, self.stop, self.ref = start, stop, ref
        self.value, self.restore = value, restore
        self.applied = 0  #: steps the fault was written before
        self._ticks: tuple[int, int | None] | None = None

    def before_step(self, execution) -> None:
        """Write the fault while the execution's tick lies in [start, stop)."""
        first, end = self._window(execution)
        tick = execution.tick
        if tick >= first and (end is None or tick < end):
            execution.set_value(self.ref, self.value)
            self.applied += 1
        elif end is not None and tick == end and self.restore is not None:
            execution.set_value(self.ref, self.restore)

    def next_action_tick(self, execution, tick: int) -> int | None:
        """``tick`` inside [start, stop), else start or stop (with a restore) ahead, else None."""
        first, end = self._window(execution)
        if end is not None and tick > end:
            return None
        if tick < first:
            return first
        if end is None or tick < end:
            return tick
        return end if self.restore is not None else None

    def _window(self, execution) -> tuple[int, int | None]:
        if self._ticks is None:
            self._ticks = (execution.ticks_until(self.start),
                           None if self.stop is None else execution.ticks_until(self.stop))
        return self._ticks
