"""The FMU boundary: the plant FMU in fmpy next to the plant alone, and where the time goes.

    python benchmarks/bench_fmu_boundary.py [--stop-time 10] [--repeat 5]
        [--baseline DIR] [--out benchmarks/results/fmu_boundary.md]

All in one process, candidates interleaved, best of ``--repeat`` (the machine is shared):

1. ``paper_open_loop`` for ``--stop-time`` s at 1 ms: the plant alone (``plant.simulator.simulate``,
   the compiled recording loop) next to the plant FMU through ``fmpy.simulate_fmu`` (all 23
   outputs recorded). Both reuse what a second run in a process reuses (the model's stable step;
   the numba cache); both include everything else (the FMU: unzip, instantiate, initialize).
2. Per step of 1 ms, the layers of that FMU run: the physics alone, ``PlantSimulator.do_step`` +
   outputs (Python), the FMU's ``fmi2DoStep`` called straight through ctypes (our wrapper +
   adapter), fmpy's ``doStep`` + ``getReal`` of the outputs, ``fmpy.simulate_fmu``.
3. ``paper_closed_loop`` through our master (``cosim.master.Execution``) at the scene's 0.25 ms
   step, per step, for the FMUs built from this checkout and, with ``--baseline DIR``, for FMUs of
   an earlier build (e.g. the main branch's ``build/fmus``) side by side.
4. One FMI call through ctypes (getReal of all outputs, setReal of all inputs, the controller's
   doStep), for both FMUs, this build and the baseline.
5. Cold start of the plant FMU in a fresh process after first use: instantiate (imports),
   initialize (model build, numba cache loads), first doStep, best of 3; next to the plant alone
   in a fresh process (imports, model + simulator, first step): the FMU layer's share.
6. Per 0.25 ms step of ``paper_closed_loop``'s plant (best of ``--repeat`` x 4000 steps): the
   integrator span alone (one compiled call for all steps: the physics floor), the compiled step
   in process (ctypes), the plant FMU through raw ctypes calls (setReal of the inputs, doStep,
   getReal of every output) with its compiled step and with it switched off
   (``DRILLCOSIM_COMPILED_STEP=0``: ``do_step`` in Python).
"""

from __future__ import annotations

import argparse
import os
import platform
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

import numpy as np  # noqa: E402
from fmpy import extract, read_model_description, simulate_fmu  # noqa: E402
from fmpy.fmi2 import FMU2Slave  # noqa: E402

from drillcosim.cosim.master.execution import Execution  # noqa: E402
from drillcosim.cosim.scenario.build import build_system  # noqa: E402
from drillcosim.cosim.scenario.config import load_config  # noqa: E402
from drillcosim.fmu_src.build import build_all  # noqa: E402
from drillcosim.plant.model import DrillstringModel  # noqa: E402
from drillcosim.plant.scene import load_scene  # noqa: E402
from drillcosim.plant.simulator import PlantSimulator, simulate  # noqa: E402

H = 1e-3


def _model() -> DrillstringModel:
    sc = load_scene("paper_open_loop", overrides={"model": "full3d"})  # = the FMU's default
    return DrillstringModel(sc.plant, sc.model)


def timed(fn, *args) -> tuple[float, float]:
    """(wall, CPU time of this process) [s] of ``fn(*args)``."""
    w0, c0 = time.perf_counter(), time.process_time()
    fn(*args)
    return time.perf_counter() - w0, time.process_time() - c0


def plant_alone(model: DrillstringModel, stop: float) -> tuple[float, float]:
    """(wall, CPU) [s] of ``simulate`` (compiled recording loop, all outputs) for ``stop`` s."""
    return timed(simulate, model, stop, H)


def plant_fmu(fmu: Path, stop: float) -> tuple[float, float]:
    """(wall, CPU) [s] of ``fmpy.simulate_fmu`` of the plant FMU for ``stop`` s at 1 ms."""
    return timed(lambda: simulate_fmu(str(fmu), stop_time=stop, step_size=H, output_interval=H))


