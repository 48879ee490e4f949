"""Sweeps: list syntax, table robustness, resume, bad points, dask, FMU engine smoke test."""

from __future__ import annotations

import csv
import math
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from drillcosim.cosim.study.grid import Point, parse_list
from drillcosim.cosim.study.sweep import SweepSpec, execute_sweep, point_row
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


#: Completion order of :func:`ordered_runner`, from the environment (spawned workers inherit
#: it): "<sweep folder>:<order>". The barrier is the sweep's own table: a point waits until
#: the rows it must follow are *written* (a worker having finished them is not enough: under
#: load the sweep can receive a closed-loop and an open-loop result in one batch).
#: references_first: closed-loop points wait for both open-loop rows; references_last:
#: open-loop points wait for all 12 closed-loop rows; references_held: open-loop points never
#: finish (the sweep is killed while they wait).
ORDER_ENV = "DRILLCOSIM_TEST_SWEEP_ORDER"
BARRIER_TIMEOUT = 300.0     # s; a barrier never met is a bug of the test: the point errors


def _wait_for_rows(folder: Path, kind: str, count: int) -> None:
    deadline = time.time() + BARRIER_TIMEOUT
    while time.time() < deadline:
        if sum(r["kind"] == kind for r in read_table(folder)) >= count:
            return
        time.sleep(0.01)
    raise RuntimeError(f"test barrier: {count} {kind} rows not written in {folder} after "
                       f"{BARRIER_TIMEOUT:g} s")


def ordered_runner(scene, gain, delay, step, stop_time, engine, open_loop=False, overrides=None,
                   **options):
    """Measured values that exercise every verdict, finishing in the order ORDER_ENV asks.

    Per step H = 1 ms / 2 ms: open loop growth 1 +- 0.1 1/s; closed loop growth 1 + gain
    (excess = gain): 0.1 stable, 0.55 undecided (within the noise), 2.0 unstable; gain 3
    diverges, gain 13 raises; gain 0.2 at H = 2 ms is too short (min_stop_time 9 s).
    """
    order = os.environ.get(ORDER_ENV)
    if order:
        folder, how = order.rsplit(":", 1)
        if how == "references_last" and open_loop:
            _wait_for_rows(Path(folder), "closed_loop", 12)
        if how == "references_first" and not open_loop:
            _wait_for_rows(Path(folder), "open_loop", 2)
        if how == "references_held" and open_loop:
            _wait_for_rows(Path(folder), "open_loop", 1)      # never: none can finish
    return _ordered_result(gain, step, stop_time, open_loop)


def _ordered_result(gain, step, stop_time, open_loop):
    if gain == 13.0:
        raise RuntimeError("injected failure")
    if gain == 3.0:
        return {"status": "diverged", "reason": "diverged at t = 0.5 s: injected",
                "end_time": 0.5, "divergence_time": 0.5, "growth_rate": 7.0,
                "growth_noise": 0.1, "rms_long": math.nan, "rms_short": math.nan,
                "wall_time": 0.0}
    return {"status": "ok", "reason": "", "end_time": stop_time, "divergence_time": math.nan,
            "growth_rate": 1.0 + (0.0 if open_loop else gain), "growth_noise": 0.1,
            "min_stop_time": math.nan if open_loop else (9.0 if gain == 0.2 and step == 2e-3
                                                         else 1.0),
            "rms_long": 1.0 if open_loop else 1.0 - gain / 10, "rms_short": 2.0,
            "peak_force": gain, "peak_power": 0.0, "wall_time": 0.0}


ORDERED = SweepSpec(SCENE, [0.1, 0.2, 0.55, 2.0, 3.0, 13.0], [0.0], [1e-3, 2e-3], 2.0, "inprocess")


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


def test_a_stop_time_that_is_not_a_whole_number_of_steps_is_refused():
    with pytest.raises(ValueError, match="6 s: not a whole number of steps of 0.00035 s"):
        SweepSpec(SCENE, [1e9], [0.0], [1e-4, 3.5e-4], 6.0, "inprocess").points()
    assert len(SweepSpec(SCENE, [1e9], [0.0], [1e-4, 4e-4], 6.0, "inprocess").points()) == 4


