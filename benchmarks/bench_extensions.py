"""Benchmarks of the physics extensions (docs/physics.md): cost when off, speed when on, and the
integrator choice for the nonsmooth scenes.

1. **Cost when off**, side by side: the paper's scenes through ``PlantSimulator`` on this tree
   and on a base tree (``--base-tree BASE``, e.g. ``git archive <commit> | tar -x -C BASE``), each in
   its own subprocess, interleaved, best of ``--repeat``. Rows as in docs/performance.md.
2. **Speed when on**: real-time factors of the new scenes (``stick_slip`` on the axial-torsional
   chain: target >= 200x real time at 1 ms outputs).
3. **Work-precision** on the nonsmooth scenes (``stick_slip``: the bit's regularized friction
   and stick phases; ``backward_whirl``: wall contact and friction): RK4 at the automatic step
   h* and fractions of it, DOPRI5 at several tolerances, against DOPRI5 at rtol 1e-11 (checked
   against 1e-10), errors as in ``bench_work_precision.py``.

Run: ``python benchmarks/bench_extensions.py --base-tree BASE [--quick]``; prints markdown
(the section "Physics extensions" of BENCHMARKS.md; with ``--base-tree``, of
docs/performance.md).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent

# One timing job: (label, scene, overrides, stop [s], h [s], mode). Modes: "record" (the
# compiled run-and-record loop of PlantSimulator), "steps" (a Python loop of do_step with inputs
# set every step, as the FMU adapter and the sweeps do).
OFF_JOBS = [
    ("paper_open_loop, full 3D, 30 s, 1 ms", "paper_open_loop", {}, 30.0, 1e-3, "record"),
    ("table1_axial_pulse, chain, 10 s, 1 ms", "table1_axial_pulse", {}, 10.0, 1e-3, "record"),
    ("table1_torsional_pulse, chain, 10 s, 1 ms", "table1_torsional_pulse", {}, 10.0, 1e-3,
     "record"),
    ("paper_closed_loop plant, inputs every 0.25 ms, 3 s", "paper_closed_loop", {}, 3.0, 2.5e-4,
     "steps"),
]

_CHILD = r"""
import json, sys, time
import numpy as np
from drillcosim.plant.model import DrillstringModel
from drillcosim.plant.scene import load_scene
from drillcosim.plant.simulator import PlantSimulator
jobs = json.loads(sys.argv[1])
out = []
for label, scene, over, stop, h, mode in jobs:
    sc = load_scene(scene, overrides=over or None)
    m = DrillstringModel(sc.plant, sc.model)
    sim = PlantSimulator(m)
    n = int(round(stop / h))
    idx = np.arange(len(m.output_names))
    sim.run_record(h, 2, idx)  # compile / warm
    sim = PlantSimulator(m)
    t0 = time.perf_counter()
    if mode == "record":
        rec, res = sim.run_record(h, n, idx)
    else:
        u = np.zeros(2 * m.n_sites)  # the actuator forces (base trees have no other input)
        for k in range(n):
            u[:] = 1e3 * np.sin(0.01 * k)
            sim.set_inputs(u)
            res = sim.do_step(k * h, h)
            sim.outputs()
    wall = time.perf_counter() - t0
    out.append([label, wall, bool(res.ok)])
