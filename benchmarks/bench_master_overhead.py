"""Per-step overhead of the co-simulation master vs raw fmpy loops (and libcosim).

Two tiny pythonfmu FMUs (integrator plant + P controller, the master tests'
``mt_integrator`` / ``mt_gain``) in a feedback loop, 1 ms steps. Measured side
by side in one process, best of ``--repeat`` runs of ``--steps`` steps each:

* raw fmpy loop: ``FMU2Slave.getReal/setReal/doStep``, the usual hand-written loop;
* raw ctypes loop: the FMI functions on preallocated buffers (lower bound);
* cosim Jacobi / Gauss-Seidel: :class:`cosim.master.execution.Execution` without observers,
  and the Jacobi run through :class:`cosim.master.Master` recording 2 outputs;
* libcosimpy (libcosim, C++) on the same FMUs, if it loads them.

Run: ``.venv/bin/python benchmarks/bench_master_overhead.py [--steps N] [--repeat R]``.
Prints a markdown table: microseconds per communication step and ratios.
"""

from __future__ import annotations

import argparse
import ctypes
import shutil
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(ROOT), str(ROOT / "tests")]

from fmpy import extract, read_model_description  # noqa: E402
from fmpy.fmi2 import FMU2Slave  # noqa: E402

from drillcosim.cosim.master.execution import Execution  # noqa: E402
from drillcosim.cosim.master.master import Master  # noqa: E402
from drillcosim.cosim.master.system import Connection, FmuSpec, SystemSpec  # noqa: E402
from support.master_fmus.build import build_fmu  # noqa: E402

H = 1e-3
K = 0.5


def _load(path: Path, name: str):
    md = read_model_description(str(path))
    unzip = extract(str(path))
    fmu = FMU2Slave(guid=md.guid, unzipDirectory=unzip,
                    modelIdentifier=md.coSimulation.modelIdentifier, instanceName=name)
    fmu.instantiate()
    fmu.setupExperiment(startTime=0.0)
    fmu.enterInitializationMode()
    fmu.exitInitializationMode()
    vrs = {v.name: v.valueReference for v in md.modelVariables}
    return fmu, vrs, unzip


def _close(*items):
    for fmu, _, unzip in items:
        fmu.terminate()
        fmu.freeInstance()
        shutil.rmtree(unzip, ignore_errors=True)


def raw_fmpy(paths, steps: int) -> float:
    """Hand-written fmpy loop (Jacobi), seconds per step."""
    p = _load(paths["mt_integrator"], "plant")
    c = _load(paths["mt_gain"], "ctrl")
    plant, pv, _ = p
    ctrl, cv, _ = c
    plant.setReal([pv["x0"]], [1.0])
    ctrl.setReal([cv["k"]], [K])
    x_vr, u_vr, y_vr, cu_vr = [pv["x"]], [pv["u"]], [cv["y"]], [cv["u"]]
    t0 = time.perf_counter()
    for k in range(steps):
        t = k * H
        x = plant.getReal(x_vr)
        y = ctrl.getReal(y_vr)
        plant.setReal(u_vr, y)
        ctrl.setReal(cu_vr, x)
        plant.doStep(t, H)
        ctrl.doStep(t, H)
    dt = time.perf_counter() - t0
    _close(p, c)
    return dt / steps


def raw_ctypes(paths, steps: int) -> float:
    """Minimal loop on the library functions with preallocated buffers."""
    p = _load(paths["mt_integrator"], "plant")
    c = _load(paths["mt_gain"], "ctrl")
    plant, pv, _ = p
    ctrl, cv, _ = c
    ctrl.setReal([cv["k"]], [K])
    vr = ctypes.c_uint * 1
    x_vr, u_vr, y_vr, cu_vr = vr(pv["x"]), vr(pv["u"]), vr(cv["y"]), vr(cv["u"])
    x, y = (ctypes.c_double * 1)(), (ctypes.c_double * 1)()
    get_p, set_p, step_p = plant.dll.fmi2GetReal, plant.dll.fmi2SetReal, plant.dll.fmi2DoStep
    get_c, set_c, step_c = ctrl.dll.fmi2GetReal, ctrl.dll.fmi2SetReal, ctrl.dll.fmi2DoStep
    cp, cc = plant.component, ctrl.component
    t0 = time.perf_counter()
    for k in range(steps):
        t = k * H
        get_p(cp, x_vr, 1, x)
        get_c(cc, y_vr, 1, y)
        set_p(cp, u_vr, 1, y)
        set_c(cc, cu_vr, 1, x)
        if step_p(cp, t, H, 0) > 1 or step_c(cc, t, H, 0) > 1:
            raise RuntimeError("step failed")
    dt = time.perf_counter() - t0
    _close(p, c)
    return dt / steps


