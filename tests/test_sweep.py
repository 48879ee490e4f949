"""Sweeps: list syntax, table robustness, resume, bad points, dask, FMU engine smoke test."""

from __future__ import annotations

import math
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from drillcosim.cosim.study.grid import Point, parse_list
from drillcosim.cosim.study.sweep import SweepSpec, execute_point, run_sweep
from drillcosim.cosim.study.table import COLUMNS, ResultTable, read_table

ROOT = Path(__file__).resolve().parents[1]
SCENE = "paper_closed_loop"
# recording every 1 ms also at coarse steps
FAST = {"cosim": {"output_interval": 1e-3}}


# --- runners injected into the sweep (module level: they pickle to worker processes) -------
def fake_runner(scene, gain, delay, step, stop_time, engine, open_loop=False, overrides=None,
                **options):
    """Instant runner: unstable above gain * (delay + step) = 1e5; raises for gain 13."""
    if gain == 13.0:
        raise RuntimeError("injected failure\nsecond line")
    stable = open_loop or gain * (delay + step) < 1e5
    return {"status": "ok" if stable else "diverged", "stable": 1.0 if stable else 0.0,
            "growth_rate": 0.0, "divergence_time": math.nan if stable else stop_time / 2,
            "end_time": stop_time if stable else stop_time / 2, "reason": "",
            "rms_long": 1.0 if open_loop else 0.5, "rms_short": 2.0, "peak_force": gain,
            "peak_power": 0.0, "wall_time": 0.0}


def slow_runner(scene, gain, delay, step, stop_time, engine, open_loop=False, overrides=None,
                **options):
    time.sleep(0.4)
    return fake_runner(scene, gain, delay, step, stop_time, engine, open_loop)


def dying_runner(scene, gain, delay, step, stop_time, engine, open_loop=False, overrides=None,
                 **options):
    if gain == 7.0:
        os._exit(3)       # the worker process dies
    return fake_runner(scene, gain, delay, step, stop_time, engine, open_loop)


# --- grid ---------------------------------------------------------------------------------
def test_parse_list_forms():
    assert parse_list("1e6,1e9") == [1e6, 1e9]
    assert parse_list("0:1e-3:3") == [0.0, 5e-4, 1e-3]
    assert parse_list("log:1e6:1e9:4") == pytest.approx([1e6, 1e7, 1e8, 1e9])
    assert parse_list("0.001, 0:2e-3:3") == [0.0, 1e-3, 2e-3]        # duplicates merged
    for bad in ("", "a", "1:2", "log:0:1:3", "1:2:x"):
        with pytest.raises(ValueError):
            parse_list(bad, "--gain")
    with pytest.raises(ValueError, match="--step"):
        parse_list("0,1", "--step", positive=True)


def test_points_open_loop_first_and_keys_unique():
    spec = SweepSpec(SCENE, [1e8, 1e9], [0.0, 1e-4], [2.5e-4, 5e-4], 1.0, "python")
    pts = spec.points()
    assert len(pts) == 2 + 8
    assert [p.kind for p in pts[:2]] == ["open_loop"] * 2
    assert len({p.key for p in pts}) == len(pts)


# --- table --------------------------------------------------------------------------------
def test_table_drops_a_half_written_row(tmp_path):
    t = ResultTable(tmp_path)
    p = Point(SCENE, 1e9, 0.0, 1e-3, 1.0, "python")
    t.append(execute_point(p, fake_runner))
    with open(t.csv_path, "a") as fh:          # a kill in the middle of a write
        fh.write("paper_closed_loop|python|closed_loop|1e8,paper_clo")
    rows = ResultTable(tmp_path).rows
    assert [r["key"] for r in rows] == [p.key]
    assert t.csv_path.read_text().endswith("\n")
    assert t.csv_path.read_text().count("\n") == 2       # header + 1 row, repaired


def test_duplicate_rows_keep_the_newest_and_the_folder_is_locked(tmp_path):
    t = ResultTable(tmp_path)
    p = Point(SCENE, 1e9, 0.0, 1e-3, 1.0, "python")
    row = execute_point(p, fake_runner)
    t.append(row)
    with open(t.csv_path, "a") as fh:           # what two concurrent writers would leave
        fh.write(t.csv_path.read_text().splitlines(keepends=True)[1])
    assert len(ResultTable(tmp_path).rows) == 1
    held = t.lock()
    try:
        with pytest.raises(OSError, match="another sweep"):
            ResultTable(tmp_path).lock()
    finally:
        held.close()


def test_benefit_from_the_open_loop_row(tmp_path):
    spec = SweepSpec(SCENE, [1.0], [0.0], [1e-3], 1.0, "python")
    run_sweep(spec, tmp_path, workers=0, runner=fake_runner, progress=False)
    rows = {r["kind"]: r for r in read_table(tmp_path)}
    assert rows["closed_loop"]["benefit_long"] == pytest.approx(0.5)
    assert rows["closed_loop"]["benefit_short"] == pytest.approx(0.0)
    parquet = read_table(tmp_path / "results.parquet")
    assert {r["key"] for r in parquet} == {r["key"] for r in rows.values()}
    assert set(parquet[0]) == set(COLUMNS)


