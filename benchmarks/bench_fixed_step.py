"""Integrator at the communication step: every fixed-step method at a scene's step H.

    python benchmarks/bench_fixed_step.py [--quick] [--repeat 3] [--scenes a,b,...] [--step H]

For each scene, the plant alone (inputs zero) is stepped at the scene's communication step H
(its ``[cosim] step``) through its compiled step (``plant.compiled_step``: what the plant FMU
and the in-process slave run), once with every method of ``plant.integrators.METHODS`` that
applies to the model: at its automatic internal step (``H / ceil(H / stable step)``), or, for
the methods without one (the 2-stage Runge-Kutta methods, whose stability region holds no part
of the imaginary axis), one step a communication step. Error: max over the scene's signals of
max|y - y_ref| / max|y_ref| over the first T seconds (2 s), sampled every 1 ms (every H if H is
longer), against DOPRI5 at rtol 1e-10 (its difference to rtol 1e-11 is reported). Cost: right-
hand side evaluations per communication step (exact) and wall time (best of k, candidates
interleaved; the machine is shared). The accuracy bar: error <= 1e-4.

A scene with a controller is also run closed loop (in-process slaves through the master, the
scene's algorithm, step and order): each method as the plant's integrator against the same loop
with RK4 at h*/8 in the plant (the co-simulation error, the same in every run, cancels).

Checks, per smooth scene (the nonsmooth ones, wall impacts and bit bounce, are reported: no
fixed step practical here keeps their trajectories within the bar over 2 s, their statistics
are in bench_extensions.py and, for the field strings, bench_field.py): the method the plant picks for H
(``DrillstringModel.method_for_step``) is on the Pareto front of (cost, error), the cost being
(rhs evaluations per H, internal steps per H), and meets the bar; and for the method table:
every method marked ``automatic`` for the scene's model kind meets the bar at its automatic
step (its marks are data the automatic choice relies on).
The other half of the bar, the RMS radial deflection within 1 % over 30 s, is a statistic of an
ensemble of runs: ``benchmarks/bench_rms_sensitivity.py --fixed METHOD@STEP,...``.
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
sys.path.insert(0, str(HERE.parent))

import bench_work_precision as wp  # noqa: E402

from drillcosim.plant.integrators import KERNEL_VERLET, METHODS  # noqa: E402
from drillcosim.plant.model import DrillstringModel  # noqa: E402
from drillcosim.plant.simulator import PlantSimulator  # noqa: E402

BAR = 1e-4  # relative trajectory error over T
T_ERR = 2.0  # s
DT_OUT = 1e-3  # s, sampling of the error (or H if longer)

#: Scenes: their signals (None: bench_work_precision.SIGNALS of the model kind) and whether
#: they are smooth (the trajectory bar applies).
SCENES: dict[str, tuple[tuple[str, ...] | None, bool]] = {
    "paper_closed_loop": (None, True),
    "paper_open_loop": (None, True),
    "table1_lateral_step": (("body11_X", "body26_X", "strain1_C"), True),
    "stick_slip": (("bit_rotary_speed", "bit_torque", "bit_axial_force"), True),
    "table1_axial_pulse": (None, True),
    "backward_whirl": (("body6_X", "body6_whirl_speed", "body6_contact_force"), False),
    "bit_bounce": (None, False),
    "field_vertical_3km": (("bit_rotary_speed", "top_torque", "hook_load", "bit_axial_force"),
                           True),
    # wall impacts of ~100 bodies as the string falls onto the low side: DOPRI5 at rtol 1e-10
    # and 1e-11 differ by 1e-4 (its statistics: benchmarks/bench_field.py, section 6)
    "field_deviated_3km": (("bit_rotary_speed", "top_torque", "hook_load",
                            "max_radial_deflection", "wall_contact_force"), False),
}


@dataclass
class Candidate:
    """One method at a scene's H."""

    method: str
    internal_step: float  # s
    rhs_per_step: int
    run: wp.Run | None  # None: not applicable
    why: str = ""
    steps: int = 0  # internal steps per H


def scene_step(name: str, step: float | None = None) -> tuple[DrillstringModel, float, bool]:
    """The scene's model (its own kind), communication step H [s] (``step``, or the scene's),
    whether it has a strain controller."""
    from drillcosim.cosim.scenario.config import load_config

    config = load_config(name, {"cosim.step": step} if step else None)
    sc = config.scene
    return DrillstringModel(sc.plant, sc.model), config.cosim.step, config.controller.enabled


