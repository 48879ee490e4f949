"""FMU- and master-level speed and memory (against their targets), measured side by side in one run.

    python benchmarks/bench_fmu_master.py [--stop-time 30] [--out benchmarks/results/fmu_master.md]

1. ``paper_open_loop`` for ``stop_time`` s at 1 ms: the plant alone (``PlantSimulator`` loop) next
   to the plant FMU through fmpy's ``FMU2Slave`` (raw loop: set 4 inputs, doStep, get outputs).
2. ``paper_closed_loop`` through our master: at the scene's step (0.25 ms, Gauss-Seidel, what the
   physics needs at gain 1e9) and at 1 ms with gain 1e8 (stable there), as real-time factors.
3. Peak resident memory of a closed-loop run in a fresh subprocess (``ru_maxrss``).

Each configuration runs ``--repeat`` times interleaved; the best is reported (noisy machine).
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
sys.path.insert(0, str(ROOT))

from fmpy import extract, read_model_description  # noqa: E402
from fmpy.fmi2 import FMU2Slave  # noqa: E402

from drillcosim.cosim.master.master import Master  # noqa: E402
from drillcosim.cosim.scenario.build import build_system  # noqa: E402
from drillcosim.cosim.scenario.config import load_config  # noqa: E402
from drillcosim.fmu_src.build import build_all  # noqa: E402
from drillcosim.plant.model import DrillstringModel  # noqa: E402
from drillcosim.plant.scene import load_scene  # noqa: E402
from drillcosim.plant.signals import actuator_inputs  # noqa: E402
from drillcosim.plant.simulator import PlantSimulator  # noqa: E402


def plant_alone(stop: float, h: float = 1e-3) -> float:
    """Wall time [s] of the plant without FMI (inputs zero, outputs read every step)."""
    sc = load_scene("paper_open_loop")
    sim = PlantSimulator(DrillstringModel(sc.plant, sc.model))
    n = int(round(stop / h))
    t0 = time.perf_counter()
    for k in range(n):
        res = sim.do_step(k * h, h)
        sim.outputs()
        if not res.ok:
            raise RuntimeError(res.message)
    return time.perf_counter() - t0


def plant_fmu(fmu: Path, stop: float, h: float = 1e-3) -> tuple[float, float]:
    """(wall time of the stepping loop [s], instantiate + init [s]) of the plant FMU via fmpy."""
    md = read_model_description(str(fmu))
    unzip = extract(str(fmu))
    vr = {v.name: v.valueReference for v in md.modelVariables}
    ins = [vr[n] for n in actuator_inputs(2)]
    outs = [v.valueReference for v in md.modelVariables if v.causality == "output"]
    t0 = time.perf_counter()
    s = FMU2Slave(guid=md.guid, unzipDirectory=unzip, modelIdentifier=md.coSimulation.modelIdentifier,
                  instanceName="plant")
    s.instantiate()
    s.setupExperiment(startTime=0.0)
    s.enterInitializationMode()
    s.exitInitializationMode()
    t_init = time.perf_counter() - t0
    n = int(round(stop / h))
    zeros = [0.0] * 4
    t0 = time.perf_counter()
    for k in range(n):
        s.setReal(ins, zeros)
        s.doStep(k * h, h)
        s.getReal(outs)
    wall = time.perf_counter() - t0
    s.terminate()
    s.freeInstance()
    shutil.rmtree(unzip, ignore_errors=True)
    return wall, t_init


def master_run(scene: str, stop: float, fmu_dir: Path, overrides: dict | None = None) -> float:
    """Wall time [s] of the master's stepping loop (Master.simulate), 1 ms output interval."""
    ov = overrides or {}
    ss = build_system(load_config(scene, ov), "fmu", fmu_dir=fmu_dir)
    outputs = ["plant.body11_radial_deflection", "plant.strain1_C", "controller.actuator1_force_C"]
    res = Master(ss.system).simulate(stop_time=stop, outputs=outputs, output_interval=1e-3)
    if res.diverged is not None:
        raise RuntimeError(f"{scene} {ov} diverged: {res.diverged}")
    return res.wall_time


MEM_SCRIPT = """
import resource, sys
sys.path.insert(0, {root!r})
from drillcosim.cosim.master.master import Master
from drillcosim.cosim.scenario.build import build_system
from drillcosim.cosim.scenario.config import load_config
ss = build_system(load_config('paper_closed_loop'), 'fmu', fmu_dir={fmu_dir!r})
Master(ss.system).simulate(stop_time={stop}, outputs=['plant.body11_radial_deflection'],
                            output_interval=1e-3, csv_path={csv!r})
print(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss)
"""


COLD_SCRIPT = """
import sys, time
t0 = time.perf_counter()
from fmpy import extract, read_model_description
from fmpy.fmi2 import FMU2Slave
md = read_model_description(sys.argv[1]); d = extract(sys.argv[1])
t1 = time.perf_counter()
s = FMU2Slave(guid=md.guid, unzipDirectory=d, modelIdentifier=md.coSimulation.modelIdentifier,
              instanceName="p")
s.instantiate(); s.setupExperiment(startTime=0.0); s.enterInitializationMode()
s.exitInitializationMode(); s.doStep(0.0, 1e-3)
print(time.perf_counter() - t1)
"""


