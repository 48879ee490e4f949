"""Progress observer: a tqdm bar of simulated time with the real-time factor."""

from __future__ import annotations

import sys
import time

from tqdm import tqdm


class ProgressObserver:
    """Show simulated time [s] and real-time factor (simulated / wall time).

    It acts only at ticks that are multiples of :attr:`stride_ticks` (set by :meth:`on_start`),
    so the native loop calls it at the ends of its chunks only (:mod:`cosim.master.native`).

    Parameters
    ----------
    stop_time : float
        Time at which the bar is full [s].
    disable : bool or None
        Force off (True) or on (False); None: on only if stderr is a TTY.
    updates : int
        Approximate number of bar refreshes over the run.
    """

    def __init__(self, stop_time: float, disable: bool | None = None, updates: int = 200):
        if disable is None:
            disable = not sys.stderr.isatty()
        self.disable = disable
        self.stop_time = stop_time
        self.updates = updates
        self.bar = None

    def on_start(self, execution) -> None:
        """Open the bar at the current simulated time."""
        t0 = execution.time
        span = max(self.stop_time - t0, execution.base_step)
        #: the bar is refreshed at ticks that are multiples of this (~``updates`` times)
        self.stride_ticks = max(1, int(span / execution.base_step / self.updates))
        self._t0, self._shown = t0, t0
        self._wall0 = time.perf_counter()
        self.bar = tqdm(total=round(span, 12), unit="s", disable=self.disable,
                        desc="co-simulation", bar_format="{l_bar}{bar}| {n:.3f}/{total:.3f} s "
                        "[{elapsed}<{remaining}{postfix}]")

    def on_step(self, execution) -> None:
        """Refresh every ``span / updates`` of simulated time."""
        if execution.tick % self.stride_ticks or self.bar is None:
            return
        t = execution.time
        self.bar.update(t - self._shown)
        self._shown = t
        wall = time.perf_counter() - self._wall0
        if wall > 0:
            self.bar.set_postfix_str(f"RTF {(t - self._t0) / wall:.3g}", refresh=False)

    def on_stop(self, execution) -> None:
        """Close the bar."""
        if self.bar is not None:
            self.bar.update(execution.time - self._shown)
            self.bar.close()
            self.bar = None
