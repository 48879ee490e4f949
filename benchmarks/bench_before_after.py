"""Before/after, side by side in one run: two checkouts of drillcosim, each with its own ``.venv``.

    python benchmarks/bench_before_after.py --before BEFORE --after . \\
        [--stop-time 30] [--sweep-stop-time 10] [--calibrate-stop-time 30] [--repeat 3] \\
        [--out FILE]

BEFORE is another checkout, e.g. ``git worktree add BEFORE <commit>`` and ``make`` there.
Each task runs in a fresh process of the tree's own interpreter (``<tree>/.venv/bin/python``)
in an empty folder, the trees interleaved, best of ``--repeat``; one warm-up round first
(FMU builds, numba caches, unpacked FMUs, the native loop's library), not timed. The processes
run without ``PYTHONDONTWRITEBYTECODE`` (as a user's shell: byte-code caches on). Tasks:

* main job: ``drillcosim run paper_closed_loop --stop-time T`` (plots on), and ``--no-plots``
  with the default controller FMU and with ``StrainControllerC.fmu``;
* start-up: the stages of ``drillcosim run`` up to its first step in a fresh process (the
  tree's own ``benchmarks/bench_one_master.py``: imports, scene, system, FMUs, first step), and
  the whole one-step process (``--stop-time 0.00025 --no-plots``: also the summary, the CSV and
  the interpreter's exit, ~0.2 s of which is numba's teardown), next to the floor
  ``python -c "import numpy, numba"``;
* the plant alone: ``plant.simulator.simulate`` of the scene's plant over T at 1 ms outputs
  (the call, timed in the process after a warm-up call);
* a 7-point sweep (actuator delay 0 .. 1.5 ms), ``--engine python`` (``inprocess`` in trees
  with the one typed configuration) and ``--engine fmu``,
  ``--workers 0`` (in one process, one point after the other);
* the calibration's ``refine`` stage on its first 2 sets (around today's set), 4 members each,
  in one process (``workers=0``).

Ratios: main job / plant alone (target <= 2.5x), default controller / C controller
(<= 1.1x), plots' share of the main job (<= 10 %), start-up minus the floor (<= 0.3 s), and
after / before for every task.
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import platform
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

_PLANT_ALONE = r"""
import json, sys, time
from drillcosim.plant.model import DrillstringModel
from drillcosim.plant.scene import load_scene
from drillcosim.plant.simulator import simulate
sc = load_scene("paper_closed_loop")
model = DrillstringModel(sc.plant, sc.model)
simulate(model, 0.01, 1e-3)
t0 = time.perf_counter()
simulate(model, float(sys.argv[1]), 1e-3)
print(json.dumps(time.perf_counter() - t0))
"""

_REFINE = r"""
import json, sys, tempfile, time
from pathlib import Path
try:
    from drillcosim.cosim.study.paper import calibration as c
except ImportError:                     # before the paper study moved (ae51f5f)
    from drillcosim.cosim.study import calibration as c
from drillcosim.cosim.study.scene_stats import measure_scene
from drillcosim.cosim.study.sweep import execute_points
sets = c.refine_sets(c.TODAY)[:2]
points = c.calibration_points(sets, c.STAGE_MEMBERS["refine"], stop_time=float(sys.argv[1]))
with tempfile.TemporaryDirectory() as d:
    table = c.CalibrationTable(Path(d) / "refine")
    t0 = time.perf_counter()
    execute_points(points, table, measure_scene, workers=0, progress=False, desc="refine")
    wall = time.perf_counter() - t0
    assert len(table.rows) == len(points), table.rows