def test_points_open_loop_first_and_keys_unique():
    spec = SweepSpec(SCENE, [1e8, 1e9], [0.0, 1e-4], [2.5e-4, 5e-4], 1.0, "inprocess")
    pts = spec.points()
    assert len(pts) == 2 + 8
    assert [p.kind for p in pts[:2]] == ["open_loop"] * 2
    assert len({p.key for p in pts}) == len(pts)


# --- table --------------------------------------------------------------------------------
def test_table_drops_a_half_written_row(tmp_path):
    t = ResultTable(tmp_path)
    p = Point(SCENE, 1e9, 0.0, 1e-3, 1.0, "inprocess")
    t.append(point_row(p, fake_runner))
    with open(t.csv_path, "a") as fh:          # a kill in the middle of a write
        fh.write("paper_closed_loop|inprocess|closed_loop|1e8,paper_clo")
    rows = ResultTable(tmp_path).rows
    assert [r["key"] for r in rows] == [p.key]
    assert not t.csv_path.read_text().endswith("\n")     # a reader writes nothing
    assert [r["key"] for r in ResultTable(tmp_path).load(repair=True)] == [p.key]
    assert t.csv_path.read_text().endswith("\n")
    assert t.csv_path.read_text().count("\n") == 2       # header + 1 row, repaired


def test_duplicate_rows_keep_the_newest_and_the_folder_is_locked(tmp_path):
    t = ResultTable(tmp_path)
    p = Point(SCENE, 1e9, 0.0, 1e-3, 1.0, "inprocess")
    row = point_row(p, fake_runner)
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
    spec = SweepSpec(SCENE, [1.0], [0.0], [1e-3], 1.0, "inprocess")
    execute_sweep(spec, tmp_path, workers=0, measure=fake_runner, progress=False)
    rows = {r["kind"]: r for r in read_table(tmp_path)}
    assert rows["closed_loop"]["benefit_long"] == pytest.approx(0.5)
    assert rows["closed_loop"]["benefit_short"] == pytest.approx(0.0)
    parquet = read_table(tmp_path / "results.parquet")
    assert {r["key"] for r in parquet} == {r["key"] for r in rows.values()}
    assert set(parquet[0]) == set(COLUMNS)


# --- bad points ---------------------------------------------------------------------------
def test_bad_points_are_recorded_with_their_reason(tmp_path):
    """A raising runner (gain 13) and a real point with invalid input (negative delay)."""
    spec = SweepSpec(SCENE, [1.0, 13.0], [0.0], [1e-3], 1.0, "inprocess")
    out = execute_sweep(spec, tmp_path, workers=1, measure=fake_runner, progress=False)
    rows = {r["gain"]: r for r in read_table(tmp_path) if r["kind"] == "closed_loop"}
    assert out.n_errors == 1 and out.n_run == 3
    assert rows[13.0]["status"] == "error"
    assert rows[13.0]["reason"].startswith("RuntimeError: injected failure second line")
    assert rows[1.0]["status"] == "ok"
    bad = point_row(Point(SCENE, 1e9, -1e-3, 1e-3, 0.01, "inprocess"))
    assert bad["status"] == "error" and "actuator_delay" in bad["reason"]


