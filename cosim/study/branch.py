"""Studies that branch: the common prefix of a sweep's points runs once, each point continues
from its checkpoint.

Closed-loop points of one scene that differ only in the strain controller's gain and the
actuator delay are the same run up to the controller's switch-on (``controller.switch_on_time``,
e.g. 25 s in ``paper_switch_on_25s``): before it the controller commands zero force whatever
its gain, so its lag state stays zero, and what the plant receives through the delayed
actuator line is zero whatever the delay. The prefix runs once per group (same scene, step,
stop time, engine and other settings) to the branch time, the last controller sample before
the switch-on, with the group's largest delay, and is checkpointed
(:mod:`cosim.master.checkpoint`). Its delay lines hold the past samples of their *source*
signals, which do not depend on the delay, and at least as many as any smaller delay needs
(:meth:`~cosim.master.delays.DelayLine.restore_history`); every point restores the
checkpoint into its own system (its gain is set again, a tunable start value) and steps on.
Its record is the prefix's rows before the branch time and its own from there: the same
numbers, bit for bit, as the point run from the start, hence the same metrics and verdicts.

:class:`BranchedPoint` carries the checkpoint's bytes and the prefix's rows with the point,
so a point branches the same way in this process, in a process pool or on a Dask worker.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from drillcosim.cosim.master.checkpoint import Checkpoint
from drillcosim.cosim.master.timegrid import split_ticks
from drillcosim.cosim.scenario.build import build_system
from drillcosim.cosim.scenario.config import SceneConfig
from drillcosim.cosim.scenario.simulate import simulate_system

from .grid import DEFAULT_GAIN_KEY, Point
from .point import point_config

__all__ = ["BranchedPoint", "Prefix", "branch_points", "branch_tick"]


@dataclass(frozen=True)
class Prefix:
    """The common run of a group of points up to its branch time.

    Attributes
    ----------
    checkpoint : bytes
        The checkpoint file's content at the branch time (:meth:`Checkpoint.to_bytes`).
    rows : numpy.ndarray
        The prefix's recorded rows before the branch time (structured, ``time`` [s] first).
    time : float
        Branch time [s].
    wall_time : float
        Wall time of the prefix run [s] (shared by the group's points).
    """

    checkpoint: bytes
    rows: np.ndarray
    time: float
    wall_time: float


@dataclass(frozen=True)
class BranchedPoint:
    """A sweep point that continues from a :class:`Prefix` (same key and identity as the
    point; :meth:`kwargs` adds the prefix for :func:`cosim.study.point.measure_point`)."""

    point: Point
    prefix: Prefix

    @property
    def key(self) -> str:
        return self.point.key

    def identity(self) -> dict[str, Any]:
        return self.point.identity()

    def kwargs(self) -> dict[str, Any]:
        return {**self.point.kwargs(), "prefix": self.prefix}


def branch_tick(config: SceneConfig) -> int:
    """The branch tick of a closed-loop configuration (0: nothing to share): one controller
    period before its first sample at or after ``switch_on_time``, so that no step of the prefix
    sees a nonzero command whether the controller evaluates it at the start or the end of its
    step."""
    c, cosim = config.controller, config.cosim
    # the P law only: its state before the switch-on does not depend on the gain
    if c.kind != "proportional" or not c.switch_on_time:
        return 0
    period = cosim.controller_ticks
    whole, fraction = split_ticks(c.switch_on_time, cosim.step)  # the one on-grid rule
    first = -(-(whole + (fraction > 0)) // period) * period  # first sample at or after it
    return max(0, min(first - period, cosim.stop_ticks - period))


def _group_key(point: Point) -> tuple:
    return (point.scene, point.engine, point.step, point.stop_time, point.overrides,
            point.options, point.vary)


def branch_points(points: Sequence[Any], fmu_dir: str | None = None) -> list[Any]:
    """``points`` with each closed-loop :class:`Point` of the default gain key whose group shares
    a prefix replaced by a :class:`BranchedPoint` (the prefix run here, once per group)."""
    groups: dict[tuple, list[Point]] = {}
    for p in points:
        if isinstance(p, Point) and p.kind == "closed_loop" and p.gain_key == DEFAULT_GAIN_KEY:
            groups.setdefault(_group_key(p), []).append(p)
    prefixes: dict[str, Prefix] = {}
    for members in groups.values():
        deepest = max(members, key=lambda p: p.delay)
        config = deepest.config
        if config is None:
            config = point_config(deepest.scene, deepest.gain, deepest.delay, deepest.step,
                                  deepest.stop_time, False, deepest.kwargs()["overrides"])
        tick = branch_tick(config)
        if tick <= 0:
            continue
        try:
            prefix = _run_prefix(config, deepest.engine, tick, fmu_dir)
        except Exception:  # noqa: BLE001 - the points then run from the start, and say why
            prefix = None
        if prefix is not None:
            prefixes.update({p.key: prefix for p in members})
    return [BranchedPoint(p, prefixes[p.key]) if isinstance(p, Point) and p.key in prefixes
            else p for p in points]


def _run_prefix(config: SceneConfig, engine: str, tick: int, fmu_dir: str | None
                ) -> Prefix | None:
    """Run ``config`` to ``tick`` and checkpoint it; None if the run stops early."""
    built = build_system(config, engine, fmu_dir=fmu_dir)
    t = config.cosim.seconds(tick)
    res, failure = simulate_system(built.system, built.slaves, built.outputs,
                                   config.cosim.output_ticks, t,
                                   checkpoint_identity={"scene": config.name, "prefix": t})
    if failure is not None or res.checkpoint is None:
        return None
    return Prefix(res.checkpoint.to_bytes(), res.data[res.data["time"] < t], t, res.wall_time)


def join_rows(prefix: Prefix, rows: np.ndarray) -> np.ndarray:
    """The prefix's rows before the branch time, then ``rows`` (from the branch time on)."""
    return np.concatenate([prefix.rows.astype(rows.dtype, copy=False), rows])


def checkpoint_of(prefix: Prefix) -> Checkpoint:
    """The prefix's checkpoint (read from its bytes: checksums checked)."""
    return Checkpoint.from_bytes(prefix.checkpoint)
