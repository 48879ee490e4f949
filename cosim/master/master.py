"""The master: simulate a :class:`~cosim.master.system.SystemSpec` to a stop time and return
its recorded :class:`Result`.

:class:`Master` puts the pieces together for one simulation: an
:class:`~cosim.master.execution.Execution` (time, slaves, algorithm), the
:class:`~cosim.master.recorder.Recorder` (and a progress bar), the caller's observers and
manipulators; a divergence ends the run with :attr:`Result.diverged` set, an FMU failure
raises :class:`~cosim.master.errors.CosimError` carrying the partial result.
"""

from __future__ import annotations

import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from .errors import CosimError, DivergenceError
from .execution import Execution
from .recorder import Recorder
from .slave import Slave
from .system import SystemSpec
from .timegrid import integer_multiple


@dataclass(frozen=True)
class Divergence:
    """Where a run stopped on a non-finite output."""

    time: float          #: simulated time of the read [s]
    quantity: str        #: 'fmu.var'
    value: float         #: nan or +-inf


@dataclass(frozen=True)
class Result:
    """Outcome of :meth:`Master.simulate`.

    Attributes
    ----------
    data : numpy.ndarray
        Structured array, shape (n_rows,), fields ``time`` [s] then each output.
    wall_time : float
        Wall-clock time of the stepping loop [s].
    real_time_factor : float
        Simulated time / wall time (> 1: faster than real time).
    end_time : float
        Simulated time reached [s].
    diverged : Divergence or None
        Set if the run stopped on a non-finite output.
    csv_path : Path or None
        The result file, if one was written.
    timings : dict
        Where the stepping loop's wall time went: per component (by name) ``steps``,
        ``step_total_s``, ``step_max_s`` (its step calls) and ``exchange_s`` (its set-inputs
        and get-outputs calls) [s]; :meth:`profile` summarizes it.
    checkpoint : Checkpoint or None
        The state at the stop time (:mod:`.checkpoint`), if asked for and the run completed.
    """

    data: np.ndarray
    wall_time: float
    real_time_factor: float
    end_time: float
    diverged: Divergence | None = None
    csv_path: Path | None = None
    timings: dict[str, dict[str, float]] = field(default_factory=dict)
    checkpoint: Any = None

    def profile(self) -> dict[str, Any]:
        """The run's telemetry: per component the mean and longest step [s], its calls' total
        and share of the stepping loop's wall time; the master's own share (exchange, delay
        lines, recording, observers: the rest) and the real-time factor.

        Returns
        -------
        dict
            ``{"components": {name: {"steps", "step_mean_s", "step_max_s", "exchange_s",
            "total_s", "share"}}, "master_s", "master_share", "wall_time_s",
            "real_time_factor"}`` (shares of the wall time, [1]).
        """
        wall = self.wall_time
        comps = {}
        for name, t in self.timings.items():
            total = t["step_total_s"] + t["exchange_s"]
            comps[name] = {"steps": t["steps"],
                           "step_mean_s": t["step_total_s"] / t["steps"] if t["steps"]
                           else float("nan"),
                           "step_max_s": t["step_max_s"], "exchange_s": t["exchange_s"],
                           "total_s": total, "share": total / wall if wall > 0 else float("nan")}
        master = wall - sum(c["total_s"] for c in comps.values())
        return {"components": comps, "master_s": master,
                "master_share": master / wall if wall > 0 else float("nan"),
                "wall_time_s": wall, "real_time_factor": self.real_time_factor}


