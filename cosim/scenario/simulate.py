"""Simulate a built system: the one call of :meth:`Master.simulate
<cosim.master.master.Master.simulate>` for every run of a scene (and of an SSP file).

A run that fails while stepping (divergence: a non-finite output; a slave discarding or
failing a step) ends early: the result keeps what was recorded and says where and why
(``failure``). A run that fails before its first step (e.g. an FMU rejecting its parameters at
initialization, or a step that fails at once) raises :class:`CosimError`; an earlier results
file is then left untouched.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from drillcosim.cosim.master.checkpoint import Checkpoint, write_checkpoint
from drillcosim.cosim.master.errors import CosimError
from drillcosim.cosim.master.master import Master
from drillcosim.cosim.master.master import Result as MasterResult
from drillcosim.cosim.master.system import SystemSpec

from .build import BuiltSystem
from .checkpoints import load_for, run_identity
from .config import ConfigError
from .result import Result

__all__ = ["simulate_system", "simulate"]


def _failure(err: CosimError | None, result: MasterResult) -> dict[str, Any] | None:
    """Where and why a run stopped early: ``{"time_s", "quantity", "value", "message"}``."""
    if result.diverged is not None:
        d = result.diverged
        return {"time_s": d.time, "quantity": d.quantity, "value": d.value,
                "message": f"non-finite {d.quantity} = {d.value!r} at t = {d.time:.6g} s"}
    if err is None:
        return None
    value = getattr(err, "value", None)
    quantity = getattr(err, "quantity", f"{err.fmu_name}.{err.call}")
    return {"time_s": err.time, "quantity": quantity, "value": value,
            "message": f"FMU '{err.fmu_name}' {err.call} failed at t = {err.time:.6g} s: "
                       f"{err.fmu_message or err.message}"}


def simulate_system(system: SystemSpec, slaves, outputs: Sequence[str], output_ticks: int,
               stop_time: float, *, progress: bool | None = False,
               csv_path: str | Path | None = None, observers: Sequence[Any] = (),
               from_checkpoint: Any = None, checkpoint_identity: Any = None
               ) -> tuple[MasterResult, dict[str, Any] | None]:
    """Run ``system`` to ``stop_time`` [s], recording ``outputs`` every ``output_ticks`` base
    steps (and streaming them to ``csv_path``, written atomically, if given); from
    ``from_checkpoint`` and taking one at the stop time with ``checkpoint_identity`` if given
    (:meth:`Master.simulate <cosim.master.master.Master.simulate>`).

    Returns
    -------
    (cosim.master.master.Result, dict or None)
        The master's result and the failure that stopped the run early (None: completed).

    Raises
    ------
    CosimError
        The run failed before its first step (an earlier ``csv_path`` is kept).
    """
    err: CosimError | None = None
    try:
        result = Master(system, slaves or None).simulate(
            stop_time=stop_time, outputs=outputs, output_ticks=output_ticks, progress=progress,
            csv_path=csv_path, observers=observers, from_checkpoint=from_checkpoint,
            checkpoint_identity=checkpoint_identity)
    except CosimError as exc:
        err, result = exc, exc.result
        if result is None or not (math.isfinite(result.end_time)
                                  and result.end_time > system.start_time):
            raise
    return result, _failure(err, result)


def simulate(built: BuiltSystem, stop_time: float | None = None, *,
             outputs: Sequence[str] | None = None, progress: bool | None = False,
             csv_path: str | Path | None = None, observers: Sequence[Any] = (),
             save_state: str | Path | None = None,
             from_state: str | Path | Checkpoint | None = None) -> Result:
    """Simulate a built system and return its :class:`~.result.Result`.

    Parameters
    ----------
    built : BuiltSystem
        From :func:`.build.build_system` (its in-process slaves serve one run).
    stop_time : float, optional
        [s], an integer multiple of the step; default the configuration's.
    outputs : sequence of str, optional
        ``'instance.variable'`` to record instead of ``built.outputs``.
    progress : bool or None
        Progress bar (None: only on a TTY).
    csv_path : path-like, optional
        Also stream the recorded rows to this CSV while running (its folder is created).
    observers : sequence
        Read-only observers for the master (e.g. a study's early stop).
    save_state : path-like, optional
        Write the whole system's state at the stop time to this checkpoint file
        (:mod:`.checkpoints`; only if the run completed).
    from_state : path-like, optional
        Continue from this checkpoint file (of the same scene, settings, engine, builds and
        drillcosim version) instead of the start time: the rows begin at its time. A
        :class:`~cosim.master.checkpoint.Checkpoint` object (a study's branch) is restored
        without the run-identity check (the components' builds are checked).

    Raises
    ------
    ConfigError
        A stop time off the step grid, an output the system does not have.
    CosimError
        The run failed before its first step.
    CheckpointError
        ``from_state`` is unreadable, damaged or of another run (one line).
    """
    cosim = built.config.cosim
    stop = cosim.stop_time if stop_time is None else cosim.seconds(
        cosim.ticks(stop_time, "stop time"))
    names = built.outputs if outputs is None else tuple(outputs)
    unknown = [n for n in names if n not in built.units]
    if unknown:
        raise ConfigError(f"outputs: the system records no {', '.join(map(repr, unknown))}; "
                          f"allowed: {', '.join(built.units)}")
    if csv_path is not None:
        Path(csv_path).parent.mkdir(parents=True, exist_ok=True)
    start = (from_state if from_state is None or isinstance(from_state, Checkpoint)
             else load_for(from_state, built.config, built.engine, stop))
    identity = None if save_state is None else run_identity(built.config, built.engine)
    result, failure = simulate_system(built.system, built.slaves, names, cosim.output_ticks, stop,
                                 progress=progress, csv_path=csv_path, observers=observers,
                                 from_checkpoint=start, checkpoint_identity=identity)
    if save_state is not None and result.checkpoint is not None:
        write_checkpoint(result.checkpoint, save_state)
    return Result(built.config, built.engine, result.data,
                  {"time": "s", **{n: built.units[n] for n in names}}, stop, result.end_time,
                  result.wall_time, result.real_time_factor, failure, result.csv_path,
                  built.components(), result.profile())