print(json.dumps(wall))
"""


_FIRST_STEP = r"""
import json, sys
sys.path.insert(0, sys.argv[1])         # the tree's own benchmarks/bench_one_master.py
import bench_one_master
print(json.dumps(sum(bench_one_master.startup().values())))
"""


def _env() -> dict[str, str]:
    env = dict(os.environ)
    env.pop("PYTHONDONTWRITEBYTECODE", None)
    env.pop("DRILLCOSIM_MASTER_LOOP", None)
    env["OPENBLAS_NUM_THREADS"] = "1"
    return env


def _python(tree: Path) -> str:
    py = tree / ".venv" / "bin" / "python"
    if not py.is_file():
        raise SystemExit(f"{tree}: no .venv/bin/python (run `make` in it first)")
    return str(py)


def _timed(cmd: list[str], cwd: str) -> float:
    """Wall time [s] of a process (it must succeed)."""
    t0 = time.perf_counter()
    proc = subprocess.run(cmd, cwd=cwd, env=_env(), capture_output=True, text=True)
    wall = time.perf_counter() - t0
    if proc.returncode != 0:
        raise RuntimeError(f"{' '.join(cmd)} failed ({proc.returncode}):\n{proc.stderr[-3000:]}")
    return wall


def _reported(cmd: list[str], cwd: str) -> float:
    """The number a process prints as its last line (JSON)."""
    proc = subprocess.run(cmd, cwd=cwd, env=_env(), capture_output=True, text=True)
    if proc.returncode != 0:
        raise RuntimeError(f"{' '.join(cmd)} failed ({proc.returncode}):\n{proc.stderr[-3000:]}")
    return float(json.loads(proc.stdout.strip().splitlines()[-1]))


def tasks(tree: Path, args: argparse.Namespace) -> dict[str, tuple[str, list[str]]]:
    """``{task: (kind, argv)}``; kind ``wall`` (process wall time) or ``reported`` (a number
    the process prints)."""
    py = _python(tree)
    cli = [py, "-m", "drillcosim.cosim.cli"]
    run = [*cli, "run", "paper_closed_loop", "--no-progress", "--out", "out"]
    c_fmu = tree / "build" / "fmus" / "StrainControllerC.fmu"
    t, ts = f"{args.stop_time:g}", f"{args.sweep_stop_time:g}"
    sweep = [*cli, "sweep", "paper_closed_loop", "--delay", "0:0.0015:7", "--stop-time", ts,
             "--workers", "0", "--no-progress"]
    # the in-process engine: 'python' before the one typed configuration, 'inprocess' since
    inprocess = "inprocess" if (tree / "cosim" / "scenario" / "build.py").is_file() else "python"
    return {
        f"main job, {t} s, plots": ("wall", [*run, "--stop-time", t]),
        f"main job, {t} s, --no-plots": ("wall", [*run, "--stop-time", t, "--no-plots"]),
        f"main job, {t} s, --no-plots, C controller": (
            "wall", [*run, "--stop-time", t, "--no-plots", "--controller-fmu", str(c_fmu)]),
        "start-up: to the first step (sum of the stages)": (
            "reported", [py, "-c", _FIRST_STEP, str(tree / "benchmarks")]),
        "start-up: one-step run, whole process, --no-plots": (
            "wall", [*run, "--stop-time", "0.00025", "--no-plots"]),
        "floor: python -c 'import numpy, numba'": ("wall", [py, "-c", "import numpy, numba"]),
        f"plant alone, {t} s (simulate call)": ("reported",
                                                [py, "-c", _PLANT_ALONE, str(args.stop_time)]),
        f"sweep, 7 points x {ts} s, --engine python / inprocess": (
            "wall", [*sweep, "--engine", inprocess, "--out", "sweep_py"]),
        f"sweep, 7 points x {ts} s, --engine fmu": (
            "wall", [*sweep, "--engine", "fmu", "--out", "sweep_fmu"]),
        f"calibrate refine, 2 sets x 4 members x {args.calibrate_stop_time:g} s": (
            "reported", [py, "-c", _REFINE, str(args.calibrate_stop_time)]),
    }


#: Every kept value [s] per tree and task, in round order (filled by :func:`measure`).
RUNS: dict[str, dict[str, list[float]]] = {}


def measure(trees: dict[str, Path], args: argparse.Namespace) -> dict[str, dict[str, float]]:
    """Best wall time [s] per tree and task (trees interleaved per task and repeat); every
    value in :data:`RUNS`."""
    plans = {name: tasks(tree, args) for name, tree in trees.items()}
    best: dict[str, dict[str, float]] = {name: {} for name in trees}
    RUNS.update({name: {} for name in trees})
    for rnd in range(args.repeat + 1):            # round 0: warm-up, not kept
        for task in plans[next(iter(trees))]:
            if args.only and not any(o in task for o in args.only):
                continue
            for name in trees:
                kind, cmd = plans[name][task]
                with tempfile.TemporaryDirectory() as cwd:
                    value = (_timed if kind == "wall" else _reported)(cmd, cwd)
                if rnd:
                    best[name][task] = min(best[name].get(task, float("inf")), value)
                    RUNS[name].setdefault(task, []).append(value)
                print(f"[{rnd}] {name:6s} {task}: {value:.3f} s", file=sys.stderr)
    return best


def _median_share(runs: dict[str, list[float]], t: str) -> float:
    """Median over the rounds of 1 - (main job --no-plots) / (main job with plots), each
    round's two runs taken side by side (NaN without both)."""
    plots, bare = runs.get(f"main job, {t} s, plots"), runs.get(f"main job, {t} s, --no-plots")
    if not plots or not bare:
        return float("nan")
    return statistics.median(1.0 - b / p for p, b in zip(plots, bare))


