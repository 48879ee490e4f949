"""Branching studies: points identical up to the controller's switch-on continue from one
checkpoint of that prefix. Each branched record equals the point run from 0 s bit for bit (FMU
and in-process engines, delays that are not multiples of the controller's period, a controller
sampled every 4 plant steps), and a branched sweep's table equals the unbranched one (locally
and on a Dask cluster)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from drillcosim.cosim.master.checkpoint import Checkpoint
from drillcosim.cosim.study.branch import BranchedPoint, branch_points, branch_tick
from drillcosim.cosim.study.grid import SweepSpec
from drillcosim.cosim.study.point import PointOptions, point_config, run_point
from drillcosim.cosim.study.sweep import execute_sweep
from drillcosim.cosim.study.table import read_table

SCENE = "paper_switch_on_25s"
#: switched on at 0.2 s (the paper's 25 s shortened), controller every 1 ms = 4 steps
SHORT = {"controller.switch_on_time": 0.2, "cosim.controller_sample_period": 1e-3}
STEP, STOP = 2.5e-4, 0.45
#: a force cap [N] the strongest, delayed point crosses after the switch-on (284 N by 0.45 s:
#: a diverged row besides the others)
OPTIONS = {"force_cap": 100.0}


#: the other exchange: Jacobi (inputs due at the branch tick taken again from the lines) with
#: linear coupling (the lines extrapolate from their last two samples)
JACOBI = {"cosim.algorithm": "jacobi", "cosim.coupling": "linear"}


def _spec(engine: str, extra: dict | None = None) -> SweepSpec:
    return SweepSpec(SCENE, [1e8, 1e9], [0.0, 1.1e-3], [STEP], STOP, engine,
                     {**SHORT, **(extra or {})}, options=OPTIONS)


def test_branch_tick_is_one_controller_period_before_the_switch_on() -> None:
    config = point_config(SCENE, 1e8, 0.0, STEP, STOP, False, SHORT)
    assert config.cosim.controller_ticks == 4
    assert branch_tick(config) == 800 - 4          # 0.2 s / 0.25 ms = 800 ticks
    off = point_config(SCENE, 1e8, 0.0, STEP, STOP, False, {**SHORT,
                                                            "controller.switch_on_time": 0.0})
    assert branch_tick(off) == 0


@pytest.mark.parametrize(("engine", "extra"), [("inprocess", None), ("fmu", None),
                                               ("inprocess", JACOBI)],
                         ids=["inprocess", "fmu", "inprocess-jacobi-linear"])
def test_branched_record_equals_straight_run_bit_for_bit(engine, extra) -> None:
    branched = [p for p in branch_points(_spec(engine, extra).points())
                if isinstance(p, BranchedPoint)]
    assert len(branched) == 4
    assert len({id(p.prefix) for p in branched}) == 1      # one prefix for the group
    opts = PointOptions.from_kwargs(OPTIONS)
    acted = 0
    for bp in branched:
        p = bp.point
        config = point_config(SCENE, p.gain, p.delay, STEP, STOP, False,
                              {**SHORT, **(extra or {})})
        straight, _ = run_point(config, opts, engine)
        rest, _ = run_point(config, opts, engine,
                            from_checkpoint=Checkpoint.from_bytes(bp.prefix.checkpoint))
        joined = np.concatenate([bp.prefix.rows, rest.data])
        assert joined.dtype == straight.data.dtype and len(joined) == len(straight.data)
        for name in straight.data.dtype.names:
            assert np.array_equal(joined[name].view(np.int64),
                                  straight.data[name].view(np.int64)), (p.gain, p.delay, name)
        acted += np.abs(straight.data["controller.actuator1_force_C"]).max() > 0
    assert acted == 4


def _rows(folder) -> dict[str, dict]:
    return {r["key"]: r for r in read_table(folder)}


_TIMING = {"wall_time", "startup_time", "stepping_time", "worker_startup", "branch_time"}


def _same_rows(a: dict[str, dict], b: dict[str, dict]) -> None:
    assert a.keys() == b.keys()
    for key, row in a.items():
        for col, value in row.items():
            if col in _TIMING:
                continue
            other = b[key][col]
            same = value == other or (isinstance(value, float) and math.isnan(value)
                                      and isinstance(other, float) and math.isnan(other))
            assert same, (key, col, value, other)


def test_branched_sweep_has_the_same_table(tmp_path) -> None:
    spec = _spec("inprocess")
    execute_sweep(spec, tmp_path / "straight", workers=0, progress=False, branch=False)
    execute_sweep(spec, tmp_path / "branched", workers=0, progress=False)
    straight, branched = _rows(tmp_path / "straight"), _rows(tmp_path / "branched")
    _same_rows(straight, branched)
    closed = [r for r in branched.values() if r["kind"] == "closed_loop"]
    assert all(r["branch_time"] == pytest.approx(0.199) for r in closed)
    assert {r["status"] for r in closed} == {"ok", "diverged"}   # verdicts of both kinds


@pytest.mark.slow
def test_branched_sweep_on_dask_has_the_same_table(tmp_path) -> None:
    """The checkpoint bytes travel with each point to a Dask worker process."""
    from distributed import Client, LocalCluster

    spec = _spec("inprocess")
    execute_sweep(spec, tmp_path / "straight", workers=0, progress=False, branch=False)
    with LocalCluster(n_workers=1, threads_per_worker=1, processes=True,
                      dashboard_address=None) as cluster, Client(cluster) as client:
        execute_sweep(spec, tmp_path / "dask", scheduler=client.scheduler.address,
                      progress=False)
    rows = _rows(tmp_path / "dask")
    _same_rows(_rows(tmp_path / "straight"), rows)
    assert all(math.isfinite(r["branch_time"]) for r in rows.values()
               if r["kind"] == "closed_loop")