def _slave(fmu: Path, unzip: str) -> tuple[FMU2Slave, list[int]]:
    md = read_model_description(str(fmu))
    s = FMU2Slave(guid=md.guid, unzipDirectory=unzip,
                  modelIdentifier=md.coSimulation.modelIdentifier, instanceName="bench")
    s.instantiate()
    s.setupExperiment(startTime=0.0)
    s.enterInitializationMode()
    s.exitInitializationMode()
    return s, [v.valueReference for v in md.modelVariables if v.causality == "output"]


def layers(model: DrillstringModel, fmu: Path, n: int) -> dict[str, float]:
    """Per-step wall time [us] of each layer of the FMU run (one pass each)."""
    out = {}
    t0 = time.perf_counter()
    simulate(model, n * H, H)
    out["physics: compiled recording loop (plant alone)"] = time.perf_counter() - t0
    sim = PlantSimulator(model)
    idx = np.arange(len(model.output_names))
    y = np.zeros(len(idx))
    t0 = time.perf_counter()
    for k in range(n):
        sim.do_step(k * H, H)
        sim.outputs().take(idx, out=y)
    out["PlantSimulator.do_step + outputs (Python loop)"] = time.perf_counter() - t0
    unzip = extract(str(fmu))
    s, outs = _slave(fmu, unzip)
    do_step, c = s.dll.fmi2DoStep, s.component
    t0 = time.perf_counter()
    for k in range(n):
        do_step(c, k * H, H, 1)
    out["FMU fmi2DoStep through ctypes (our wrapper + adapter)"] = time.perf_counter() - t0
    s.terminate()
    s.freeInstance()
    s, outs = _slave(fmu, unzip)
    t0 = time.perf_counter()
    for k in range(n):
        s.doStep(k * H, H)
        s.getReal(outs)
    out["fmpy FMU2Slave.doStep + getReal(23 outputs)"] = time.perf_counter() - t0
    s.terminate()
    s.freeInstance()
    shutil.rmtree(unzip, ignore_errors=True)
    out["fmpy.simulate_fmu (whole run)"] = plant_fmu(fmu, n * H)[0]
    return {k: v / n * 1e6 for k, v in out.items()}


def per_call(fmu: Path, n: int = 20000, repeat: int = 5) -> dict[str, float]:
    """us per raw ctypes call (preallocated arrays) in step mode: getReal of every output,
    setReal of every input, and (controller only) doStep; best of ``repeat`` x ``n``."""
    import ctypes

    md = read_model_description(str(fmu))
    unzip = extract(str(fmu))
    s, outs = _slave(fmu, unzip)
    ins = [v.valueReference for v in md.modelVariables if v.causality == "input"]
    vo = (ctypes.c_uint * len(outs))(*outs)
    yo = (ctypes.c_double * len(outs))()
    vi = (ctypes.c_uint * len(ins))(*ins)
    ui = (ctypes.c_double * len(ins))()
    c, dll = s.component, s.dll
    calls = {f"getReal({len(outs)} outputs)": lambda: dll.fmi2GetReal(c, vo, len(outs), yo),
             f"setReal({len(ins)} inputs)": lambda: dll.fmi2SetReal(c, vi, len(ins), ui)}
    if "Controller" in fmu.name:
        t = [0.0]

        def step() -> None:
            dll.fmi2DoStep(c, t[0], 1e-3, 1)
            t[0] += 1e-3

        calls["doStep"] = step
    out = {}
    for name, call in calls.items():
        best = float("inf")
        for _ in range(repeat):
            t0 = time.perf_counter()
            for _ in range(n):
                call()
            best = min(best, time.perf_counter() - t0)
        out[name] = best / n * 1e6
    s.terminate()
    s.freeInstance()
    shutil.rmtree(unzip, ignore_errors=True)
    return out