def report(best: dict[str, dict[str, float]], trees: dict[str, Path],
           args: argparse.Namespace) -> str:
    names = list(trees)
    t = f"{args.stop_time:g}"
    lines = ["## Before / after (benchmarks/bench_before_after.py)", "",
             f"Command: `python benchmarks/bench_before_after.py --before {trees[names[0]]} "
             f"--after {trees[names[-1]]} --stop-time {t} --sweep-stop-time "
             f"{args.sweep_stop_time:g} --calibrate-stop-time {args.calibrate_stop_time:g} "
             f"--repeat {args.repeat}`; {platform.platform()}, {os.cpu_count()} cores, Python "
             f"{platform.python_version()}, {datetime.datetime.now():%Y-%m-%d %H:%M}; "
             f"best of {args.repeat} interleaved runs after a warm-up round; load average at "
             f"the end {os.getloadavg()[0]:.1f}.", "",
             "| task | " + " | ".join(f"{n} [s]" for n in names) + " | after / before |",
             "|---|" + "---:|" * (len(names) + 1)]
    tasks_ = list(best[names[0]])
    for task in tasks_:
        vals = [best[n].get(task, float("nan")) for n in names]
        lines.append(f"| {task} | " + " | ".join(f"{v:.2f}" for v in vals)
                     + f" | {vals[-1] / vals[0]:.2f} |")
    lines += ["", "| ratio (target) | " + " | ".join(names) + " |",
              "|---|" + "---:|" * len(names)]

    def get(n: str, key: str) -> float:
        return next((v for k, v in best[n].items() if k.startswith(key)), float("nan"))

    rows = {
        "main job (plots) / plant alone (<= 2.5x)": lambda n: (
            get(n, f"main job, {t} s, plots") / get(n, "plant alone"), "{:.2f}x"),
        "main job --no-plots: default controller / C controller (<= 1.1x)": lambda n: (
            get(n, f"main job, {t} s, --no-plots") / get(n, f"main job, {t} s, --no-plots, C"),
            "{:.2f}x"),
        "plots' share of the main job (<= 10 %)": lambda n: (
            100 * (1 - get(n, f"main job, {t} s, --no-plots") / get(n, f"main job, {t} s, plots")),
            "{:.1f} %"),
        "plots' share, median over the rounds (each round's pair)": lambda n: (
            100 * _median_share(RUNS.get(n, {}), t), "{:.1f} %"),
        "start-up to the first step minus the floor (<= 0.3 s)": lambda n: (
            get(n, "start-up: to the first step") - get(n, "floor"), "{:.2f} s"),
        "one-step run (whole process) minus the floor": lambda n: (
            get(n, "start-up: one-step run") - get(n, "floor"), "{:.2f} s"),
    }
    for label, f in rows.items():
        cells = []
        for n in names:
            value, fmt = f(n)
            cells.append(fmt.format(value))
        lines.append(f"| {label} | " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--before", required=True, type=Path, help="checkout of the old commit")
    ap.add_argument("--after", required=True, type=Path, help="checkout of the new one")
    ap.add_argument("--stop-time", type=float, default=30.0, help="main job [s]")
    ap.add_argument("--sweep-stop-time", type=float, default=10.0, help="per sweep point [s]")
    ap.add_argument("--calibrate-stop-time", type=float, default=30.0,
                    help="per calibration member [s] (the stage's own: 30)")
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--only", action="append", default=[],
                    help="run only the tasks whose name contains this (repeatable)")
    ap.add_argument("--out", help="write the markdown section here (default: print)")
    args = ap.parse_args(argv)
    trees = {"before": args.before.resolve(), "after": args.after.resolve()}
    best = measure(trees, args)
    text = report(best, trees, args)
    if args.out:
        Path(args.out).write_text(text)
    print(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