def run_fixed(model: DrillstringModel, H: float, T: float, method: str,
              names: list[str]) -> tuple[wp.Run, float, int]:
    """The plant stepped at ``H`` through its compiled step with ``method``; sampled outputs.

    Returns the run, the internal steps and the rhs evaluations per communication step.
    Raises ValueError when the method does not apply to the model.
    """
    spec = METHODS[method]
    warm = PlantSimulator(model, H if spec.radius == 0.0 else None, method)
    warm.do_step(0.0, H)  # compiles, builds an exponential operator: not timed
    sim = PlantSimulator(model, H if spec.radius == 0.0 else None, method)
    n_sub = max(1, math.ceil(H / sim.max_step - 1e-9)) if math.isfinite(sim.max_step) else 1
    rhs = spec.stages * n_sub + (1 if spec.kernel == KERNEL_VERLET else 0)  # Verlet: FSAL
    out = np.zeros(len(model.output_names))
    inp = np.zeros(model.n_inputs)
    step = sim.compiled_step(inp, np.arange(inp.size), out, np.arange(out.size))
    if step is None:
        raise ValueError(f"no compiled step for {method} on this model")
    idx = [model.output_names.index(n) for n in names]
    every = max(1, int(round(DT_OUT / H)))
    n_steps = int(round(T / H))
    rows = [sim.outputs()[idx].copy()]
    ok = True
    t0 = time.perf_counter()
    for k in range(n_steps):
        res = step.step(k * H, H)
        if not res.ok:
            if not res.quantity:  # refused: e.g. an exponential integrator on the 3D model
                raise ValueError(res.message)
            ok = False
            break
        if (k + 1) % every == 0:
            rows.append(out[idx].copy())
    wall = time.perf_counter() - t0
    arr = np.array(rows)
    dt = every * H
    run = wp.Run(method, method, wall, np.arange(len(arr)) * dt,
                 {n: arr[:, i] for i, n in enumerate(names)}, ok)
    return run, n_sub, rhs


def applicable(model: DrillstringModel, method: str) -> str:
    """Why ``method`` does not apply to ``model`` ("" if it does)."""
    spec = METHODS[method]
    if spec.radius is None and model.kind != "axial_torsional":
        return "exponential integrators need the axial-torsional model"
    if spec.kernel == KERNEL_VERLET and model.n_state != model.n_body_state:
        return "Verlet needs a state of positions and velocities only"
    return ""


def front(cands: list[Candidate], errors: dict[str, float]) -> set[str]:
    """Methods on the Pareto front of (cost, error) among the finished runs, the cost being
    (rhs evaluations per H, internal steps per H) in that order: the same on every machine
    (the wall time, its noisy image, is shown); at equal rhs fewer steps do less other work."""
    pts = [((c.rhs_per_step, c.steps), errors[c.method], c.method) for c in cands
           if c.run is not None and c.run.ok]
    return {m for w, e, m in pts
            if not any(w2 <= w and e2 <= e and (w2, e2) != (w, e) for w2, e2, _ in pts)}


