"""The linear prediction of a sweep's maps and a sweep worker's start-up, before / after, side by
side in one run (the 12-point map's prediction; a sweep worker's start-up).

    python benchmarks/bench_prediction.py --before BEFORE --after . [--repeat 3]

BEFORE is a git worktree of the commit before the change, with its own ``make``-built ``.venv``.

Each task runs in a fresh process of the tree's own interpreter (``<tree>/.venv/bin/python``),
the trees interleaved, best of ``--repeat`` after a warm-up round (not timed);
``OPENBLAS_NUM_THREADS`` is left as a user's shell has it (unset). Tasks:

* ``prediction``: what ``drillcosim sweep paper_closed_loop --gain 1e6,1e8,1e9 --delay
  0,5e-5,1e-4,2e-4 --stop-time 6 --maps`` computes for its maps' prediction, in the process
  that draws them (imports included): before, the critical-gain boundary over the maps' 13
  delays (``maps.predicted_boundary``: one linearization, scan and bisection); after, the
  boundary (``prediction.predicted_boundary``: frequency response, checked) and the growth-rate
  curves of the three gains over the same delays (``growth_rate.png``), the linearization from
  the on-disk cache (filled by the warm-up); ``after, cold cache``: the same with an empty cache
  folder (the linearization computed);
* ``worker start-up``: a fresh process imports the sweep and runs two points of
  ``paper_closed_loop`` (FMU engine, H = 0.25 ms, 1 s each): its import, its first point and its
  second point [s wall, s CPU]; the first point's excess over the second is the rest of a
  worker's start-up.

The numbers: the boundary's critical gains of both trees (the bisection's midpoints at rtol 0.02
before) and the predicted growth rates of the 12 points (``LoopModel.growth_rate`` before,
``prediction.point_prediction`` after), with their largest differences.
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import platform
import subprocess
import sys
import tempfile
from pathlib import Path

_BEFORE = r"""
import json, sys, time
t0, c0 = time.perf_counter(), time.process_time()
import numpy as np
from drillcosim.cosim.study.maps import predicted_boundary
from drillcosim.cosim.study.stability import LoopModel
delays = sorted(set(np.linspace(0.0, 2e-4, 13).tolist()) | {0.0, 5e-5, 1e-4, 2e-4})
b = predicted_boundary("paper_closed_loop", [2.5e-4], delays, (1e5, 1e10))
wall, cpu = time.perf_counter() - t0, time.process_time() - c0
lm = LoopModel.from_scene("paper_closed_loop")
rates = [lm.growth_rate(g, d, 2.5e-4) for g in (1e6, 1e8, 1e9) for d in (0.0, 5e-5, 1e-4, 2e-4)]
print(json.dumps({"wall": wall, "cpu": cpu, "boundary": b[2.5e-4], "rates": rates}))
"""

_AFTER = r"""
import json, sys, time
t0, c0 = time.perf_counter(), time.process_time()
import numpy as np
from drillcosim.cosim.study.prediction import (point_prediction, predicted_boundary,
                                               predicted_curves)
delays = sorted(set(np.linspace(0.0, 2e-4, 13).tolist()) | {0.0, 5e-5, 1e-4, 2e-4})
b = predicted_boundary("paper_closed_loop", [2.5e-4], delays, (1e5, 1e10))
predicted_curves("paper_closed_loop", [1e6, 1e8, 1e9], [2.5e-4], delays)
wall, cpu = time.perf_counter() - t0, time.process_time() - c0
from drillcosim.cosim.study.point import point_config
rates = [point_prediction(point_config("paper_closed_loop", g, d, 2.5e-4, 6.0, False, None))[0]
         for g in (1e6, 1e8, 1e9) for d in (0.0, 5e-5, 1e-4, 2e-4)]
print(json.dumps({"wall": wall, "cpu": cpu, "boundary": b[2.5e-4], "rates": rates}))
"""

_WORKER = r"""
import json, time
t0, c0 = time.perf_counter(), time.process_time()
from drillcosim.cosim.study.sweep import point_row
from drillcosim.cosim.study.grid import Point
t1, c1 = time.perf_counter(), time.process_time()
point_row(Point("paper_closed_loop", 1e8, 1e-4, 2.5e-4, 1.0, "fmu"))
t2, c2 = time.perf_counter(), time.process_time()
point_row(Point("paper_closed_loop", 1e8, 2e-4, 2.5e-4, 1.0, "fmu"))
t3, c3 = time.perf_counter(), time.process_time()
print(json.dumps({"import": [t1 - t0, c1 - c0], "first": [t2 - t1, c2 - c1],
                  "second": [t3 - t2, c3 - c2]}))