def _raw_loop(fmu: Path, compiled: bool, n: int, h: float) -> float:
    """us per step of setReal(inputs) + doStep + getReal(outputs) through raw ctypes calls."""
    import ctypes

    os.environ["DRILLCOSIM_COMPILED_STEP"] = "1" if compiled else "0"
    try:
        md = read_model_description(str(fmu))
        unzip = extract(str(fmu))
        s = FMU2Slave(guid=md.guid, unzipDirectory=unzip,
                      modelIdentifier=md.coSimulation.modelIdentifier, instanceName="bench")
        s.instantiate()
        vr = {v.name: v.valueReference for v in md.modelVariables}
        s.setString([vr["scene"]], ["paper_closed_loop"])
        s.setupExperiment(startTime=0.0)
        s.enterInitializationMode()
        s.exitInitializationMode()
    finally:
        os.environ.pop("DRILLCOSIM_COMPILED_STEP", None)
    outs = [v.valueReference for v in md.modelVariables if v.causality == "output"]
    ins = [v.valueReference for v in md.modelVariables if v.causality == "input"]
    vo, yo = (ctypes.c_uint * len(outs))(*outs), (ctypes.c_double * len(outs))()
    vi, ui = (ctypes.c_uint * len(ins))(*ins), (ctypes.c_double * len(ins))(*[10.0] * len(ins))
    c, dll = s.component, s.dll
    get, put, do_step = dll.fmi2GetReal, dll.fmi2SetReal, dll.fmi2DoStep
    do_step(c, 0.0, h, 1)  # the first step of a step size picks the method (in Python)
    t0 = time.perf_counter()
    for k in range(1, n + 1):
        put(c, vi, len(ins), ui)
        do_step(c, k * h, h, 1)
        get(c, vo, len(outs), yo)
    wall = time.perf_counter() - t0
    s.terminate()
    s.freeInstance()
    shutil.rmtree(unzip, ignore_errors=True)
    return wall / n * 1e6


def closed_loop_plant_step(fmu: Path, n: int = 4000, repeat: int = 5) -> dict[str, float]:
    """us per 0.25 ms step of paper_closed_loop's plant, each layer best of ``repeat``."""
    h = 2.5e-4
    sc = load_scene("paper_closed_loop")
    model = DrillstringModel(sc.plant, sc.model)
    method = model.method_for_step(h)

    def span(meth: str) -> float:
        y = model.initial_state()
        model.advance(0.0, y, 2, h, method=meth)  # compiled before timing
        t0 = time.perf_counter()
        model.advance(0.0, y, n, h, method=meth)
        return (time.perf_counter() - t0) / n * 1e6

    def span_per_call(meth: str) -> float:
        y = model.initial_state()
        u = np.full(model.n_inputs, 10.0)
        t0 = time.perf_counter()
        for k in range(n):
            model.advance(k * h, y, 1, h, u, meth)
        return (time.perf_counter() - t0) / n * 1e6

    def in_process() -> float:
        sim = PlantSimulator(DrillstringModel(sc.plant, sc.model))
        inp, out = np.full(sim.u.size, 10.0), np.zeros(len(model.output_names))
        step = sim.compiled_step(inp, np.arange(inp.size), out, np.arange(out.size))
        step.step(0.0, h)
        t0 = time.perf_counter()
        for k in range(1, n + 1):
            step.step(k * h, h)
        return (time.perf_counter() - t0) / n * 1e6

    parts = {f"integrator span alone ({method}, one compiled call for all steps)":
             lambda: span(method),
             "integrator span alone (rk4: the method before)": lambda: span("rk4"),
             f"integrator span, one call per step from Python ({method}; numba's dispatch "
             "included, as the span of the issue's 2.1x)": lambda: span_per_call(method),
             "compiled step in process (ctypes; checks, outputs)": in_process,
             "plant FMU, compiled step: setReal + doStep + getReal (raw ctypes)":
             lambda: _raw_loop(fmu, True, n, h),
             "plant FMU, Python do_step (DRILLCOSIM_COMPILED_STEP=0), same calls":
             lambda: _raw_loop(fmu, False, n, h)}
    best = dict.fromkeys(parts, float("inf"))
    for _ in range(repeat):
        for name, fn in parts.items():
            best[name] = min(best[name], fn())
    return best


def closed_loop(fmu_dir: Path, stop: float) -> tuple[float, float]:
    """(wall, CPU) [s] of ``paper_closed_loop`` through Execution (0.25 ms, no recording)."""
    ss = build_system(load_config("paper_closed_loop"), "fmu", fmu_dir=fmu_dir)
    with Execution(ss.system) as ex:
        ex.initialize()
        return timed(ex.simulate_until, stop)


