"""One master, two sets of slaves; and the start-up of ``drillcosim run``, side by side in one run.

    python benchmarks/bench_one_master.py [--stop-time 10] [--repeat 3] [--out FILE]

1. ``paper_closed_loop`` at its step (0.25 ms, Gauss-Seidel) through our master
   (:class:`cosim.master.execution.Execution` + the recorder at 1 ms), once with the plant and
   controller FMUs, once with the same models in process (:mod:`cosim.scenario.inprocess`):
   real-time factors of the stepping loop and their ratio (target: FMU >= 0.8x the
   in-process slaves). Configurations interleaved, ``--repeat`` times, best reported.
2. Start-up of ``drillcosim run paper_closed_loop`` in fresh processes: time from the start of
   the interpreter to the first step, split into the interpreter itself (``python -c pass``),
   imports (cli, scenario, plant scene), scene loading, system building (FMU staleness check),
   FMU extraction and ``Execution.initialize`` (instantiation: the FMUs' own imports, numba cache
   load, model build). Best of ``--repeat`` (target <= 1 s).
3. The whole ``drillcosim run paper_closed_loop`` process for ``--whole-stop-time`` (default the
   scene's 30 s; target >= 8x real time): with plots, without, and without plots with
   the C controller FMU. Best of ``--repeat``.
4. Where a 0.25 ms step goes, each part timed alone in this process (mean of 4000 calls): the
   plant's compiled RK4 span, the plant's Python step with its checks and outputs, the
   controller law, the two FMUs' doStep through the master's slave objects. From these the
   real-time factor the whole run could reach if everything but a given part cost nothing.
5. The master's own budget per 0.25 ms step (:func:`master_budget`): two tiny FMUs whose
   doStep never enters Python (the test FMU ``mt_compiled``: a numba step called by our C
   wrapper, Real buffers), wired like the closed loop (Gauss-Seidel, one delayed connection,
   a recorder every 4 steps): each FMI call from Python (ctypes, as the Python loop makes
   it), the recorder's row, the whole step in the Python loop and in the native loop (chunks
   in C, :mod:`cosim.master.native`); and ``paper_closed_loop`` through its FMUs in both
   loops.
"""

from __future__ import annotations

import argparse
import ctypes
import datetime
import json
import os
import platform
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
H_LOOP = 0.00025          #: the closed loop's base step [s]

#: Run in a fresh interpreter: the path of ``drillcosim run`` up to its first step, timed.
_STARTUP = r"""
import time
T0 = time.perf_counter()
marks = {}
from drillcosim.cosim import cli                       # the console script's module
from drillcosim.cosim.scenario import simulate as simulate_module
marks["import cli + scenario.simulate (numpy, fmpy, the master)"] = time.perf_counter()
from drillcosim.cosim.scenario.config import load_config
marks["import scenario.config (numba, scipy, the plant model)"] = time.perf_counter()
config = load_config("paper_closed_loop", {"cosim.stop_time": 0.00025})
marks["load the scene"] = time.perf_counter()
from drillcosim.cosim.scenario.build import build_system
ss = build_system(config, "fmu")
marks["build the system (FMU staleness check)"] = time.perf_counter()
from drillcosim.cosim.master.execution import Execution
ex = Execution(ss.system, read_outputs=ss.outputs)
marks["extract the FMUs"] = time.perf_counter()
ex.initialize()
marks["instantiate + initialize (FMU imports, numba cache, model build)"] = time.perf_counter()
ex.simulate_until(0.00025)
marks["first step"] = time.perf_counter()
ex.close()
import json, sys
prev, out = T0, {}
for k, v in marks.items():
    out[k] = v - prev
    prev = v
json.dump(out, sys.stdout)
"""


def _with_loop(loop: str | None):
    """Set ``DRILLCOSIM_MASTER_LOOP`` (None: leave it) and return the previous value."""
    from drillcosim.cosim.master.native.runner import LOOP_ENV

    old = os.environ.get(LOOP_ENV)
    if loop is not None:
        os.environ[LOOP_ENV] = loop
    return old