def test_a_dying_worker_is_recorded_and_the_sweep_goes_on(tmp_path):
    spec = SweepSpec(SCENE, [1.0, 7.0], [0.0], [1e-3], 1.0, "inprocess")
    out = execute_sweep(spec, tmp_path, workers=1, measure=dying_runner, progress=False)
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
        "from drillcosim.cosim.study.sweep import SweepSpec, execute_sweep\n"
        "spec = SweepSpec({!r}, [1.0, 2.0, 3.0, 4.0, 5.0, 6.0], [0.0], [1e-3], 1.0, 'inprocess')\n"
        "execute_sweep(spec, {!r}, workers=0, measure=slow_runner, progress=False)\n"
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
    spec = SweepSpec(SCENE, [1.0, 2.0, 3.0, 4.0, 5.0, 6.0], [0.0], [1e-3], 1.0, "inprocess")
    out = execute_sweep(spec, tmp_path, workers=0, measure=fake_runner, progress=False)
    assert out.n_skipped == len(before) and out.n_run == 7 - len(before)
    rows = read_table(tmp_path)
    assert len(rows) == 7 and len({r["key"] for r in rows}) == 7
    again = execute_sweep(spec, tmp_path, workers=0, measure=fake_runner, progress=False)
    assert again.n_run == 0 and again.n_skipped == 7


# --- order independence -------------------------------------------------------------------
def _table(folder: Path) -> list[dict]:
    """Both files of a sweep folder, read raw (no repair), checked equal; sorted by key,
    without the wall times (the columns that differ between runs)."""
    import pyarrow.parquet as pq

    lines = list(csv.reader(open(folder / "results.csv")))
    assert lines[0] == list(COLUMNS)
    text = {"key", "scene", "engine", "kind", "varied", "status", "verdict", "prediction_note",
            "benefit_note", "reason"}
    from_csv = [{c: (v if c in text else (float(v) if v else math.nan))
                 for c, v in zip(COLUMNS, line)} for line in lines[1:]]
    from_parquet = pq.read_table(folder / "results.parquet").to_pylist()
    assert len(from_csv) == len(from_parquet)
    for a, b in zip(from_csv, from_parquet):        # same rows, same order
        assert set(a) == set(b)
        for c in COLUMNS:
            assert a[c] == b[c] or (a[c] != a[c] and b[c] != b[c]), (a["key"], c, a[c], b[c])
    rows = sorted(from_csv, key=lambda r: r["key"])
    for r in rows:
        for c in ("wall_time", "startup_time", "stepping_time", "worker_startup"):
            r.pop(c)
    return rows


def _same_tables(a: list[dict], b: list[dict]) -> None:
    assert [r["key"] for r in a] == [r["key"] for r in b]
    for ra, rb in zip(a, b):
        for c in ra:
            x, y = ra[c], rb[c]
            assert x == y or (x != x and y != y), (ra["key"], c, x, y)


@pytest.fixture(scope="module")
def clean_ordered_run(tmp_path_factory):
    """ORDERED run in this process, points one after another (references first)."""
    folder = tmp_path_factory.mktemp("clean")
    out = execute_sweep(ORDERED, folder, workers=0, measure=ordered_runner, progress=False)
    return folder, out


def test_verdicts_of_the_ordered_runner(clean_ordered_run):
    folder, out = clean_ordered_run
    rows = {(r["gain"], r["step"]): r for r in read_table(folder) if r["kind"] == "closed_loop"}
    for h in (1e-3, 2e-3):
        assert rows[(0.1, h)]["verdict"] == "stable" and rows[(0.1, h)]["stable"] == 1.0
        assert rows[(0.55, h)]["verdict"] == "undecided"
        assert "within the noise" in rows[(0.55, h)]["reason"]
        assert math.isnan(rows[(0.55, h)]["stable"])
        assert rows[(2.0, h)]["verdict"] == "unstable" and rows[(2.0, h)]["stable"] == 0.0
        assert rows[(3.0, h)]["verdict"] == "unstable" and "injected" in rows[(3.0, h)]["reason"]
        assert rows[(13.0, h)]["verdict"] == "error"
    assert rows[(0.2, 1e-3)]["verdict"] == "stable"
    assert rows[(0.2, 2e-3)]["verdict"] == "undecided"
    assert rows[(0.2, 2e-3)]["reason"].startswith("too short to judge")
    assert out.counts == {"stable": 3, "unstable": 4, "undecided": 3, "reference": 2,
                          "error": 2}