def closed_loop_table(name: str, H: float, T: float, names: list[str]) -> list[str]:
    """The scene's closed loop (in-process) with each automatic-capable method in the plant."""
    from drillcosim.cosim.master.master import Master
    from drillcosim.cosim.scenario.build import build_system
    from drillcosim.cosim.scenario.config import load_config
    from drillcosim.cosim.scenario.inprocess import PlantSlave

    config = load_config(name, {"cosim.stop_time": T})
    algorithm = config.cosim.algorithm
    model0 = build_system(config, "inprocess").slaves["plant"].sim.model  # the FMU's model
    base = DrillstringModel(model0.params, model0.kind)

    def run(method: str, max_step: float | None) -> tuple[np.ndarray, float]:
        built = build_system(config, "inprocess")
        plant = PlantSimulator(DrillstringModel(base.params, base.kind), max_step, method)
        built.slaves["plant"] = PlantSlave("plant", plant)
        t0 = time.perf_counter()
        res = Master(built.system, built.slaves).simulate(outputs=built.outputs)
        wall = time.perf_counter() - t0
        every = max(1, int(round(DT_OUT / H)))
        return np.array([res.data[f"plant.{n}"][::every] for n in names]).T, wall

    ref, ref_wall = run("rk4", base.stable_step() / 8)
    scale = np.abs(ref).max(axis=0)
    L = [f"Closed loop ({algorithm}, H = {H * 1e3:g} ms, {T:g} s, "
         f"in-process slaves): each method in the plant against RK4 at h*/8 in the plant "
         f"({ref_wall:.2f} s).", "",
         "| method in the plant | rhs per H | wall [s] | rel. error | <= 1e-4 |",
         "|---|---:|---:|---:|---|"]
    for method, spec in METHODS.items():
        if applicable(base, method) or spec.radius is None:
            continue
        max_step = H if spec.radius == 0.0 else None
        sim = PlantSimulator(base, max_step, method)
        n_sub = max(1, math.ceil(H / sim.max_step - 1e-9))
        got, wall = run(method, max_step)
        if got.shape != ref.shape or not np.all(np.isfinite(got)):
            L.append(f"| {method} | {spec.stages * n_sub} | {wall:.2f} | diverged | no |")
            continue
        e = float((np.abs(got - ref).max(axis=0) / scale).max())
        L.append(f"| {method} | {spec.stages * n_sub} | {wall:.2f} | {e:.3g} | "
                 f"{'yes' if e <= BAR else 'no'} |")
    return L + [""]


