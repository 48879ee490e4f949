"""Per-step cost of the C controller FMU next to the Python one, measured side by side in one run.

    python benchmarks/bench_controller_fmus.py [--steps 20000] [--stop-time 2] [--repeat 3]

1. The controller FMU alone, driven the way our master drives it (raw ctypes calls on
   preallocated buffers): per step ``fmi2SetReal`` (4 strains), ``fmi2DoStep``, ``fmi2GetReal``
   (4 forces); strains from a fixed random sequence, gain 1e9, lag 5 ms.
2. ``paper_closed_loop`` through our master (the scene's 0.25 ms Gauss-Seidel stepping) with the
   plant FMU and each controller FMU: wall time per base step, and the two runs' results
   compared (they must be equal bit for bit).

``StrainController.fmu`` is the pythonfmu adapter run by our native C wrapper (an embedded
Python interpreter), whose doStep calls the law's compiled step without entering Python (and,
as a third configuration, the same FMU with it switched off, ``DRILLCOSIM_COMPILED_STEP=0``:
``do_step`` in Python); ``StrainControllerC.fmu`` is the same law in C99. Both are built fresh
into a temporary folder. Configurations run ``--repeat`` times interleaved; the best is
reported (shared, noisy machine). Prints a markdown section (for BENCHMARKS.md).
"""

from __future__ import annotations

import argparse
import ctypes
import datetime as _dt
import os
import platform
import shutil
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import numpy as np  # noqa: E402
from fmpy import extract, read_model_description  # noqa: E402
from fmpy.fmi2 import FMU2Slave  # noqa: E402

from drillcosim.cosim.master.master import Master  # noqa: E402
from drillcosim.cosim.scenario.build import build_system  # noqa: E402
from drillcosim.cosim.scenario.config import load_config  # noqa: E402
from drillcosim.fmu_src.build import REGISTRY, build_one  # noqa: E402
from drillcosim.fmu_src.build_c import build_c_controller  # noqa: E402

INPUTS = ["strain1_C", "strain1_E", "strain2_C", "strain2_E"]
OUTPUTS = ["actuator1_force_C", "actuator1_force_E", "actuator2_force_C", "actuator2_force_E"]


class _Compiled:
    """``DRILLCOSIM_COMPILED_STEP`` set for a block (the FMUs read it at initialization)."""

    def __init__(self, on: bool) -> None:
        self.on = on

    def __enter__(self) -> None:
        os.environ["DRILLCOSIM_COMPILED_STEP"] = "1" if self.on else "0"

    def __exit__(self, *exc) -> None:
        os.environ.pop("DRILLCOSIM_COMPILED_STEP", None)


class ControllerLoop:
    """One instantiated controller FMU and its hot loop on raw ctypes buffers."""

    def __init__(self, fmu: Path):
        md = read_model_description(str(fmu))
        self.unzip = extract(str(fmu))
        self.slave = FMU2Slave(guid=md.guid, unzipDirectory=self.unzip,
                               modelIdentifier=md.coSimulation.modelIdentifier,
                               instanceName="bench")
        vr = {v.name: v.valueReference for v in md.modelVariables}
        s = self.slave
        s.instantiate()
        s.setupExperiment(startTime=0.0)
        s.enterInitializationMode()
        s.setReal([vr["lag_time_constant"]], [0.005])
        s.exitInitializationMode()
        self.ins = (ctypes.c_uint * 4)(*[vr[n] for n in INPUTS])
        self.outs = (ctypes.c_uint * 4)(*[vr[n] for n in OUTPUTS])
        self.time = 0.0

    def run(self, strains: np.ndarray, h: float) -> tuple[float, np.ndarray]:
        """Wall time [s] of ``len(strains)`` steps, and the last forces [N]."""
        dll, comp = self.slave.dll, self.slave.component
        set_real, do_step, get_real = dll.fmi2SetReal, dll.fmi2DoStep, dll.fmi2GetReal
        buf_in, buf_out = (ctypes.c_double * 4)(), (ctypes.c_double * 4)()
        rows = [tuple(r) for r in strains.tolist()]
        t = self.time
        t0 = time.perf_counter()
        for k, row in enumerate(rows):
            buf_in[:] = row
            if set_real(comp, self.ins, 4, buf_in) or do_step(comp, ctypes.c_double(t + k * h),
                                                             ctypes.c_double(h), 1) \
                    or get_real(comp, self.outs, 4, buf_out):
                raise RuntimeError(f"FMI call failed at step {k}")
        wall = time.perf_counter() - t0
        self.time = t + len(rows) * h
        return wall, np.array(buf_out[:])

    def close(self) -> None:
        self.slave.terminate()
        self.slave.freeInstance()
        shutil.rmtree(self.unzip, ignore_errors=True)