@pytest.mark.slow
@pytest.mark.parametrize("order", ["references_first", "references_last"])
def test_table_and_summary_do_not_depend_on_completion_order(clean_ordered_run, tmp_path,
                                                             monkeypatch, order):
    """A process pool whose points finish in a forced order (open-loop references first, or
    last: closed-loop rows are written before the reference they are judged against): the
    CSV equals the Parquet copy, and both equal the clean run's table; same summary."""
    monkeypatch.setenv(ORDER_ENV, f"{tmp_path / 'sweep'}:{order}")
    out = execute_sweep(ORDERED, tmp_path / "sweep", workers=3, measure=ordered_runner,
                    progress=False)
    tmp_path = tmp_path / "sweep"
    kinds = [r["kind"] for r in read_table(tmp_path)]      # completion order
    if order == "references_last":
        assert kinds[-2:] == ["open_loop"] * 2, kinds
    else:
        assert kinds[:2] == ["open_loop"] * 2, kinds
    clean_folder, clean = clean_ordered_run
    _same_tables(_table(tmp_path), _table(clean_folder))
    assert out.summary().replace(str(tmp_path), "") == \
        clean.summary().replace(str(clean_folder), "")
    assert out.counts == clean.counts


@pytest.mark.slow
def test_killed_process_group_then_resume_equals_a_clean_run(clean_ordered_run, tmp_path):
    """Kill a sweep's whole process group (the sweep and its pool workers) once a few
    closed-loop rows are written while their references are still running; the resumed sweep
    re-judges them and its table and summary equal a clean run's."""
    script = (
        "import sys; sys.path.insert(0, {!r})\n"
        "from test_sweep import ORDERED, ordered_runner\n"
        "from drillcosim.cosim.study.sweep import execute_sweep\n"
        "execute_sweep(ORDERED, {!r}, workers=3, measure=ordered_runner, progress=False)\n"
    ).format(str(ROOT / "tests"), str(tmp_path))
    env = {**os.environ, ORDER_ENV: f"{tmp_path}:references_held"}
    proc = subprocess.Popen([sys.executable, "-c", script], cwd=ROOT, env=env,
                            start_new_session=True)
    csv_path = tmp_path / "results.csv"
    deadline = time.time() + BARRIER_TIMEOUT
    try:
        while time.time() < deadline:
            text = csv_path.read_text() if csv_path.exists() else ""
            # header + 3 rows, one of them a closed-loop row written before its references
            if text.count("\n") >= 4 and "no completed open-loop reference" in text:
                break
            time.sleep(0.02)
    finally:
        os.killpg(proc.pid, signal.SIGKILL)
        proc.wait()
    before = read_table(tmp_path)
    assert 3 <= len(before) < 14
    assert any(r["verdict"] == "undecided" and "no completed open-loop reference" in r["reason"]
               for r in before)                 # written before its reference: not judged yet
    out = execute_sweep(ORDERED, tmp_path, workers=0, measure=ordered_runner, progress=False)
    assert out.n_skipped == len(before) and out.n_run == 14 - len(before)
    clean_folder, clean = clean_ordered_run
    _same_tables(_table(tmp_path), _table(clean_folder))
    assert out.summary().replace(str(tmp_path), "") == \
        clean.summary().replace(str(clean_folder), "")


def test_a_stale_derived_column_is_repaired_by_the_next_sweep(tmp_path):
    """A CSV row written before its reference (an older version kept it forever) is
    re-judged when read, and the files are repaired by the next (resumed) sweep."""
    spec = SweepSpec(SCENE, [2.0], [0.0], [1e-3], 2.0, "inprocess")
    execute_sweep(spec, tmp_path, workers=0, measure=ordered_runner, progress=False)
    path = tmp_path / "results.csv"
    text = path.read_text()
    assert ",unstable,0.0," in text
    path.write_text(text.replace(",unstable,0.0,", ",stable,1.0,"))
    rows = {r["kind"]: r for r in read_table(tmp_path)}
    assert rows["closed_loop"]["verdict"] == "unstable"
    assert ",stable,1.0," in path.read_text()                  # read only
    out = execute_sweep(spec, tmp_path, workers=0, measure=ordered_runner, progress=False)
    assert out.n_run == 0 and ",unstable,0.0," in path.read_text()
    _table(tmp_path)