COLD = """
import sys, time
from fmpy import extract, read_model_description
from fmpy.fmi2 import FMU2Slave
md = read_model_description(sys.argv[1]); d = extract(sys.argv[1])
t0 = time.perf_counter()
s = FMU2Slave(guid=md.guid, unzipDirectory=d, modelIdentifier=md.coSimulation.modelIdentifier,
              instanceName="p")
s.instantiate(); t1 = time.perf_counter()
s.setupExperiment(startTime=0.0); s.enterInitializationMode(); s.exitInitializationMode()
t2 = time.perf_counter(); s.doStep(0.0, 1e-3); t3 = time.perf_counter()
print(t1 - t0, t2 - t1, t3 - t2)
"""


COLD_ALONE = """
import time
t0 = time.perf_counter()
from drillcosim.plant.model import DrillstringModel
from drillcosim.plant.scene import load_scene
from drillcosim.plant.simulator import PlantSimulator
t1 = time.perf_counter()
sc = load_scene("paper_open_loop", overrides={"model": "full3d"})
sim = PlantSimulator(DrillstringModel(sc.plant, sc.model))
t2 = time.perf_counter(); sim.do_step(0.0, 1e-3); sim.outputs(); t3 = time.perf_counter()
print(t1 - t0, t2 - t1, t3 - t2)
"""