"""


def _run(tree: Path, code: str, env: dict[str, str] | None = None) -> dict:
    py = tree / ".venv" / "bin" / "python"
    with tempfile.TemporaryDirectory() as cwd:
        proc = subprocess.run([str(py), "-c", code], cwd=cwd, capture_output=True, text=True,
                              env={**os.environ, **(env or {})})
    if proc.returncode != 0:
        raise RuntimeError(f"{tree}: failed:\n{proc.stderr[-3000:]}")
    return json.loads(proc.stdout.strip().splitlines()[-1])


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--before", required=True, type=Path)
    ap.add_argument("--after", required=True, type=Path)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--out", help="write the markdown section here (default: print)")
    args = ap.parse_args(argv)
    before, after = args.before.resolve(), args.after.resolve()
    best: dict[str, dict] = {}
    keep: dict[str, dict] = {}
    for rnd in range(args.repeat + 1):
        with tempfile.TemporaryDirectory() as cold:
            runs = {"before": (before, _BEFORE, None), "after": (after, _AFTER, None),
                    "after, cold cache": (after, _AFTER, {"DRILLCOSIM_CACHE": cold})}
            for name, (tree, code, env) in runs.items():
                got = _run(tree, code, env)
                keep[name] = got
                print(f"[{rnd}] prediction {name}: {got['wall']:.2f} s", file=sys.stderr)
                if rnd and got["wall"] < best.get(name, {"wall": float("inf")})["wall"]:
                    best[name] = got
        for name, tree in (("worker before", before), ("worker after", after)):
            got = _run(tree, _WORKER)
            print(f"[{rnd}] {name}: {got}", file=sys.stderr)
            if rnd and got["first"][0] < best.get(name, {"first": [float("inf")]})["first"][0]:
                best[name] = got
    kb = [k for _, k in keep["before"]["boundary"]]
    ka = [k for _, k in keep["after"]["boundary"]]
    rel = max(abs(a / b - 1) for a, b in zip(ka, kb))
    dr = max(abs(a - b) for a, b in zip(keep["after"]["rates"], keep["before"]["rates"]))
    lines = ["## The maps' prediction and a sweep worker's start-up (benchmarks/bench_prediction.py)",
             "", f"Command: `python benchmarks/bench_prediction.py --before {before} --after "
             f"{after} --repeat {args.repeat}`; {platform.platform()}, {os.cpu_count()} cores, "
             f"{datetime.datetime.now():%Y-%m-%d %H:%M}; best of {args.repeat} interleaved "
             f"runs after a warm-up round; load average at the end {os.getloadavg()[0]:.1f}.",
             "", "| prediction of the 12-point sweep's maps (fresh process) | wall [s] | CPU [s] |",
             "|---|---:|---:|"]
    for name in ("before", "after", "after, cold cache"):
        lines.append(f"| {name} | {best[name]['wall']:.2f} | {best[name]['cpu']:.2f} |")
    lines += ["", f"after / before: {best['after']['wall'] / best['before']['wall']:.2f} (wall), "
              f"{best['after']['cpu'] / best['before']['cpu']:.2f} (CPU). Boundary: largest "
              f"relative difference of the critical gains {rel:.2g} (the bisection's rtol: "
              f"0.02); the 12 points' predicted growth rates: largest difference {dr:.2g} 1/s.",
              "", "| sweep worker (fresh process, FMU engine, 1 s points) | import | first point "
              "| second point |", "|---|---:|---:|---:|"]
    for name in ("worker before", "worker after"):
        r = best[name]
        lines.append(f"| {name.split()[1]} [s wall / s CPU] | " + " | ".join(
            f"{r[k][0]:.2f} / {r[k][1]:.2f}" for k in ("import", "first", "second")) + " |")
    text = "\n".join(lines) + "\n"
    if args.out:
        Path(args.out).write_text(text)
    print(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