def closed_loop(stop: float, engine: str, loop: str | None = None) -> float:
    """Wall time [s] of the stepping loop of paper_closed_loop for ``stop`` s (``loop``:
    ``"python"`` or ``"auto"`` for the master's loop; None: as the environment says)."""
    from drillcosim.cosim.master.execution import Execution
    from drillcosim.cosim.master.recorder import Recorder
    from drillcosim.cosim.scenario.build import build_system
    from drillcosim.cosim.scenario.config import load_config

    ss = build_system(load_config("paper_closed_loop", {"cosim.stop_time": stop}),
                      "inprocess" if engine == "in-process" else "fmu")
    old = _with_loop(loop)
    try:
        with Execution(ss.system, read_outputs=ss.outputs, slaves=ss.slaves) as ex:
            ex.add_observer(Recorder(ss.outputs, ss.config.cosim.output_ticks))
            ex.initialize()
            t0 = time.perf_counter()
            ex.simulate_until(stop)
            return time.perf_counter() - t0
    finally:
        _with_loop(old) if old is not None else os.environ.pop("DRILLCOSIM_MASTER_LOOP", None)


def startup() -> dict[str, float]:
    """Seconds per stage of one fresh ``drillcosim run`` up to its first step."""
    t0 = time.perf_counter()
    subprocess.run([sys.executable, "-c", "pass"], check=True)
    interp = time.perf_counter() - t0
    proc = subprocess.run([sys.executable, "-c", _STARTUP], check=True, capture_output=True,
                          text=True, cwd=ROOT)
    return {"interpreter (python -c pass)": interp, **json.loads(proc.stdout)}


def whole_run(stop: float, *extra: str) -> float:
    """Wall time [s] of one ``drillcosim run paper_closed_loop`` process (fresh interpreter)."""
    import tempfile
    with tempfile.TemporaryDirectory() as out:
        t0 = time.perf_counter()
        subprocess.run([sys.executable, "-m", "drillcosim.cosim.cli", "run", "paper_closed_loop",
                        "--stop-time", f"{stop:g}", "--no-progress", "--out", out, *extra],
                       check=True, capture_output=True, cwd=out)
        return time.perf_counter() - t0


def _mean_us(f, n: int = 4000) -> float:
    t0 = time.perf_counter()
    for _ in range(n):
        f()
    return (time.perf_counter() - t0) / n * 1e6


def step_parts(h: float = 0.00025) -> dict[str, float]:
    """Microseconds per 0.25 ms step of each part of the closed loop, timed alone."""
    from drillcosim.cosim.master.slave import FmuSlave
    from drillcosim.cosim.scenario.build import build_system
    from drillcosim.cosim.scenario.config import load_config

    ss = build_system(load_config("paper_closed_loop"), "fmu")
    local = build_system(ss.config, "inprocess").slaves
    sim, law = local["plant"].sim, local["controller"].law
    model = sim.model
    sim.time = 0.0
    clock = {"t": 0.0}

    def physics():
        t = clock["t"]
        model.advance_span(t, t + h, sim.max_step, sim.y, sim.u)
        clock["t"] = sim.time = t + h

    def plant_step():
        t = clock["t"]
        sim.do_step(t, h)
        sim.outputs()
        clock["t"] = t + h

    strains = [1e-6, -1e-6, 2e-6, 0.5e-6]

    def law_step():
        law.step(clock["t"], h, strains)
        clock["t"] += h

    parts = {"plant physics: compiled RK4 span (`advance_span`)": _mean_us(physics)}
    clock["t"] = 0.0
    sim.time = 0.0
    parts["plant in process: `PlantSimulator.do_step` + outputs"] = _mean_us(plant_step)
    clock["t"] = 0.0
    parts["controller law in process (`StrainController.step`)"] = _mean_us(law_step)
    for spec in ss.system.fmus:
        slave = FmuSlave(spec)
        slave.instantiate(0.0, None)
        names = {c: [v.name for v in slave.model_description.modelVariables
                     if v.causality == c and v.type == "Real"] for c in ("input", "output")}
        y = (ctypes.c_double * max(1, len(names["output"])))()
        u = (ctypes.c_double * max(1, len(names["input"])))()
        slave.bind(names["output"], y, 0, names["input"], u)
        clock["t"] = 0.0

        def fmu_step(slave=slave):
            slave.write_inputs()
            slave.do_step(clock["t"], h)
            slave.read_outputs()
            clock["t"] += h
        parts[f"{spec.name} FMU: set all inputs, doStep, get all outputs (`FmuSlave`)"] = \
            _mean_us(fmu_step)
        slave.close()
    return parts


def _tiny_system(fmu: Path):
    """Two compiled tiny FMUs wired like the closed loop: a -> b direct, b -> a delayed 2 H."""
    from drillcosim.cosim.master.system import Connection, FmuSpec, SystemSpec

    return SystemSpec([FmuSpec("a", fmu), FmuSpec("b", fmu)],
                      [Connection("a.x", "b.u"), Connection("b.x", "a.u", delay=2 * H_LOOP)],
                      H_LOOP, "gauss_seidel", ("b", "a"))