print(json.dumps(out))
"""


def _shim(tree: Path, where: Path) -> Path:
    """A folder whose ``drillcosim`` package maps onto ``tree`` (as the installed layout)."""
    pkg = where / "drillcosim"
    pkg.mkdir(parents=True, exist_ok=True)
    (pkg / "__init__.py").write_text((tree / "drillcosim" / "__init__.py").read_text())
    for sub in ("plant", "controller", "cosim", "fmu_src", "scenes"):
        link = pkg / sub
        if not link.exists():
            link.symlink_to(tree / sub)
    return where


def _child(path: Path | None, jobs: list) -> list:
    env = dict(os.environ)
    if path is not None:
        env["PYTHONPATH"] = str(path) + os.pathsep + env.get("PYTHONPATH", "")
    cwd = tempfile.gettempdir()  # not the repository: ``python -c`` puts the cwd first
    code = "import drillcosim, sys; print(drillcosim.__file__)"
    where = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True,
                           text=True, check=True, cwd=cwd).stdout.strip()
    if path is not None and not where.startswith(str(path)):
        raise RuntimeError(f"the base tree is not imported (got {where})")
    if path is None and not where.startswith(str(ROOT)):
        raise RuntimeError(f"this tree is not imported (got {where})")
    r = subprocess.run([sys.executable, "-c", _CHILD, json.dumps(jobs)], env=env,
                       capture_output=True, text=True, check=True, cwd=cwd)
    return json.loads(r.stdout.strip().splitlines()[-1])


def cost_when_off(base_tree: Path, repeat: int) -> list[str]:
    """Markdown rows: wall time on base and head, best of ``repeat``, interleaved."""
    with tempfile.TemporaryDirectory() as tmp:
        shim = _shim(base_tree.resolve(), Path(tmp))
        _child(shim, OFF_JOBS[:1])  # compile both trees' kernels before timing
        _child(None, OFF_JOBS[:1])
        best: dict[tuple[str, str], float] = {}
        for _ in range(repeat):
            for tag, path in (("base", shim), ("head", None)):
                for label, wall, ok in _child(path, OFF_JOBS):
                    if not ok:
                        raise RuntimeError(f"{tag}: {label} failed")
                    key = (tag, label)
                    best[key] = min(best.get(key, math.inf), wall)
    rows = ["| scene (extensions off) | base [s] | this branch [s] | ratio |",
            "|---|---:|---:|---:|"]
    for label, *_ in OFF_JOBS:
        b, h = best[("base", label)], best[("head", label)]
        rows.append(f"| {label} | {b:.3f} | {h:.3f} | {h / b:.3f} |")
    return rows


def speed_when_on(repeat: int) -> list[str]:
    """Real-time factors of the new scenes through PlantSimulator (1 ms outputs)."""
    import numpy as np

    from drillcosim.plant.model import DrillstringModel
    from drillcosim.plant.scene import load_scene
    from drillcosim.plant.simulator import PlantSimulator

    rows = ["| scene | model | integrator, internal step | simulated [s] | wall [s] | x real time |",
            "|---|---|---|---:|---:|---:|"]
    for scene, stop in (("stick_slip", 60.0), ("bit_bounce", 8.0), ("backward_whirl", 5.0),
                        ("forward_whirl", 6.0)):
        sc = load_scene(scene)
        m = DrillstringModel(sc.plant, sc.model)
        idx = np.array([m.output_names.index(k) for k in sc.outputs])
        PlantSimulator(m).run_record(1e-3, 2, idx)
        wall = math.inf
        for _ in range(repeat):
            sim = PlantSimulator(m)
            t0 = time.perf_counter()
            _, res = sim.run_record(1e-3, int(round(stop / 1e-3)), idx)
            wall = min(wall, time.perf_counter() - t0)
            assert res.ok, res.message
        h = min(sim.max_step, 1e-3)
        n_sub = math.ceil(1e-3 / h - 1e-9)
        rows.append(f"| {scene} | {m.kind} | {sim.method}, {1.0 / n_sub:.3g} ms | {stop:g} | "
                    f"{wall:.3f} | {stop / wall:.0f} |")
    return rows


def _wp_scene(wp, scene: str, T: float, names: list[str], quick: bool,
              stat: tuple[str, str, float]) -> list[str]:
    """Work-precision table (markdown) of one scene over ``T`` seconds.

    ``stat`` = (signal, "mean" | "max", window [s]): a statistic of the last ``window`` seconds
    whose relative error is reported beside the trajectory error (the physical result: the
    whirl speed, the stick-slip peak speed).
    """
    m = wp.scene_model(scene)
    h0 = m.stable_step()
    r10 = wp.run_plant(m, T, "dopri5", rtol=1e-10, atol=1e-13, names=names,
                       label="ref DOPRI5 rtol 1e-10")
    ref = wp.run_plant(m, T, "dopri5", rtol=1e-11, atol=1e-14, names=names,
                       label="ref DOPRI5 rtol 1e-11")
    check = wp.traj_error(r10, ref)

    def cand(label: str, method: str, max_step: float | None = None, rtol: float = 1e-6):
        return label, lambda: wp.run_plant(m, T, method, max_step, rtol=rtol, atol=rtol * 1e-3,
                                           names=names, label=label)

    cands = [cand("rk4 (auto step h*)", "rk4"), cand("rk4 h*/2", "rk4", h0 / 2),
             cand("rk4 h*/4", "rk4", h0 / 4)]
    if m.n_state == m.n_body_state:
        cands.append(cand("verlet (auto step)", "verlet"))
    for rt in ((1e-4, 1e-7) if quick else (1e-4, 1e-6, 1e-8)):
        cands.append(cand(f"dopri5 rtol {rt:g}", "dopri5", rtol=rt))
    runs = wp.timed_best(cands, 2 if quick else 3)
    errs = [wp.traj_error(r, ref) for r in runs]
    sig, kind, window = stat

    def statistic(r) -> float:
        x = r.values[sig][r.t > T - window]
        return float(np.mean(x) if kind == "mean" else np.max(x))

    s_ref = statistic(ref)
    front = [not any((o.wall < r.wall and eo <= e) or (o.wall <= r.wall and eo < e)
                     for o, eo in zip(runs, errs)) for r, e in zip(runs, errs)]
    out = [f"### {scene} ({m.kind}, {T:g} s, signals {', '.join(names)})", "",
           f"Reference DOPRI5 rtol 1e-11 ({ref.wall:.2f} s); its difference to rtol 1e-10: "
           f"{check:.3g}. Automatic RK4 step h* = {h0 * 1e3:.3g} ms.", "",
           f"| candidate | wall [s] | x real time | rel. error (trajectory) | rel. error of the "
           f"{kind} {sig} over the last {window:g} s ({s_ref:.5g}) | Pareto front |",
           "|---|---:|---:|---:|---:|---|"]
    for r, e, f in zip(runs, errs, front):
        se = abs(statistic(r) - s_ref) / abs(s_ref) if r.ok else math.inf
        out.append(f"| {r.label} | {r.wall:.3f} | {T / r.wall:.0f} | {e:.3g} | {se:.3g} | "
                   f"{'*' if f else ''} |")
    return out + [""]


def work_precision(quick: bool) -> list[str]:
    """Work-precision tables of the nonsmooth scenes (markdown)."""
    sys.path.insert(0, str(HERE))
    import bench_work_precision as wp

    return (_wp_scene(wp, "stick_slip", 8.0 if quick else 20.0,
                      ["bit_rotary_speed", "bit_torque", "bit_axial_force"], quick,
                      ("bit_rotary_speed", "max", 5.0))
            + _wp_scene(wp, "backward_whirl", 2.0 if quick else 3.0,
                        ["body6_X", "body6_whirl_speed", "body6_contact_force"], quick,
                        ("body6_whirl_speed", "mean", 1.0)))


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--base-tree", type=Path, help="a checkout of the base (e.g. main)")
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--skip", default="", help="comma list of: off,on,wp")
    args = ap.parse_args(argv)
    skip = set(filter(None, args.skip.split(",")))
    t0 = time.perf_counter()
    lines = [f"Command: `python benchmarks/bench_extensions.py {' '.join(argv or sys.argv[1:])}`",
             ""]
    if "off" not in skip:
        if args.base_tree is None:
            ap.error("--base-tree is required for the cost-when-off comparison (or --skip off)")
        lines += ["### Cost when off (side by side, best of "
                  f"{args.repeat}, interleaved subprocesses)", ""]
        lines += cost_when_off(args.base_tree, args.repeat) + [""]
    if "on" not in skip:
        lines += ["### Speed of the new scenes (PlantSimulator, 1 ms outputs, best of "
                  f"{args.repeat})", ""] + speed_when_on(args.repeat) + [""]
    if "wp" not in skip:
        lines += work_precision(args.quick)
    lines.append(f"Total wall time: {time.perf_counter() - t0:.0f} s.")
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
