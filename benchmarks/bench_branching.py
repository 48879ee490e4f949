"""A switch-on sweep with and without branching, side by side in one run.

    python benchmarks/bench_branching.py [--stop-time 30] [--workers 2] [--engine fmu]

The sweep is ``paper_switch_on_25s`` (the controller switched on at 25 s into steady
vibration), 4 gains x 4 actuator delays at H = 0.25 ms, plus its open-loop reference: once with
every point run from 0 s (``branch=False``), once branching (each closed-loop point continues
from one checkpoint of the shared 25 s prefix, :mod:`cosim.study.branch`). Both runs use the same
workers, the unbranched one first; the FMUs are built before either is timed. Printed: the wall
time of each sweep, their ratio, and whether the two tables agree: every verdict, status and
metric column equal (timings and ``branch_time`` left out), with the largest difference of the
growth rates (0 when the records are bit-identical).
"""

from __future__ import annotations

import argparse
import math
import tempfile
import time
from pathlib import Path

from drillcosim.cosim.study.grid import SweepSpec
from drillcosim.cosim.study.sweep import execute_sweep
from drillcosim.cosim.study.table import read_table

GAINS = (1e8, 3e8, 1e9, 3e9)            # N per unit strain
DELAYS = (0.0, 5e-5, 1e-4, 2e-4)        # s
STEP = 2.5e-4                           # s
_TIMING = {"wall_time", "startup_time", "stepping_time", "worker_startup", "branch_time"}


def _same(a: object, b: object) -> bool:
    return a == b or (isinstance(a, float) and isinstance(b, float) and math.isnan(a)
                      and math.isnan(b))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--stop-time", type=float, default=30.0, help="[s] (default 30)")
    ap.add_argument("--workers", type=int, default=2, help="local worker processes")
    ap.add_argument("--engine", default="fmu", choices=("fmu", "inprocess"))
    args = ap.parse_args()
    spec = SweepSpec("paper_switch_on_25s", GAINS, DELAYS, [STEP], args.stop_time, args.engine)
    tables, walls = {}, {}
    with tempfile.TemporaryDirectory() as tmp:
        for branch in (False, True):
            out = Path(tmp) / ("branched" if branch else "straight")
            t0 = time.perf_counter()
            outcome = execute_sweep(spec, out, workers=args.workers, progress=False,
                                    branch=branch)
            walls[branch] = time.perf_counter() - t0
            tables[branch] = {r["key"]: r for r in read_table(out)}
            print(f"branch={branch}: {walls[branch]:.1f} s wall; {outcome.summary()}")
    straight, branched = tables[False], tables[True]
    differ = sorted({c for k, r in straight.items() for c, v in r.items()
                     if c not in _TIMING and not _same(v, branched[k][c])})
    growth = max((abs(r["growth_rate"] - branched[k]["growth_rate"])
                  for k, r in straight.items() if math.isfinite(r["growth_rate"])), default=0.0)
    verdicts = [(r["gain"], r["delay"], r["verdict"]) for r in straight.values()]
    print(f"ratio branched / straight: {walls[True] / walls[False]:.3f}")
    print(f"columns that differ: {differ or 'none'}; largest growth-rate difference {growth:g}")
    print(f"verdicts: {sorted(verdicts)}")


if __name__ == "__main__":
    main()