def _tiny_loop_us(fmu: Path, loop: str, steps: int, record: bool) -> float:
    """Microseconds per step of the tiny system in the master's ``loop``."""
    from drillcosim.cosim.master.execution import Execution
    from drillcosim.cosim.master.recorder import Recorder

    outputs = ["a.x", "b.x", "a.n_compiled", "b.n_compiled"]
    old = _with_loop(loop)
    try:
        with Execution(_tiny_system(fmu), read_outputs=outputs) as ex:
            if record:
                ex.add_observer(Recorder(outputs, 4))
            ex.initialize()
            t0 = time.perf_counter()
            ex.simulate_until(steps * H_LOOP)
            wall = time.perf_counter() - t0
            assert ex.get_real("a.n_compiled") == steps, "the tiny FMU stepped in Python"
            return wall / steps * 1e6
    finally:
        _with_loop(old) if old is not None else os.environ.pop("DRILLCOSIM_MASTER_LOOP", None)


def master_budget(steps: int = 40000, repeat: int = 3, stop: float = 2.0) -> dict[str, float]:
    """Microseconds per 0.25 ms step of the master's own work (see the module docstring, 5)."""
    sys.path.insert(0, str(ROOT / "tests"))
    from drillcosim.cosim.master.recorder import Recorder
    from drillcosim.cosim.master.slave import FmuSlave
    from drillcosim.cosim.master.system import FmuSpec
    from support.master_fmus.build import build_fmu

    fmu = build_fmu("mt_compiled")
    slave = FmuSlave(FmuSpec("a", fmu))
    slave.instantiate(0.0, None)
    y = (ctypes.c_double * 3)()
    u = (ctypes.c_double * 1)()
    slave.bind(["x", "n_compiled", "n_python"], y, 0, ["u"], u)
    clock = {"t": 0.0}

    def do_step():
        slave.do_step(clock["t"], H_LOOP)
        clock["t"] += H_LOOP

    out: dict[str, float] = {}
    out["fmi2SetReal from Python (ctypes, 1 input)"] = min(
        _mean_us(slave.write_inputs, 20000) for _ in range(repeat))
    out["fmi2DoStep from Python (ctypes; compiled step, no Python inside)"] = min(
        _mean_us(do_step, 20000) for _ in range(repeat))
    out["fmi2GetReal from Python (ctypes, 3 outputs)"] = min(
        _mean_us(slave.read_outputs, 20000) for _ in range(repeat))
    slave.close()

    class _Ex:       # what Recorder.on_step reads
        tick, time = 0, 0.0
    rec = Recorder(["a.x", "b.x", "a.n", "b.n"], 1)
    rec._y, rec._fast, rec._slow = y, [0, 1, 2, 0], {}
    out["recorder row in Python (4 variables; per row, the loop records every 4th step)"] = min(
        _mean_us(lambda: rec.on_step(_Ex), 20000) for _ in range(repeat))
    for loop in ("python", "auto"):
        name = "Python loop" if loop == "python" else "native loop (chunks in C)"
        for record in (False, True):
            key = f"whole step, 2 compiled FMUs, {name}" + (", recorder every 4th" if record
                                                          else "")
            out[key] = min(_tiny_loop_us(fmu, loop, steps, record) for _ in range(repeat))
    closed_loop(0.01, "fmu")
    for loop in ("python", "auto"):
        name = "Python loop" if loop == "python" else "native loop"
        out[f"paper_closed_loop through its FMUs, {name} ({stop:g} s)"] = min(
            closed_loop(stop, "fmu", loop) for _ in range(repeat)) / (stop / H_LOOP) * 1e6
    return out