def closed_loop(plant: Path, controller: Path, stop: float) -> tuple[float, np.ndarray, int]:
    """(wall [s], structured result, base steps) of paper_closed_loop through our master."""
    config = load_config("paper_closed_loop", plant_fmu=plant, controller_fmu=controller)
    ss = build_system(config, "fmu")
    res = Master(ss.system).simulate(stop, ss.outputs)
    return res.wall_time, res.data, round(stop / ss.system.base_step)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--steps", type=int, default=20000, help="controller-alone steps per run")
    ap.add_argument("--stop-time", type=float, default=2.0, help="closed loop [s]")
    ap.add_argument("--repeat", type=int, default=3, help="interleaved runs (best is reported)")
    args = ap.parse_args(argv)
    work = Path(tempfile.mkdtemp(prefix="bench_ctl_"))
    try:
        spec = {s.name: s for s in REGISTRY}
        py_fmu = build_one(spec["StrainController"], work)
        fmus = {"Python (StrainController.fmu)": py_fmu,
                "C99 (StrainControllerC.fmu)": build_c_controller(work),
                "Python, compiled steps off (DRILLCOSIM_COMPILED_STEP=0; in the closed loop the "
                "plant's too)": py_fmu}
        compiled = {label: "off" not in label for label in fmus}
        plant = build_one(spec["DrillstringPlant"], work)
        strains = np.random.default_rng(1).normal(scale=3e-6, size=(args.steps, 4))
        loops = {}
        for label, path in fmus.items():
            with _Compiled(compiled[label]):
                loops[label] = ControllerLoop(path)
        for loop in loops.values():  # warm-up (first calls, caches)
            loop.run(strains[:500], 1e-3)
        alone: dict[str, float] = {label: np.inf for label in fmus}
        last: dict[str, np.ndarray] = {}
        for _ in range(args.repeat):
            for label, loop in loops.items():
                wall, last[label] = loop.run(strains, 1e-3)
                alone[label] = min(alone[label], wall)
        for loop in loops.values():
            loop.close()
        same_alone = len({v.tobytes() for v in last.values()}) == 1

        loop_wall: dict[str, float] = {label: np.inf for label in fmus}
        data: dict[str, np.ndarray] = {}
        n_steps = 0
        for _ in range(args.repeat):
            for label, path in fmus.items():
                with _Compiled(compiled[label]):
                    wall, data[label], n_steps = closed_loop(plant, path, args.stop_time)
                loop_wall[label] = min(loop_wall[label], wall)
        py, *others = data.values()
        same_loop = all(np.array_equal(py[n], o[n]) for o in others for n in py.dtype.names)
    finally:
        shutil.rmtree(work, ignore_errors=True)

    labels = list(fmus)
    cmd = (f"python benchmarks/bench_controller_fmus.py --steps {args.steps} --stop-time "
           f"{args.stop_time:g} --repeat {args.repeat}")
    lines = [
        "## Controller FMU per-step cost: C99 vs Python (benchmarks/bench_controller_fmus.py)",
        "",
        f"Command: `{cmd}`; {platform.platform()}, {os.cpu_count()} cores, Python "
        f"{platform.python_version()}, {_dt.datetime.now():%Y-%m-%d %H:%M}; best of "
        f"{args.repeat} interleaved runs.",
        "",
        "| controller FMU | alone: us / step (set 4, doStep, get 4) | closed loop via our master: "
        "us / base step (plant + controller) |",
        "|---|---:|---:|",
    ]
    for label in labels:
        lines.append(f"| {label} | {1e6 * alone[label] / args.steps:.2f} | "
                     f"{1e6 * loop_wall[label] / n_steps:.1f} |")
    ratio = alone[labels[0]] / alone[labels[1]]
    ratio_off = alone[labels[2]] / alone[labels[1]]
    loop_ratio = loop_wall[labels[0]] / loop_wall[labels[1]]
    lines += [
        "",
        f"Per step alone ({args.steps} steps of 1 ms, lag 5 ms) the Python controller FMU costs "
        f"{ratio:.2f}x the C one with its compiled step ({ratio_off:.2f}x with it off); in "
        f"paper_closed_loop ({args.stop_time:g} s, {n_steps} steps of 0.25 ms, Gauss-Seidel, "
        f"the plant FMU included) the whole loop with the Python controller costs "
        f"{loop_ratio:.2f}x the loop with the C one. Same forces alone: "
        f"{'yes' if same_alone else 'NO'}; closed-loop results equal bit for bit: "
        f"{'yes' if same_loop else 'NO'}.",
        "",
    ]
    print("\n".join(lines))
    return 0 if same_alone and same_loop else 1


if __name__ == "__main__":
    sys.exit(main())
