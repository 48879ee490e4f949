"""Transport delays and coupling on connections.

A :class:`DelayLine` keeps a ring buffer of the past samples of one source
output, one sample per exchange of that output (i.e. at the source FMU's
communication points, spaced ``Ts = sample_period_ticks * base_step``). The
value delivered to the target is the source signal delayed by ``delay``
seconds *relative to the newest sample*:

* ``delay = n * Ts`` exactly (n integer): the sample n exchanges before the
  newest one, bit for bit;
* ``delay = (n + f) * Ts`` with ``0 < f < 1``: linear interpolation between
  the samples n and n + 1 exchanges back, ``(1 - f) s[-n] + f s[-n-1]``;
* before enough samples exist, the initial sample is repeated (the signal
  is taken constant before the start time).

Coupling (applied to the delayed signal):

* ``zoh``: the delayed value is held constant over the target's step;
* ``linear``: the delayed signal is extrapolated linearly from its last two
  samples to the midpoint of the target's step. A constant input equal to
  the midpoint value of a linear extrapolant has the same integral over the
  step, which makes the coupling error second order, O(H^2), for FMUs whose
  inputs are held over their steps (FMI 2 without input derivatives). When
  the source is already ahead of that midpoint (Gauss-Seidel), this is an
  interpolation between its last two samples.
"""

from __future__ import annotations

from .timegrid import split_ticks


class DelayLine:
    """Ring buffer of one connection's source samples.

    Parameters
    ----------
    delay : float
        Transport delay [s], >= 0.
    sample_period : float
        Spacing Ts of the source samples [s] (source FMU period).
    linear : bool
        Linear extrapolation coupling instead of zero-order hold.
    """

    __slots__ = ("n", "f", "depth", "buf", "pos", "linear", "delay", "sample_period")

    def __init__(self, delay: float, sample_period: float, linear: bool = False):
        n, f = split_ticks(delay, sample_period)
        self.delay = delay
        self.sample_period = sample_period
        self.n = n
        self.f = f
        self.linear = linear
        self.depth = n + 3
        self.buf = [0.0] * self.depth
        self.pos = 0

    def reset(self, value: float) -> None:
        """Fill the history with ``value`` (the signal before the start time)."""
        self.buf = [float(value)] * self.depth
        self.pos = 0

    def push(self, value: float) -> None:
        """Append the newest sample."""
        pos = self.pos + 1
        if pos == self.depth:
            pos = 0
        self.buf[pos] = value
        self.pos = pos

    def delayed(self, back: int = 0) -> float:
        """Delayed signal ``back`` samples before the newest one, interpolated."""
        buf = self.buf
        i = self.pos - self.n - back
        f = self.f
        if f == 0.0:
            return buf[i]
        return (1.0 - f) * buf[i] + f * buf[i - 1]

    def value(self, horizon: float) -> float:
        """Coupled value for the target.

        Parameters
        ----------
        horizon : float
            Time from the newest sample to the midpoint of the target's step,
            in units of ``sample_period`` (only used by linear coupling).
        """
        v0 = self.delayed(0)
        if not self.linear:
            return v0
        return v0 + (v0 - self.delayed(1)) * horizon

    def history(self) -> tuple[float, ...]:
        """The samples held, oldest first, newest last (:attr:`depth` of them)."""
        buf, pos = self.buf, self.pos
        return tuple(buf[pos + 1:] + buf[:pos + 1])

    def restore_history(self, samples) -> None:
        """Hold the newest :attr:`depth` of ``samples`` (oldest first): a line of any delay
        continues from the history of a line of the same source with a larger or equal one."""
        if len(samples) < self.depth:
            raise ValueError(f"{len(samples)} samples; this line holds {self.depth}")
        self.buf = [float(v) for v in samples[len(samples) - self.depth:]]
        self.pos = self.depth - 1

    def get_state(self) -> tuple[tuple[float, ...], int]:
        """Snapshot of the buffer (immutable)."""
        return tuple(self.buf), self.pos

    def set_state(self, state: tuple[tuple[float, ...], int]) -> None:
        """Restore a snapshot from :meth:`get_state`."""
        self.buf = list(state[0])
        self.pos = state[1]