def system(paths, algorithm: str) -> SystemSpec:
    return SystemSpec(
        [FmuSpec("plant", paths["mt_integrator"], {"x0": 1.0}),
         FmuSpec("ctrl", paths["mt_gain"], {"k": K})],
        [Connection("plant.x", "ctrl.u"), Connection("ctrl.y", "plant.u")],
        H, algorithm, ("plant", "ctrl"))


def cosim_execution(paths, steps: int, algorithm: str) -> float:
    with Execution(system(paths, algorithm)) as ex:
        ex.initialize()
        t0 = time.perf_counter()
        ex.simulate_until(steps * H)
        return (time.perf_counter() - t0) / steps


def cosim_facade(paths, steps: int) -> float:
    res = Master(system(paths, "jacobi")).simulate(steps * H, outputs=["plant.x", "ctrl.y"])
    return res.wall_time / steps


def libcosim(paths, steps: int) -> float:
    from libcosimpy.CosimExecution import CosimExecution
    from libcosimpy.CosimLogging import CosimLogLevel, log_output_level
    from libcosimpy.CosimSlave import CosimLocalSlave

    log_output_level(CosimLogLevel.ERROR)

    ex = CosimExecution.from_step_size(step_size=int(round(H * 1e9)))
    plant = ex.add_local_slave(CosimLocalSlave(str(paths["mt_integrator"]), "plant"))
    ctrl = ex.add_local_slave(CosimLocalSlave(str(paths["mt_gain"]), "ctrl"))
    md_p = read_model_description(str(paths["mt_integrator"]))
    md_c = read_model_description(str(paths["mt_gain"]))
    pv = {v.name: v.valueReference for v in md_p.modelVariables}
    cv = {v.name: v.valueReference for v in md_c.modelVariables}
    ex.real_initial_value(plant, pv["x0"], 1.0)
    ex.real_initial_value(ctrl, cv["k"], K)
    ex.connect_real_variables(plant, pv["x"], ctrl, cv["u"])
    ex.connect_real_variables(ctrl, cv["y"], plant, pv["u"])
    ex.step(1)  # initialisation outside the timing
    t0 = time.perf_counter()
    ok = ex.step(steps)
    dt = time.perf_counter() - t0
    if not ok:
        raise RuntimeError("libcosim step failed")
    return dt / steps


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--steps", type=int, default=20000)
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args(argv)
    paths = {n: build_fmu(n) for n in ("mt_integrator", "mt_gain")}
    cases = {
        "raw fmpy loop (getReal/setReal/doStep)": lambda: raw_fmpy(paths, args.steps),
        "raw ctypes loop (preallocated buffers)": lambda: raw_ctypes(paths, args.steps),
        "cosim Execution, Jacobi": lambda: cosim_execution(paths, args.steps, "jacobi"),
        "cosim Execution, Gauss-Seidel": lambda: cosim_execution(paths, args.steps,
                                                                 "gauss_seidel"),
        "cosim Master.simulate, Jacobi, 2 outputs recorded": lambda: cosim_facade(
            paths, args.steps),
        "libcosimpy (libcosim, fixed step)": lambda: libcosim(paths, args.steps),
    }
    best: dict[str, float | str] = {}
    for _ in range(args.repeat):  # interleaved, so machine load hits all cases alike
        for name, fn in cases.items():
            try:
                dt = fn()
            except Exception as exc:  # noqa: BLE001 - report and go on
                best[name] = f"failed: {type(exc).__name__}: {exc}"[:80]
                continue
            prev = best.get(name)
            if not isinstance(prev, str):
                best[name] = dt if prev is None else min(prev, dt)
    ref_fmpy = best["raw fmpy loop (getReal/setReal/doStep)"]
    ref_ctypes = best["raw ctypes loop (preallocated buffers)"]
    print(f"\n{args.steps} steps of {H * 1e3:g} ms, 2 FMUs (pythonfmu), best of {args.repeat}\n")
    print("| loop | us / step | vs raw fmpy | vs raw ctypes |")
    print("|---|---:|---:|---:|")
    for name, dt in best.items():
        if isinstance(dt, str):
            print(f"| {name} | {dt} | | |")
        else:
            print(f"| {name} | {dt * 1e6:.2f} | {dt / ref_fmpy:.2f} | {dt / ref_ctypes:.2f} |")


if __name__ == "__main__":
    main()