# --- bad points ---------------------------------------------------------------------------
def test_bad_points_are_recorded_with_their_reason(tmp_path):
    """A raising runner (gain 13) and a real point with invalid input (negative delay)."""
    spec = SweepSpec(SCENE, [1.0, 13.0], [0.0], [1e-3], 1.0, "python")
    out = run_sweep(spec, tmp_path, workers=1, runner=fake_runner, progress=False)
    rows = {r["gain"]: r for r in read_table(tmp_path) if r["kind"] == "closed_loop"}
    assert out.n_errors == 1 and out.n_run == 3
    assert rows[13.0]["status"] == "error"
    assert rows[13.0]["reason"].startswith("RuntimeError: injected failure second line")
    assert rows[1.0]["status"] == "ok"
    bad = execute_point(Point(SCENE, 1e9, -1e-3, 1e-3, 0.01, "python"))
    assert bad["status"] == "error" and "actuator_delay" in bad["reason"]


def test_a_dying_worker_is_recorded_and_the_sweep_goes_on(tmp_path):
    spec = SweepSpec(SCENE, [1.0, 7.0], [0.0], [1e-3], 1.0, "python")
    out = run_sweep(spec, tmp_path, workers=1, runner=dying_runner, progress=False)
    rows = {r["gain"]: r for r in read_table(tmp_path) if r["kind"] == "closed_loop"}
    assert out.n_points == 3 and len(read_table(tmp_path)) == 3
    assert rows[7.0]["status"] == "error" and "died" in rows[7.0]["reason"]
    assert rows[1.0]["status"] == "ok"


# --- resume -------------------------------------------------------------------------------
@pytest.mark.slow
def test_killed_sweep_resumes_and_skips_finished_points(tmp_path):
    """SIGKILL a sweep process mid-way; the rerun only runs the missing points."""
    script = (
        "import sys; sys.path.insert(0, {!r})\n"
        "from test_sweep import slow_runner\n"
        "from drillcosim.cosim.study.sweep import SweepSpec, run_sweep\n"
        "spec = SweepSpec({!r}, [1.0, 2.0, 3.0, 4.0, 5.0, 6.0], [0.0], [1e-3], 1.0, 'python')\n"
        "run_sweep(spec, {!r}, workers=0, runner=slow_runner, progress=False)\n"
    ).format(str(ROOT / "tests"), SCENE, str(tmp_path))
    proc = subprocess.Popen([sys.executable, "-c", script], cwd=ROOT)
    csv = tmp_path / "results.csv"
    deadline = time.time() + 60
    while time.time() < deadline:
        if csv.exists() and csv.read_text().count("\n") >= 3:     # header + 2 rows
            break
        time.sleep(0.05)
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    before = {r["key"] for r in read_table(tmp_path)}
    assert 2 <= len(before) < 7
    spec = SweepSpec(SCENE, [1.0, 2.0, 3.0, 4.0, 5.0, 6.0], [0.0], [1e-3], 1.0, "python")
    out = run_sweep(spec, tmp_path, workers=0, runner=fake_runner, progress=False)
    assert out.n_skipped == len(before) and out.n_run == 7 - len(before)
    rows = read_table(tmp_path)
    assert len(rows) == 7 and len({r["key"] for r in rows}) == 7
    again = run_sweep(spec, tmp_path, workers=0, runner=fake_runner, progress=False)
    assert again.n_run == 0 and again.n_skipped == 7


# --- real engines -------------------------------------------------------------------------
@pytest.mark.slow
def test_small_sweep_on_a_dask_local_cluster(tmp_path):
    """2 x 2 closed-loop points (+ 1 open loop), python engine, 1.2 s at H = 1 ms, on a
    LocalCluster with one worker process; then the maps."""
    from distributed import Client, LocalCluster

    spec = SweepSpec(SCENE, [1e8, 1e9], [0.0, 1e-3], [1e-3], 1.2, "python", FAST,
                     options={"force_cap": 1e5})
    with LocalCluster(n_workers=1, threads_per_worker=1, processes=True,
                      dashboard_address=None) as cluster, Client(cluster) as client:
        out = run_sweep(spec, tmp_path, scheduler=client.scheduler.address, progress=False)
    assert out.n_run == 5 and out.n_errors == 0
    rows = {(r["gain"], r["delay"]): r for r in read_table(tmp_path) if r["kind"] ==
            "closed_loop"}
    assert set(rows) == {(1e8, 0.0), (1e8, 1e-3), (1e9, 0.0), (1e9, 1e-3)}
    # gain 1e9 with a 1 ms step and 1 ms delay (predicted growth 18 1/s): past the cap by 1.2 s
    assert rows[(1e9, 1e-3)]["status"] == "diverged"
    assert rows[(1e9, 1e-3)]["stable"] == 0.0 and "force cap" in rows[(1e9, 1e-3)]["reason"]
    assert rows[(1e8, 0.0)]["status"] == "ok" and rows[(1e8, 0.0)]["end_time"] == 1.2
    assert all(math.isfinite(r["peak_force"]) and r["wall_time"] > 0 for r in rows.values())
    from drillcosim.cosim.study.maps import plot_maps

    paths = plot_maps(tmp_path, predict=False)
    assert [p.name for p in paths] == ["stability_map.png", "benefit_map.png"]
    assert all(p.stat().st_size > 10_000 for p in paths)


def test_fmu_engine_matches_the_python_engine():
    """Smoke test of the FMU path (plant + controller FMUs in the master): one 0.2 s point
    agrees with the in-process engine."""
    from drillcosim.cosim.study.point import run_point

    args = (SCENE, 1e9, 5e-4, 1e-3, 0.2)
    fmu = run_point(*args, engine="fmu", overrides=FAST)
    py = run_point(*args, engine="python", overrides=FAST)
    assert fmu["status"] == py["status"] == "ok"
    assert fmu["peak_force"] == pytest.approx(py["peak_force"], rel=1e-6)
    assert fmu["peak_deflection_long"] == pytest.approx(py["peak_deflection_long"], rel=1e-6)