def scene_table(name: str, signals: tuple[str, ...] | None, smooth: bool, repeat: int,
                T: float, step: float | None = None) -> tuple[list[str], dict]:
    """Markdown of one scene (at ``step`` [s], or its own H) and its verdicts."""
    model, H, controlled = scene_step(name, step)
    names = list(signals or wp.SIGNALS[model.kind])
    if H > DT_OUT:
        raise ValueError(f"{name}: H = {H} s longer than {DT_OUT} s is not supported")
    ref10 = wp.run_plant(model, T, "dopri5", rtol=1e-10, atol=1e-13, names=names)
    ref11 = wp.run_plant(model, T, "dopri5", rtol=1e-11, atol=1e-14, names=names)
    check = wp.traj_error(ref11, ref10)
    cands = {m: Candidate(m, math.nan, 0, None, applicable(model, m)) for m in METHODS}
    best: dict[str, float] = {}
    for _ in range(repeat):
        for method, c in cands.items():
            if c.why:
                continue
            try:
                run, n_sub, rhs = run_fixed(model, H, T, method, names)
            except ValueError as exc:
                c.why = str(exc)
                continue
            if method not in best or run.wall < best[method]:
                best[method] = run.wall
                c.run, c.internal_step, c.rhs_per_step, c.steps = run, H / n_sub, rhs, n_sub
    errors = {m: wp.traj_error(c.run, ref10) if c.run is not None else math.inf
              for m, c in cands.items()}
    on_front = front(list(cands.values()), errors)
    chosen = model.method_for_step(H)
    L = [f"### {name} ({model.kind}, H = {H * 1e3:g} ms, {T:g} s, signals {', '.join(names)}"
         f"{'' if smooth else '; nonsmooth: reported, not judged'})", "",
         f"Reference DOPRI5 rtol 1e-10 ({ref10.wall:.2f} s); its difference to rtol 1e-11: "
         f"{check:.2g}. Stable RK4 step h* = {model.stable_step() * 1e3:.3f} ms; the plant's "
         f"method at this H: **{chosen}**.", "",
         "| method | stages | order | internal step [ms] | steps per H | rhs per H | wall [s] | "
         "x real time | rel. error | <= 1e-4 | Pareto front (cost, error) |",
         "|---|---:|---:|---:|---:|---:|---:|---:|---:|---|---|"]
    rows = sorted(cands.values(), key=lambda c: (c.run is None, c.run.wall if c.run else 0.0))
    for c in rows:
        spec = METHODS[c.method]
        mark = " (chosen)" if c.method == chosen else ""
        if c.run is None:
            L.append(f"| {c.method}{mark} | {spec.stages} | {spec.order} | - | - | - | - | - | - "
                     f"| - | not applicable: {c.why} |")
            continue
        e = errors[c.method]
        L.append(f"| {c.method}{mark} | {spec.stages} | {spec.order} | "
                 f"{c.internal_step * 1e3:.4g} | {c.steps} | {c.rhs_per_step} | {c.run.wall:.3f} | "
                 f"{T / c.run.wall:.1f} | {'diverged' if not c.run.ok else f'{e:.3g}'} | "
                 f"{'yes' if e <= BAR else 'no'} | {'*' if c.method in on_front else ''} |")
    verdict = {"scene": name, "H": H, "kind": model.kind, "smooth": smooth, "chosen": chosen,
               "errors": errors, "chosen_ok": errors[chosen] <= BAR and chosen in on_front,
               "automatic_fail": [m for m, sp in METHODS.items() if model.kind in sp.automatic
                                  and cands[m].run is not None and errors[m] > BAR]}
    L += [""]
    if controlled:
        L += closed_loop_table(name, H, T, names)
    return L, verdict


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="2 scenes, 1 repeat")
    ap.add_argument("--repeat", type=int, default=3, help="best of k wall times (default 3)")
    ap.add_argument("--scenes", default="", help="comma list (default: all of SCENES)")
    ap.add_argument("--step", type=float, default=None,
                    help="communication step H [s] instead of each scene's own")
    args = ap.parse_args(argv)
    scenes = [s for s in args.scenes.split(",") if s] or (
        ["paper_closed_loop", "stick_slip"] if args.quick else list(SCENES))
    unknown = [s for s in scenes if s not in SCENES]
    if unknown:
        ap.error(f"--scenes: unknown {', '.join(unknown)}; allowed {', '.join(SCENES)}")
    repeat = 1 if args.quick else args.repeat
    t0 = time.perf_counter()
    cmd = "python benchmarks/bench_fixed_step.py " + " ".join(argv if argv is not None
                                                              else sys.argv[1:])
    L = ["## Integrator at the communication step (benchmarks/bench_fixed_step.py)", "",
         f"Command: `{cmd.strip()}`; best of {repeat}, candidates interleaved.", "",
         "The plant alone (inputs zero) stepped at the scene's communication step H through its "
         "compiled step, with every fixed-step method of `plant.integrators.METHODS` that applies "
         "(at its automatic internal step; the 2-stage methods, which have none, one step per H). "
         f"Error: max over the signals of max|y - y_ref| / max|y_ref| over {T_ERR:g} s at 1 ms "
         f"against DOPRI5 rtol 1e-10; bar {BAR:g}. rhs per H: right-hand side evaluations per "
         "communication step. The plant's method for H is `DrillstringModel.method_for_step`: "
         "the fewest rhs per H among the methods marked automatic for the model kind (ties to "
         "fewer internal steps, then the higher order). Pareto front on (cost, error), the cost "
         "being (rhs per H, internal steps per H): machine-independent; the wall times (noisy "
         "on a shared machine) show the same order. A scene with a controller is also run "
         "closed loop.", ""]
    verdicts = []
    for s in scenes:
        print(f"{s} ...", file=sys.stderr, flush=True)
        signals, smooth = SCENES[s]
        lines, v = scene_table(s, signals, smooth, repeat, T_ERR, args.step)
        L += lines
        verdicts.append(v)
    L += ["| check (smooth scenes) | result |", "|---|---|"]
    judged = [v for v in verdicts if v["smooth"]]
    for v in judged:
        L.append(f"| {v['scene']} (H = {v['H'] * 1e3:g} ms): the plant's method "
                 f"{v['chosen']} meets the bar and is on the Pareto front | "
                 f"{'yes' if v['chosen_ok'] else 'NO'} (error {v['errors'][v['chosen']]:.2g}) |")
    for kind in ("full3d", "axial_torsional"):
        auto = [m for m, sp in METHODS.items() if kind in sp.automatic]
        these = [v for v in judged if v["kind"] == kind]
        fails = sorted({f"{m} ({v['scene']})" for v in these for m in v["automatic_fail"]})
        L.append(f"| every method marked automatic for {kind} ({', '.join(auto)}) meets the bar "
                 f"at its automatic step on every smooth {kind} scene "
                 f"({', '.join(v['scene'] for v in these) or 'none run'}) | "
                 f"{'not checked' if not these else 'yes' if not fails else 'NO: ' + ', '.join(fails)} |")
    L += ["", f"Total wall time: {time.perf_counter() - t0:.0f} s.", ""]
    print("\n".join(L))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