def cold_start(fmu: Path | None, repeat: int = 3) -> tuple[float, float, float]:
    """Best (imports, build, first step) [s] in fresh processes after first use: the FMU
    (instantiate, initialize, first doStep) or, for ``fmu=None``, the plant alone."""
    env = {**os.environ, "OPENBLAS_NUM_THREADS": "1"}
    cmd = [sys.executable, "-c", COLD_ALONE] if fmu is None else [sys.executable, "-c", COLD,
                                                                   str(fmu)]
    runs = []
    for _ in range(repeat + 1):  # the first one may still fill caches: dropped
        out = subprocess.run(cmd, capture_output=True, text=True, check=True,
                             env=env).stdout.split()
        runs.append(tuple(float(x) for x in out[-3:]))
    return min(runs[1:], key=sum)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--stop-time", type=float, default=10.0, help="open loop [s]")
    ap.add_argument("--closed-stop-time", type=float, default=2.0, help="closed loop [s]")
    ap.add_argument("--repeat", type=int, default=5, help="interleaved repetitions (best kept)")
    ap.add_argument("--baseline", type=Path, default=None,
                    help="folder with FMUs of an earlier build, measured side by side")
    ap.add_argument("--out", default=str(ROOT / "benchmarks" / "results" / "fmu_boundary.md"))
    args = ap.parse_args(argv)
    stop = args.stop_time
    fmu_dir = Path(tempfile.mkdtemp(prefix="bench_fmus_"))
    build_all(fmu_dir)
    plant = fmu_dir / "DrillstringPlant.fmu"
    dirs = {"this build": fmu_dir}
    if args.baseline is not None:
        dirs["baseline"] = args.baseline.resolve()
    model = _model()
    for d in dirs.values():  # warm: numba caches, the model's stable step
        plant_fmu(d / "DrillstringPlant.fmu", 0.01)
        closed_loop(d, 0.01)
    plant_alone(model, 0.01)

    runs: dict[str, list[tuple[float, float]]] = {"alone": []}
    for name in dirs:
        runs[f"fmu {name}"] = []
        runs[f"closed {name}"] = []
    for _ in range(args.repeat):
        runs["alone"].append(plant_alone(model, stop))
        for name, d in dirs.items():
            runs[f"fmu {name}"].append(plant_fmu(d / "DrillstringPlant.fmu", stop))
            runs[f"closed {name}"].append(closed_loop(d, args.closed_stop_time))
    best = {k: min(w for w, _c in v) for k, v in runs.items()}  # wall
    cpu = {k: min(c for _w, c in v) for k, v in runs.items()}
    per_layer = layers(model, plant, 3000)
    calls = {(fmu_name, name): per_call(d / f"{fmu_name}.fmu")
             for name, d in dirs.items() for fmu_name in ("DrillstringPlant", "StrainController")}
    cold = {f"plant FMU, {name}": cold_start(d / "DrillstringPlant.fmu")
            for name, d in dirs.items()}
    cold["plant alone (imports, model + simulator, first do_step)"] = cold_start(None)
    step_parts = closed_loop_plant_step(plant, repeat=args.repeat)
    shutil.rmtree(fmu_dir, ignore_errors=True)

    n_cl = args.closed_stop_time / 2.5e-4
    lines = [
        "## FMU boundary (benchmarks/bench_fmu_boundary.py)",
        "",
        f"Command: `python benchmarks/bench_fmu_boundary.py --stop-time {stop:g} --repeat "
        f"{args.repeat}{' --baseline ' + str(args.baseline) if args.baseline else ''}`; "
        f"{time.strftime('%Y-%m-%d %H:%M')}; {platform.platform()}, {os.cpu_count()} cores, "
        f"Python {platform.python_version()}, load average {os.getloadavg()[0]:.1f} at the end; "
        f"best of {args.repeat} interleaved runs (wall and this process's CPU time, each the "
        f"best of its runs: on a shared machine CPU time is the steadier of the two).",
        "",
        f"paper_open_loop, {stop:g} s at 1 ms, all outputs recorded:",
        "",
        "| run | wall [s] | real-time factor | vs the plant alone (wall) | CPU [s] | "
        "vs the plant alone (CPU) |",
        "|---|---:|---:|---:|---:|---:|",
        f"| plant alone (`plant.simulator.simulate`, compiled recording loop) | "
        f"{best['alone']:.3f} | {stop / best['alone']:.1f} | 1.00 | {cpu['alone']:.3f} | 1.00 |",
    ]
    for name in dirs:
        b, c = best[f"fmu {name}"], cpu[f"fmu {name}"]
        lines.append(f"| plant FMU through `fmpy.simulate_fmu` ({name}) | {b:.3f} | "
                     f"{stop / b:.1f} | {best['alone'] / b:.2f} | {c:.3f} | "
                     f"{cpu['alone'] / c:.2f} |")
    lines += ["", "Where a 1 ms step of the plant FMU goes (this build, 3 s, one pass each):", "",
              "| layer | us per step |", "|---|---:|"]
    lines += [f"| {k} | {v:.1f} |" for k, v in per_layer.items()]
    lines += ["", "One FMI call through ctypes with preallocated arrays (step mode, best of 5 x "
              "20 000), us:", "", "| FMU | call | " + " | ".join(dirs) + " |",
              "|---|---|" + "---:|" * len(dirs)]
    for fmu_name in ("DrillstringPlant", "StrainController"):
        for call in calls[(fmu_name, "this build")]:
            lines.append(f"| {fmu_name} | {call} | " + " | ".join(
                f"{calls[(fmu_name, name)][call]:.2f}" for name in dirs) + " |")
    lines += ["", f"paper_closed_loop through `cosim.master.Execution` at 0.25 ms "
              f"({args.closed_stop_time:g} s, {n_cl:.0f} steps, no recording):", "",
              "| FMUs | wall [s] | us per step (wall) | real-time factor | us per step (CPU) |",
              "|---|---:|---:|---:|---:|"]
    for name in dirs:
        b, c = best[f"closed {name}"], cpu[f"closed {name}"]
        lines.append(f"| {name} | {b:.3f} | {b / n_cl * 1e6:.1f} | "
                     f"{args.closed_stop_time / b:.2f} | {c / n_cl * 1e6:.1f} |")
    lines += ["", "Cold start in a fresh process after first use (best of 3), the FMU through fmpy "
              "(read_model_description and unzip not counted):", "",
              "| run | instantiate (imports) [s] | initialize (model build) [s] | "
              "first doStep [s] | total [s] |", "|---|---:|---:|---:|---:|"]
    for name, (a, b, c) in cold.items():
        lines.append(f"| {name} | {a:.3f} | {b:.3f} | {c:.3f} | {a + b + c:.3f} |")
    floor = next(iter(step_parts.values()))
    lines += ["", f"Per 0.25 ms step of paper_closed_loop's plant (this build, best of "
              f"{args.repeat} x 4000 steps):", "", "| layer | us per step | / the span alone |",
              "|---|---:|---:|"]
    lines += [f"| {k} | {v:.2f} | {v / floor:.2f} |" for k, v in step_parts.items()]
    text = "\n".join(lines) + "\n"
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text(text)
    print(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