# --- verdict rules ----------------------------------------------------------------------------
def test_judge_rules():
    """Each rule of cosim.study.verdict, from a row and its reference alone."""
    from drillcosim.cosim.study.verdict import GROWTH_MARGIN, NOISE_FACTOR, judge

    ref = {"kind": "open_loop", "status": "ok", "growth_rate": 1.0, "growth_noise": 0.03}
    row = {"kind": "closed_loop", "status": "ok", "end_time": 6.0, "min_stop_time": 5.9,
           "growth_noise": 0.04}                  # noise of the excess: hypot = 0.05
    band = NOISE_FACTOR * 0.05

    def verdict(**kw):
        return judge({**row, **kw}, kw.pop("reference", ref))[:2]

    assert verdict(growth_rate=1.0 + GROWTH_MARGIN + band + 1e-9)[0] == "unstable"
    assert verdict(growth_rate=1.0 + GROWTH_MARGIN + band - 1e-9)[0] == "undecided"
    assert verdict(growth_rate=1.0 + GROWTH_MARGIN - band + 1e-9)[0] == "undecided"
    # below the margin: stable only within the noise of no extra growth
    v, why = verdict(growth_rate=1.0 + GROWTH_MARGIN - band - 1e-9)
    assert v == "undecided" and "less than the 0.5 1/s margin" in why
    assert verdict(growth_rate=1.0 + band + 1e-9)[0] == "undecided"
    assert verdict(growth_rate=1.0 + band - 1e-9) == ("stable", "")
    assert verdict(growth_rate=0.2) == ("stable", "")      # less growth than open loop
    # a noisy window: the margin's band reaches below zero, nothing is stable
    noisy = {"growth_noise": 0.3, "reference": {**ref, "growth_noise": 0.0}}
    assert verdict(growth_rate=1.0, **noisy)[0] == "undecided"
    v, why = verdict(growth_rate=9.0, end_time=5.0)          # too short wins over growth
    assert v == "undecided" and why.startswith("too short") and "5.9 s" in why
    assert verdict(growth_rate=1.0, reference=None) == (
        "undecided", "no completed open-loop reference run (missing)")
    assert verdict(growth_rate=1.0, reference={**ref, "status": "error"})[0] == "undecided"
    assert verdict(growth_rate=math.nan)[0] == "undecided"
    assert verdict(status="diverged", reason="boom", end_time=0.1) == ("unstable", "boom")
    assert verdict(status="error", reason="bad") == ("error", "bad")
    assert judge(ref, None)[:2] == ("reference", "")


def test_judging_window_from_modes():
    """transient end = start-up + 3 / (slowest decay above the cut-off); min stop time =
    max(transient end / (1 - f), (1 / margin) / f)."""
    from drillcosim.cosim.study.verdict import judging_window

    lam = [-0.1 + 50j, -0.1 - 50j, -2.0 + 150j, -1.5 + 400j, -300.0 + 2000j]
    w = judging_window(lam, start_up=1.0, highpass=100.0, fit_fraction=0.5)
    assert (w.slowest_frequency, w.slowest_decay) == (400.0, 1.5)
    assert w.transient_end == pytest.approx(1.0 + 3.0 / 1.5)
    assert w.min_stop_time == pytest.approx(6.0)
    assert judging_window(lam, 1.0, 100.0, 0.9).min_stop_time == pytest.approx(3.0 / 0.1)
    # a fast-settling plant: the window length (one e-fold at the margin rate) decides
    assert judging_window([-30 + 400j], 0.0, 100.0, 0.5).min_stop_time == pytest.approx(4.0)
    assert judging_window(lam, 1.0, 0.0, 0.5).slowest_decay == 0.1   # no filter: all modes