class Master:
    """Simulate a co-simulation system.

    Parameters
    ----------
    system : SystemSpec
    slaves : mapping of str to Slave, optional
        Ready-made components (see :class:`~cosim.master.execution.Execution`), used by one
        run (they are closed at its end).
    """

    def __init__(self, system: SystemSpec, slaves: Mapping[str, Slave] | None = None):
        self.system = system
        self.slaves = slaves

    def simulate(self, stop_time: float | None = None, outputs: Sequence[str] = (),
            output_interval: float | None = None, progress: bool | None = False,
            csv_path: str | Path | None = None, flush_every: int = 1000,
            observers: Sequence[Any] = (), manipulators: Sequence[Any] = (),
            output_ticks: int | None = None, from_checkpoint: Any = None,
            checkpoint_identity: Mapping[str, Any] | None = None) -> Result:
        """Simulate from the start time to ``stop_time``.

        Parameters
        ----------
        stop_time : float, optional
            [s]; defaults to ``system.stop_time``.
        outputs : sequence of str
            ``'fmu.var'`` variables to record.
        output_interval : float, optional
            Recording interval [s], an integer multiple of the base step
            (default: every base step).
        output_ticks : int, optional
            The recording interval in base steps instead (not with ``output_interval``).
        progress : bool or None
            Show a progress bar (None: only on a TTY).
        csv_path : str or Path, optional
            Also stream the recorded rows to this CSV (atomic, see
            :mod:`cosim.master.recorder`).
        flush_every : int
            Rows per CSV write.
        observers : sequence
            Extra read-only observers (``on_step(execution)``, optional ``on_start``), added
            before the recorder.
        manipulators : sequence
            Manipulators (``before_step(execution)``): scenario events, fault injection.
        from_checkpoint : Checkpoint, optional
            Start from it (:func:`.resume.restore`) instead of the start time: the recorded
            rows begin at its time.
        checkpoint_identity : mapping, optional
            Take a checkpoint at the stop time carrying this identity
            (:attr:`Result.checkpoint`).

        Returns
        -------
        Result
            With ``diverged`` set if a non-finite output stopped the run.

        Raises
        ------
        CosimError
            If an FMU call fails; ``error.result`` holds the partial
            :class:`Result` (and the CSV is finalised if at least one step was made;
            a failure before the first step leaves an earlier file untouched).
        """
        system = self.system
        stop = system.stop_time if stop_time is None else stop_time
        if stop is None:
            raise ValueError("stop_time: required (the system has no stop_time)")
        H = system.base_step
        interval = 1 if output_ticks is None else output_ticks
        if output_interval is not None and output_ticks is not None:
            raise ValueError("output_interval and output_ticks: give one of them")
        if output_interval is not None:
            interval = integer_multiple(output_interval, H)
            if interval is None:
                raise ValueError(f"output_interval: a positive integer multiple of "
                                 f"base_step = {H} s, got {output_interval} s")
        recorder = Recorder(outputs, interval, csv_path, flush_every)
        execution = None
        wall0 = time.perf_counter()
        diverged = checkpoint = None
        try:
            execution = Execution(system, read_outputs=outputs, slaves=self.slaves)
            if from_checkpoint is not None:
                execution.resume_from(from_checkpoint)
            for obs in observers:
                execution.add_observer(obs)
            for man in manipulators:
                execution.add_manipulator(man)
            execution.add_observer(recorder)
            if progress is not False:
                from .progress import ProgressObserver  # tqdm: imported only when used

                execution.add_observer(ProgressObserver(stop, disable=None if progress
                                                        is None else not progress))
            execution.initialize()
            if hasattr(execution.algorithm, "reset_timing"):
                execution.algorithm.reset_timing()
            wall0 = time.perf_counter()
            execution.simulate_until(stop)
            if checkpoint_identity is not None:
                from .resume import capture

                checkpoint = capture(execution, checkpoint_identity)
        except DivergenceError as err:
            diverged = Divergence(err.time, err.quantity, err.value)
        except CosimError as err:
            err.result = self._finish(recorder, execution, wall0, None)
            raise
        except BaseException:
            self._finish(recorder, execution, wall0, None)
            raise
        return self._finish(recorder, execution, wall0, diverged, checkpoint)

    @staticmethod
    def _finish(recorder: Recorder, execution: Execution | None, wall0: float,
                diverged: Divergence | None, checkpoint: Any = None) -> Result:
        wall = time.perf_counter() - wall0
        end = execution.time if execution is not None else float("nan")
        sim = (execution.time - (execution.start_time if execution._resume is None
                                 else execution._resume.time)) if execution is not None else 0.0
        stepped = execution is not None and execution.tick > 0

        timings = {}
        if execution is not None and hasattr(execution.algorithm, "timings") \
                and execution.initialized:
            timings = execution.algorithm.timings()

        def result() -> Result:
            return Result(recorder.data, wall, sim / wall if wall > 0 else float("inf"), end,
                          diverged, recorder.csv_path, timings, checkpoint)

        try:
            if execution is not None:
                execution.close()
        except CosimError as err:   # the recorder's last write (on_stop) failed
            recorder.abort()
            if err.result is None:
                err.result = result()
            raise
        if not stepped:  # failed before the first step: leave any earlier file untouched
            recorder.abort()
            return result()
        try:
            recorder.close()
        except CosimError as err:   # the last rows could not be written: they are in memory
            if err.result is None:
                err.result = result()
            raise
        return result()