def cold_start_s(fmu: Path, repeat: int = 3) -> float:
    """Best instantiate + initialize + first doStep [s] in a fresh process (numba cache warm)."""
    best = float("inf")
    for _ in range(repeat):
        out = subprocess.run([sys.executable, "-c", COLD_SCRIPT, str(fmu)], capture_output=True,
                             text=True, check=True, env={**os.environ, "OPENBLAS_NUM_THREADS": "1"})
        best = min(best, float(out.stdout.strip().splitlines()[-1]))
    return best


def peak_memory_mb(fmu_dir: Path, stop: float) -> float:
    """Peak RSS [MB] of a fresh process running paper_closed_loop for ``stop`` s (CSV streamed)."""
    with tempfile.TemporaryDirectory() as d:
        code = MEM_SCRIPT.format(root=str(ROOT), fmu_dir=str(fmu_dir), stop=stop,
                                 csv=str(Path(d) / "r.csv"))
        out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                             check=True, env={**os.environ, "OPENBLAS_NUM_THREADS": "1"})
    return int(out.stdout.strip().splitlines()[-1]) / 1024.0


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--stop-time", type=float, default=30.0, help="simulated time [s]")
    ap.add_argument("--repeat", type=int, default=2, help="interleaved repetitions (best kept)")
    ap.add_argument("--out", default=str(ROOT / "benchmarks" / "results" / "fmu_master.md"))
    ap.add_argument("--memory-stop-time", type=float, default=30.0, help="[s]")
    args = ap.parse_args(argv)
    stop = args.stop_time
    fmu_dir = Path(tempfile.mkdtemp(prefix="bench_fmus_"))
    build_all(fmu_dir)
    plant_fmu(fmu_dir / "DrillstringPlant.fmu", 0.01)  # warm the numba cache
    rows: dict[str, list[float]] = {k: [] for k in ("alone", "fmu", "init", "cl025", "cl1")}
    for _ in range(args.repeat):
        rows["alone"].append(plant_alone(stop))
        w, ti = plant_fmu(fmu_dir / "DrillstringPlant.fmu", stop)
        rows["fmu"].append(w)
        rows["init"].append(ti)
        rows["cl025"].append(master_run("paper_closed_loop", stop, fmu_dir))
        rows["cl1"].append(master_run("paper_closed_loop", stop, fmu_dir, {
            "controller": {"gain": 1e8}, "cosim": {"step": 1e-3}}))
    best = {k: min(v) for k, v in rows.items()}
    mem_first = peak_memory_mb(fmu_dir, args.memory_stop_time)  # may compile (cache dropped)
    mem = peak_memory_mb(fmu_dir, args.memory_stop_time)
    cold = cold_start_s(fmu_dir / "DrillstringPlant.fmu")
    shutil.rmtree(fmu_dir, ignore_errors=True)
    lines = [
        "## FMU and master level (benchmarks/bench_fmu_master.py)",
        "",
        f"Command: `python benchmarks/bench_fmu_master.py --stop-time {stop:g}`; "
        f"{platform.platform()}, {os.cpu_count()} cores, Python {platform.python_version()}, "
        f"{time.strftime('%Y-%m-%d %H:%M')}; best of {args.repeat} interleaved runs; "
        f"{stop:g} s simulated.",
        "",
        "| configuration | wall [s] | real-time factor | per step [us] | target |",
        "|---|---|---|---|---|",
        f"| paper_open_loop, plant alone (PlantSimulator), 1 ms | {best['alone']:.2f} | "
        f"{stop / best['alone']:.1f} | {1e3 * best['alone'] / stop:.0f} | - |",
        f"| paper_open_loop, plant FMU via fmpy FMU2Slave, 1 ms | {best['fmu']:.2f} | "
        f"{stop / best['fmu']:.1f} | {1e3 * best['fmu'] / stop:.0f} | >= 10 (<= 3 s for 30 s) |",
        f"| paper_closed_loop via our master, 0.25 ms Gauss-Seidel (scene) | {best['cl025']:.2f} "
        f"| {stop / best['cl025']:.2f} | {best['cl025'] / (stop / 2.5e-4) * 1e6:.0f} | - |",
        f"| paper_closed_loop via our master, 1 ms Jacobi, gain 1e8 | {best['cl1']:.2f} | "
        f"{stop / best['cl1']:.2f} | {best['cl1'] / (stop / 1e-3) * 1e6:.0f} | >= 8 |",
        "",
        f"FMU overhead on the plant: {best['fmu'] / best['alone']:.2f}x the plant alone. "
        f"Plant FMU instantiate + initialize in this warm process: {best['init']:.2f} s; cold "
        f"start in a fresh process after first use (instantiate + initialize + first doStep, "
        f"best of 3): {cold:.2f} s (target < 1 s).",
        f"Peak resident memory of a {args.memory_stop_time:g} s paper_closed_loop run in a fresh "
        f"process (CSV streamed): {mem:.0f} MB with the numba cache warm (target < 500 MB); "
        f"the first such process in this run: {mem_first:.0f} MB (it compiles whatever the "
        f"cache lacks after a build or an edit).",
        "",
    ]
    text = "\n".join(lines)
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = out.with_suffix(".tmp")
    tmp.write_text(text)
    os.replace(tmp, out)
    print(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
