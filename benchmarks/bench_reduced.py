"""What the reduced (axial-torsional) model saves: the same scene on both models, side by side.

    python benchmarks/bench_reduced.py [--stop-time 10]

The two models give the same axial/torsional trajectories on these scenes (to 1e-9, tested in
tests/test_plant_physics.py), so the wall-time ratio is pure saving.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from drillcosim.plant.model import DrillstringModel  # noqa: E402
from drillcosim.plant.scene import load_scene  # noqa: E402
from drillcosim.plant.simulator import simulate  # noqa: E402

SCENES = ("table1_axial_pulse", "table1_torsional_pulse")


def wall(scene: str, kind: str, stop: float, method: str = "rk4", repeat: int = 3) -> float:
    """Best wall time [s] of ``stop`` s of ``scene`` on model ``kind`` (1 ms outputs)."""
    sc = load_scene(scene)
    m = DrillstringModel(sc.plant, kind)
    simulate(m, 0.01, 1e-3, list(sc.outputs), method=method)  # caches warm
    best = float("inf")
    for _ in range(repeat):
        t0 = time.perf_counter()
        simulate(m, stop, 1e-3, list(sc.outputs), method=method)
        best = min(best, time.perf_counter() - t0)
    return best


def report(stop: float) -> list[str]:
    """Markdown lines: wall time per model and integrator, and the savings."""
    lines = ["## What the reduced model saves (benchmarks/bench_reduced.py)", "",
             f"Command: `python benchmarks/bench_reduced.py --stop-time {stop:g}`; the same scene "
             "on the full 3D model and on the axial-torsional chain (identical axial/torsional "
             "results, tested), 1 ms outputs, best of 3: first both with RK4 at each model's "
             "automatic step (what the model alone saves), then the chain with its default "
             "integrator (`auto`: exponential Euler, one exact step per 1 ms, because these "
             "scenes are linear time-invariant).", "",
             "| scene | full 3D RK4 [s] | chain RK4 [s] | model saving | chain default [s] | "
             "total saving | chain default x real time |", "|---|---:|---:|---:|---:|---:|---:|"]
    for sc in SCENES:
        w3 = wall(sc, "full3d", stop)
        wa = wall(sc, "axial_torsional", stop)
        wd = wall(sc, "axial_torsional", stop, "auto")
        lines.append(f"| {sc} | {w3:.3f} | {wa:.3f} | {w3 / wa:.1f}x | {wd:.4f} | {w3 / wd:.0f}x "
                     f"| {stop / wd:.0f} |")
    return lines + [""]


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--stop-time", type=float, default=10.0, help="simulated time [s]")
    args = ap.parse_args(argv)
    print("\n".join(report(args.stop_time)))
    return 0


if __name__ == "__main__":
    sys.exit(main())
