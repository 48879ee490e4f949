"""Cost of the plant (RK4 through ``PlantSimulator``, 1 ms outputs) vs size, horizon, memory.

* real-time factors: paper_open_loop (full 3D, n = 30) over 30 s and table1_axial_pulse
  (axial-torsional) over its 3 s, through :func:`plant.simulator.simulate`;
* cost vs n (15, 30, 60, 120) over a fixed horizon, with the fitted exponent of wall ~ n^a (the
  stable step shrinks ~ 1/n and the rhs grows ~ n, so ~ n^2 is expected);
* cost vs simulated time (exponent ~ 1 expected);
* peak memory of a 30 s run in a fresh subprocess (``ru_maxrss``, and ``tracemalloc`` peak of
  the Python allocations during the run) next to the same process doing only the imports.
"""

from __future__ import annotations

import json
import math
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
from bench_work_precision import run_plant, scene_model

ROOT = Path(__file__).resolve().parents[1]

_MEM_SCRIPT = r"""
import json, resource, sys, time, tracemalloc
sys.path.insert(0, {root!r})
from drillcosim.plant.model import DrillstringModel
from drillcosim.plant.scene import load_scene
from drillcosim.plant.simulator import simulate
sc = load_scene("paper_open_loop")
m = DrillstringModel(sc.plant, sc.model)
simulate(m, 0.01, 1e-3)  # compile/load caches outside the measurement
base = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
if {run}:
    tracemalloc.start()
    t0 = time.perf_counter()
    t, v, r = simulate(m, {T}, 1e-3, list(sc.outputs))
    wall = time.perf_counter() - t0
    cur, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
else:
    wall, peak, r = 0.0, 0, None
print(json.dumps({{"maxrss_kb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss,
                  "maxrss_before_kb": base, "tracemalloc_peak_b": peak, "wall": wall}}))
"""


def _fit_exponent(x: list[float], y: list[float]) -> float:
    return float(np.polyfit(np.log(x), np.log(y), 1)[0])


def real_time(quick: bool) -> dict:
    """Wall time and real-time factor of the target runs (best of k)."""
    out = {}
    T3 = 10.0 if quick else 30.0
    m3 = scene_model("paper_open_loop")
    ma = scene_model("table1_axial_pulse")
    mt = scene_model("table1_torsional_pulse")
    Ta = 10.0
    best: dict[str, float] = {}
    for _ in range(2 if quick else 3):
        for key, fn in (
            ("3d rk4", lambda: run_plant(m3, T3, "rk4").wall),
            ("at rk4", lambda: run_plant(ma, Ta, "rk4").wall),
            ("at expeuler", lambda: run_plant(ma, Ta, "expeuler").wall),
            ("at auto", lambda: run_plant(ma, Ta, "auto").wall),
            ("at torsional auto", lambda: run_plant(mt, Ta, "auto").wall),
        ):
            w = fn()
            best[key] = min(best.get(key, math.inf), w)
    out["3d"] = {"T": T3, "wall": best["3d rk4"], "rtf": T3 / best["3d rk4"],
                 "h_star": m3.stable_step()}
    out["at rk4"] = {"T": Ta, "wall": best["at rk4"], "rtf": Ta / best["at rk4"],
                     "h_star": ma.stable_step()}
    out["at expeuler"] = {"T": Ta, "wall": best["at expeuler"], "rtf": Ta / best["at expeuler"],
                          "h_star": 1e-3}
    for key, m in (("at auto", ma), ("at torsional auto", mt)):
        out[key] = {"T": Ta, "wall": best[key], "rtf": Ta / best[key], "method": m.default_method}
    return out


def scaling_n(quick: bool) -> dict:
    """Wall time vs n (full 3D, paper_open_loop), interleaved best of k."""
    ns = [15, 30, 60, 120]
    T = 0.3 if quick else 2.0
    models = {n: scene_model("paper_open_loop", n=n) for n in ns}
    for m in models.values():
        run_plant(m, 0.01, names=["strain1_C"])  # eigenvalues, compilation: not timed
    best = {n: math.inf for n in ns}
    for _ in range(2 if quick else 3):
        for n in ns:
            best[n] = min(best[n], run_plant(models[n], T, names=["strain1_C"]).wall)
    return {"T": T, "n": ns, "wall": [best[n] for n in ns],
            "h_star": [models[n].stable_step() for n in ns],
            "exponent": _fit_exponent(ns, [best[n] for n in ns]),
            "exponent_large": _fit_exponent(ns[1:], [best[n] for n in ns[1:]])}


def scaling_time(quick: bool) -> dict:
    """Wall time vs simulated time (n = 30)."""
    Ts = [1.0, 2.0, 4.0] if quick else [2.0, 4.0, 8.0, 16.0, 30.0]
    m = scene_model("paper_open_loop")
    run_plant(m, 0.01)  # stable step (eigenvalues) and compilation outside the timing
    best = {T: math.inf for T in Ts}
    for _ in range(1 if quick else 2):
        for T in Ts:
            best[T] = min(best[T], run_plant(m, T).wall)
    return {"T": Ts, "wall": [best[T] for T in Ts],
            "exponent": _fit_exponent(Ts, [best[T] for T in Ts])}


def memory(quick: bool) -> dict:
    """Peak memory of a paper_open_loop run in a fresh subprocess, and of the imports alone.

    ``cold``: the first run, which may compile the kernels (LLVM needs ~200 MiB more) when the
    numba cache was empty or dropped after an edit; then ``imports+model`` and ``run`` with
    the cache warm, what every later process sees.
    """
    T = 5.0 if quick else 30.0
    res = {}
    for key, run in (("cold", True), ("imports+model", False), ("run", True)):
        code = _MEM_SCRIPT.format(root=str(ROOT), run=run, T=T)
        out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                             check=True, timeout=600)
        res[key] = json.loads(out.stdout.strip().splitlines()[-1])
    res["T"] = T
    return res


if __name__ == "__main__":  # pragma: no cover
    t0 = time.perf_counter()
    print(json.dumps({"rt": real_time(True), "n": scaling_n(True), "T": scaling_time(True),
                      "mem": memory(True)}, indent=1, default=float))
    print("took", time.perf_counter() - t0)