def budget_lines(budget: dict[str, float], command: str) -> list[str]:
    """The markdown budget table."""
    lines = ["## The master's own cost per 0.25 ms step (benchmarks/bench_one_master.py "
             "--budget)", "", f"Command: `{command}`; {platform.platform()}, "
             f"{os.cpu_count()} cores, Python {platform.python_version()}, "
             f"{datetime.datetime.now():%Y-%m-%d %H:%M}; best of the repeats; load average at "
             f"the end {os.getloadavg()[0]:.1f}.", "", "| part | us per step |", "|---|---:|"]
    lines += [f"| {k} | {v:.2f} |" for k, v in budget.items()]
    return lines + [""]


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--stop-time", type=float, default=10.0, help="simulated time [s]")
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--whole-stop-time", type=float, default=30.0,
                    help="simulated time [s] of the whole `drillcosim run` processes")
    ap.add_argument("--out", help="write the markdown section here (default: print)")
    ap.add_argument("--budget", action="store_true",
                    help="only the master's budget per step (section 5)")
    args = ap.parse_args(argv)
    if args.budget:
        budget = master_budget(repeat=args.repeat, stop=args.stop_time)
        budget.update(step_parts())
        text = "\n".join(budget_lines(budget,
                                       "python benchmarks/bench_one_master.py --budget "
                                       f"--repeat {args.repeat} --stop-time {args.stop_time:g}"))
        if args.out:
            Path(args.out).write_text(text)
        print(text)
        return 0
    closed_loop(0.01, "fmu")          # build/compile/load caches once, outside the timing
    walls: dict[str, list[float]] = {"fmu": [], "in-process": []}
    starts: list[dict[str, float]] = []
    from drillcosim.cosim.scenario.scene_fmus import default_fmu_dir
    c_controller = default_fmu_dir() / "StrainControllerC.fmu"
    wholes: dict[str, tuple[str, ...]] = {
        "with plots": (), "`--no-plots`": ("--no-plots",),
        "`--no-plots`, C controller (`--controller-fmu StrainControllerC.fmu`)":
            ("--no-plots", "--controller-fmu", str(c_controller))}
    whole_walls: dict[str, list[float]] = {k: [] for k in wholes}
    for _ in range(args.repeat):
        for engine in walls:
            walls[engine].append(closed_loop(args.stop_time, engine))
        starts.append(startup())
        for k, extra in wholes.items():
            whole_walls[k].append(whole_run(args.whole_stop_time, *extra))
    parts = step_parts()
    best = {k: min(v) for k, v in walls.items()}
    first = min(starts, key=lambda d: sum(d.values()))
    stamp = datetime.datetime.now().strftime("%Y-%m-%d %H:%M")
    lines = [
        "## One master: FMU slaves vs in-process slaves; start-up (benchmarks/bench_one_master.py)",
        "",
        f"Command: `python benchmarks/bench_one_master.py --stop-time {args.stop_time:g} "
        f"--repeat {args.repeat}`; {platform.platform()}, {os.cpu_count()} cores, Python "
        f"{platform.python_version()}, {stamp}; best of {args.repeat} interleaved runs; load "
        f"average at the end {os.getloadavg()[0]:.1f}.",
        "",
        "| paper_closed_loop, 0.25 ms Gauss-Seidel, recorder at 1 ms | wall [s] | "
        "real-time factor |",
        "|---|---|---|",
    ]
    for engine, wall in best.items():
        lines.append(f"| our master, {engine} slaves | {wall:.2f} | "
                     f"{args.stop_time / wall:.2f} |")
    lines += ["", f"FMU slaves / in-process slaves (real-time factor): "
              f"{best['in-process'] / best['fmu']:.2f}x (target >= 0.8x).", "",
              "Start-up of `drillcosim run paper_closed_loop` to its first step, fresh process "
              f"(best of {args.repeat}):", "", "| stage | [s] |", "|---|---|"]
    for stage, sec in first.items():
        lines.append(f"| {stage} | {sec:.3f} |")
    lines.append(f"| **total to the first step** | **{sum(first.values()):.3f}** |")
    ws = args.whole_stop_time
    lines += ["", f"The whole `drillcosim run paper_closed_loop --stop-time {ws:g}` process "
              f"(fresh interpreter, FMUs and numba cache warm; best of {args.repeat}):", "",
              "| run | wall [s] | real-time factor |", "|---|---:|---:|"]
    for k, v in whole_walls.items():
        lines.append(f"| {k} | {min(v):.2f} | {ws / min(v):.2f} |")
    n_steps = round(ws / 0.00025)
    start = sum(first.values())
    lines += ["", f"Where a 0.25 ms step goes (each part timed alone in this process, mean of "
              f"4000 calls; the closed loop is {n_steps} such steps):", "",
              "| part | us per step | the whole run's ceiling if only this part and the "
              f"{start:.2f} s start-up cost time |", "|---|---:|---:|"]
    for k, us in parts.items():
        lines.append(f"| {k} | {us:.1f} | {ws / (start + n_steps * us * 1e-6):.1f}x |")
    budget = (ws / 8.0 - start) / n_steps * 1e6
    lines += ["", f"Target 8x real time for the whole process = {ws / 8:.2f} s: after the "
              f"start-up, {budget:.1f} us per 0.25 ms step for everything (physics, both FMUs, "
              f"the master, recording, results and plots)."]
    text = "\n".join(lines) + "\n"
    if args.out:
        Path(args.out).write_text(text)
    print(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