@pytest.mark.slow
def test_short_runs_are_undecided_and_long_runs_are_judged(tmp_path, capsys):
    """paper_closed_loop, inprocess engine, H = 0.25 ms: gain 1e8 without delay is undecided in
    1 s runs (inside the start-up transient; the CLI says so in one line) and stable in 6 s
    runs; gain 1e9 with 1 ms of delay (predicted growth +13 1/s) is unstable in 6 s runs."""
    from drillcosim.cosim.cli import main
    from drillcosim.cosim.study.verdict import scene_judging_window

    need = scene_judging_window(SCENE).min_stop_time
    assert 1.0 < need <= 6.0
    common = ["sweep", SCENE, "--engine", "inprocess", "--delay", "0,1e-3", "--workers", "0",
              "--no-progress"]
    assert main([*common, "--gain", "1e8", "--stop-time", "1", "--out", str(tmp_path / "a")]) == 0
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and f"below the {need:.3g} s needed" in err, err
    rows = {(r["gain"], r["delay"]): r for r in read_table(tmp_path / "a")
            if r["kind"] == "closed_loop"}
    assert rows[(1e8, 0.0)]["verdict"] == "undecided"
    assert rows[(1e8, 0.0)]["reason"].startswith("too short to judge")
    assert main([*common, "--gain", "1e8,1e9", "--stop-time", "6",
                 "--out", str(tmp_path / "b")]) == 0
    assert capsys.readouterr().err == ""
    rows = {(r["gain"], r["delay"]): r for r in read_table(tmp_path / "b")
            if r["kind"] == "closed_loop"}
    assert rows[(1e8, 0.0)]["verdict"] == "stable", rows[(1e8, 0.0)]
    assert rows[(1e9, 1e-3)]["verdict"] == "unstable", rows[(1e9, 1e-3)]


# --- real engines -------------------------------------------------------------------------
@pytest.mark.slow
def test_small_sweep_on_a_dask_local_cluster(tmp_path):
    """2 x 2 closed-loop points (+ 1 open loop), inprocess engine, 1.2 s at H = 1 ms, on a
    LocalCluster with one worker process; then the maps."""
    from distributed import Client, LocalCluster

    spec = SweepSpec(SCENE, [1e8, 1e9], [0.0, 1e-3], [1e-3], 1.2, "inprocess", FAST,
                     options={"force_cap": 1e5})
    with LocalCluster(n_workers=1, threads_per_worker=1, processes=True,
                      dashboard_address=None) as cluster, Client(cluster) as client:
        out = execute_sweep(spec, tmp_path, scheduler=client.scheduler.address, progress=False)
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
    assert [p.name for p in paths] == ["stability_map.png", "benefit_map.png", "growth_rate.png"]
    assert all(p.stat().st_size > 10_000 for p in paths)


@pytest.mark.parametrize("gain,delay,step,cosim", [
    (1e9, 5e-4, 1e-3, {"output_interval": 1e-3}),
    (1e9, 1.3e-4, 2.5e-4, {"algorithm": "jacobi", "coupling": "linear", "sensor_delay": 3e-4}),
])
def test_fmu_and_in_process_slaves_give_the_same_run_bit_for_bit(gain, delay, step, cosim):
    """One master, two sets of slaves: the plant and controller FMUs, or the same models in
    process (cosim.scenario.inprocess). Every recorded value is identical, for Gauss-Seidel
    with a hold and for Jacobi with linear coupling and fractional delays."""
    from drillcosim.cosim.study.point import PointOptions, point_config, simulate_point

    config = point_config(SCENE, gain, delay, step, 0.2, False, {"cosim": cosim})
    fmu, reason_fmu = simulate_point(config, PointOptions(), "fmu")
    py, reason_py = simulate_point(config, PointOptions(), "inprocess")
    assert reason_fmu == reason_py == ""
    assert fmu.dtype.names == py.dtype.names and len(fmu) == 201
    assert np.any(fmu["controller.actuator1_force_C"] != 0.0)
    for name in fmu.dtype.names:
        assert fmu[name].tobytes() == py[name].tobytes(), name
