"""Field-scale strings: right-hand-side cost per body, what sets the step, and the field scenes
against the paper's scene, side by side in one run.

    python benchmarks/bench_field.py [--quick]

Sections of the report (markdown on stdout):

1. rhs cost per body for 30 ... 300 bodies: the compiled right-hand side called in a compiled
   loop (no Python per call), for the paper's uniform pipe and for a field string in the
   deviated well (per-body frames, a contact check at every body), on the axis and with every
   body pressed on the wall with friction (every contact branch taken).
2. The paper scene's cost against n: the automatic RK4 step h* and where it comes from.
3. field_deviated_3km (and field_vertical_3km) against paper_open_loop, plant alone, per
   simulated second, best of k, interleaved; the target is (bodies / 30) x 1.2.
4. Where a field step goes (rhs, RK4 update, outputs and checks) and which eigenvalues set h*.
5. Work-precision of field_deviated_3km over 2 s, per signal, against DOPRI5 at rtol 1e-10: the
   plant's automatic method (``DrillstringModel.method_for_step``) at H = 1 ms and 0.25 ms,
   the other candidates at the same H, finer RK4 steps.
6. The automatic method at 1 ms and 0.25 ms on field_deviated_3km over 40 s: stable, and its
   statistics against RK4 at h*/8, beside a second reference (RK4 at h*/4).
7. What the joint dampers add to the rotating surface torque of field_deviated_3km (off
   bottom): runs with and without them, and the formula c_be omega theta^2 per bent joint.

``--only 5,6`` runs some sections.
"""

from __future__ import annotations

import argparse
import math
import platform
import sys
import time
from datetime import datetime
from pathlib import Path

import numpy as np
from numba import njit

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from drillcosim.plant import kernels as kern  # noqa: E402
from drillcosim.plant import layout as lay  # noqa: E402
from drillcosim.plant.integrators import METHODS, advance_rk4, stable_step  # noqa: E402
from drillcosim.plant.model import DrillstringModel  # noqa: E402
from drillcosim.plant.observables import outputs3d  # noqa: E402
from drillcosim.plant.params import (  # noqa: E402
    BitParams,
    PlantParams,
    SectionParams,
    TopDriveParams,
    UnbalanceParams,
)
from drillcosim.plant.scene import load_scene  # noqa: E402
from drillcosim.plant.simulator import PlantSimulator, simulate  # noqa: E402

try:
    from threadpoolctl import threadpool_limits
except ImportError:  # pragma: no cover
    from contextlib import nullcontext as threadpool_limits  # type: ignore[assignment]


@njit(cache=False)
def _rhs_loop(model, reps, y, dy, p, ip, fp, u, wR, wF, wM):
    acc = 0.0
    for i in range(reps):
        kern.rhs(model, 0.1 + 1e-9 * i, y, dy, p, ip, fp, u, wR, wF, wM)
        acc += dy[-1]
    return acc


def rhs_seconds(m: DrillstringModel, y: np.ndarray, reps: int, repeat: int = 5) -> float:
    """Best time [s] of one right-hand side at state ``y`` (compiled loop of ``reps`` calls)."""
    dy = np.empty_like(y)
    args = (m.model_id, 0, y, dy, m.p, m.ip, m.fp, m.u, m.wR, m.wF, m.wM)
    _rhs_loop(*args[:1], 1, *args[2:])  # compile
    best = math.inf
    for _ in range(repeat):
        t0 = time.perf_counter()
        _rhs_loop(args[0], reps, *args[2:])
        best = min(best, time.perf_counter() - t0)
    return best / reps


def field_string(n: int) -> PlantParams:
    """3000 m of 5-in drill pipe in n equal segments in the field_deviated_3km well, in mud,
    wall friction 0.25."""
    dev = load_scene("field_deviated_3km").plant
    return PlantParams(
        sections=(SectionParams(kind="drill_pipe", length=3000.0, outer_diameter=0.127,
                                inner_diameter=0.1086, linear_mass=32.6,
                                contact_diameter=0.1683, segment_length=3000.0 / n),),
        trajectory=dev.trajectory, fluid=dev.fluid, contact=dev.contact, damping=dev.damping,
        bit=BitParams(axial_stiffness=0.0, radius=0.5 * dev.trajectory.hole_diameter(3000.0)),
        unbalance=UnbalanceParams(enabled=False), top_drive=TopDriveParams(rotary_speed=4.0),
        gravity=9.81)


def on_the_wall(m: DrillstringModel, y: np.ndarray, spin: float = 4.0) -> np.ndarray:
    """``y`` with every body pressed 1 mm into the wall on its low side, spinning."""
    y = y.copy()
    n = m.n
    for k in range(n):
        o = lay.NP + lay.NB * k
        g = m.p[o + lay.B_R: o + lay.B_R + 9].reshape(3, 3).T @ np.array([0.0, 0.0, 1.0]) \
            if m.framed else np.array([1.0, 0.0, 0.0])
        g[2] = 0.0
        g = g / np.linalg.norm(g) if np.linalg.norm(g) > 1e-9 else np.array([1.0, 0.0, 0.0])
        y[3 * k: 3 * k + 2] = (m.p[o + lay.B_CLR] + 1e-3) * g[:2]
        y[9 * n + 3 * k + 2] = spin
    return y


def section_rhs_per_body(quick: bool) -> list[str]:
    sizes = (30, 60, 100, 200, 300)
    rounds = 5 if quick else 25
    cases = []  # (label, n, model, state)
    for n in sizes:
        paper = load_scene("paper_open_loop", overrides={"pipe": {"n_segments": n},
                                                          "contact": {"bodies": []},
                                                          "outputs": []}).plant
        mp = DrillstringModel(paper, "full3d")
        cases.append(("paper pipe (uniform, 2 contact bodies)", n, mp, mp.initial_state()))
        mf = DrillstringModel(field_string(n), "full3d")
        yf = mf.initial_state()
        cases.append(("field string, on the axis", n, mf, yf))
        cases.append(("field string, every body on the wall", n, mf, on_the_wall(mf, yf)))
    best = {(c[0], c[1]): math.inf for c in cases}
    for _ in range(rounds):  # interleaved rounds of ~5 ms loops: the minimum over all rounds
        for label, n, m, y in cases:
            reps = max(20000 // n, 20)
            best[label, n] = min(best[label, n], rhs_seconds(m, y, reps, repeat=1))
    rows = []
    per = {label: [best[label, n] / n for n in sizes] for label in dict.fromkeys(c[0] for c in cases)}
    for name, vals in per.items():
        v = np.array(vals) * 1e9
        rows.append(f"| {name} | " + " | ".join(f"{x:.0f}" for x in v)
                    + f" | {v.max() / v.min():.2f} |")
    head = ("| string | " + " | ".join(f"n = {n}" for n in sizes) + " | max / min |")
    return ["### 1. Right-hand side cost per body [ns]", "",
            "One compiled right-hand side at a fixed state, called in a compiled loop of ~5 ms, "
            "the minimum over interleaved rounds (the machine is shared), divided by the number "
            "of bodies. Paper pipe: paper_open_loop with "
            "`pipe.n_segments = n`. Field string: 3000 m of 5-in drill pipe in n segments in "
            "the field_deviated_3km well (per-body reference frames, a radial contact check at "
            "every body and at the bit, mud drag), on the hole axis or pressed 1 mm into the "
            "low side and spinning (every contact and friction branch taken). Target: max / min "
            "<= 1.2 from 30 to 300 bodies.", "",
            head, "|---|" + "---:|" * (len(sizes) + 1), *rows, ""]


def paper_scaling(quick: bool) -> list[str]:
    sizes = (15, 30, 60, 120) if not quick else (15, 30, 60)
    rows = []
    for n in sizes:
        out = []
        for cap in (math.inf, 0.0):
            sc = load_scene("paper_open_loop", overrides={
                "pipe": {"n_segments": n}, "contact": {"bodies": []}, "outputs": [],
                "damping": {"max_joint_rate": cap}})
            m = DrillstringModel(sc.plant, "full3d")
            J = m.initial_jacobian
            with threadpool_limits(1):
                lam = np.linalg.eigvals(J)
            k = int(np.argmax(np.abs(lam)))
            out.append((m.stable_step(), lam[k]))
        (h0, l0), (h1, l1) = out
        rows.append(f"| {n} | {h0 * 1e3:.3f} | {l0.real:.0f} {l0.imag:+.0f}j | {h1 * 1e3:.3f} "
                    f"| {h1 / h0:.1f} |")
    return ["### 2. Why the paper scene costs ~n^2.35: the step, not the right-hand side", "",
            "paper_open_loop with n segments: the automatic RK4 step h* and the eigenvalue of "
            "largest modulus that sets it, then the same with the joint dampers capped "
            "(`damping.max_joint_rate = 0`: no overdamped joint mode faster than the string's "
            "highest joint frequency). The right-hand side costs the same per body (section 1), "
            "so the cost per simulated second is ~ n / h*. The stiffness-proportional dampers "
            "c = beta k (beta fixed by the first mode's damping ratio) make the highest joint "
            "modes overdamped with a real eigenvalue ~ -beta w_max^2 ~ n^2: h* falls as 1/n^2 "
            "and the cost grows as n^3 once that real eigenvalue dominates (n >= 30 here).", "",
            "| n | h* [ms] (paper damping) | largest eigenvalue [1/s] | h* [ms] (capped) | "
            "step gain |", "|---:|---:|---|---:|---:|", *rows, ""]


def wall_per_second(scene: str, T: float, repeat: int, kind: str | None = None,
                    overrides: dict | None = None) -> tuple[float, float, int]:
    sc = load_scene(scene, overrides=overrides)
    m = DrillstringModel(sc.plant, kind or sc.model)
    h = m.stable_step()
    simulate(m, 0.01, 1e-3, list(sc.outputs))
    best = math.inf
    for _ in range(repeat):
        mm = DrillstringModel(sc.plant, kind or sc.model)
        mm.__dict__["max_eigenvalue"] = m.max_eigenvalue
        t0 = time.perf_counter()
        _, _, res = simulate(mm, T, 1e-3, list(sc.outputs))
        best = min(best, time.perf_counter() - t0)
        assert res.ok, res.message
    return best / T, h, m.n


def side_by_side(quick: bool) -> list[str]:
    T = 1.0 if quick else 2.0
    rep = 2 if quick else 5
    cases = [("paper_open_loop", None, None, "paper_open_loop"),
             ("field_deviated_3km", None, None, "field_deviated_3km"),
             ("field_vertical_3km", None, None, "field_vertical_3km (axial-torsional)"),
             ("field_vertical_3km", "full3d", None, "field_vertical_3km, full 3D"),
             ("field_deviated_3km", None, {"sections": _fine_bha()},
              "field_deviated_3km, BHA in 1.5 m segments")]
    res = {label: [] for *_, label in cases}
    meta = {}
    for _ in range(rep):  # interleaved
        for scene, kind, over, label in cases:
            w, h, n = wall_per_second(scene, T, 1, kind, over)
            res[label].append(w)
            meta[label] = (h, n)
    base = min(res["paper_open_loop"])
    rows = []
    for *_, label in cases:
        w = min(res[label])
        h, n = meta[label]
        target = n / 30 * 1.2
        rows.append(f"| {label} | {n} | {h * 1e3:.3f} | {w:.3f} | {T / (w * T):.1f} | "
                    f"{w / base:.2f} | {target:.2f} | {'yes' if w / base <= target else 'no'} |")
    return ["### 3. Field scenes against paper_open_loop, plant alone", "",
            f"Wall time per simulated second through `plant.simulator.simulate` (RK4 at the "
            f"automatic step, 1 ms outputs of the scene's outputs), {T:g} s simulated, best of "
            f"{rep}, the cases interleaved in one run. Target: at most (bodies / 30) x "
            "1.2 times paper_open_loop.", "",
            "| case | bodies | h* [ms] | wall per simulated s [s] | x real time | vs paper | "
            "target | met |", "|---|---:|---:|---:|---:|---:|---:|---|", *rows, ""]


def _fine_bha() -> list[dict]:
    """field_deviated_3km's sections with the collars in 1.5 m segments."""
    secs = []
    for s in load_scene("field_deviated_3km").plant.sections:
        d = {f: getattr(s, f) for f in s.__dataclass_fields__}
        d["stabilizers"] = list(d["stabilizers"])
        if s.kind == "collar":
            d["segment_length"] = 1.5
        secs.append(d)
    return secs


def cost_split(quick: bool) -> list[str]:
    sc = load_scene("field_deviated_3km")
    m = DrillstringModel(sc.plant, sc.model)
    h = m.stable_step()
    from drillcosim.plant.simulator import PlantSimulator

    sim = PlantSimulator(m)  # 1 s: the string falls onto the wall
    for k in range(1000):
        sim.do_step(k * 1e-3, 1e-3)
    sim_y = sim.y.copy()
    reps = 300 if quick else 3000
    t_rhs = rhs_seconds(m, sim_y, reps)
    k1, k2, k3, k4, yt = m._scratch
    yy = sim_y.copy()
    steps = 100 if quick else 1000
    advance_rk4(m.model_id, 1.0, yy, 2, h, m.p, m.ip, m.fp, m.u, m.wR, m.wF, m.wM, k1, k2, k3, k4,
                yt)
    t0 = time.perf_counter()
    advance_rk4(m.model_id, 1.0, yy, steps, h, m.p, m.ip, m.fp, m.u, m.wR, m.wF, m.wM, k1, k2,
                k3, k4, yt)
    t_step = (time.perf_counter() - t0) / steps
    out = np.zeros(len(m.output_names))
    outputs3d(1.0, sim_y, m.p, m.ip, m.fp, m.u, m.wR, 0.0, out)
    t0 = time.perf_counter()
    for _ in range(reps):
        outputs3d(1.0, sim_y, m.p, m.ip, m.fp, m.u, m.wR, 0.0, out)
    t_out = (time.perf_counter() - t0) / reps
    steps_per_ms = math.ceil(1e-3 / h - 1e-9)
    per_ms = steps_per_ms * t_step + t_out
    with threadpool_limits(1):
        lam, vec = np.linalg.eig(m.initial_jacobian)
    order = np.argsort(-np.abs(lam))
    n = m.n
    seen = []
    erows = []
    names = ("position", "angle", "velocity", "angular velocity")
    for i in order:
        if len(erows) >= 5:
            break
        if lam[i].imag < 0:
            continue
        v = np.abs(vec[:, i])
        j = int(np.argmax(v))
        body, comp = (j % (3 * n)) // 3 + 1, "xyz"[j % 3]
        key = (body, names[j // (3 * n)])
        if key in seen:
            continue
        seen.append(key)
        what = _eigen_source(m, body, names[j // (3 * n)], comp)
        erows.append(f"| {lam[i].real:.0f} {lam[i].imag:+.0f}j | {abs(lam[i]):.0f} | body {body} "
                     f"({_section_of(m, body)}), {names[j // (3 * n)]} {comp} | {what} |")
    return ["### 4. Where a field_deviated_3km step goes and what sets it", "",
            f"State after 1 s (the string on the low side). RK4 step h* = {h * 1e3:.3f} ms "
            f"({steps_per_ms} steps per 1 ms output). One right-hand side {t_rhs * 1e6:.1f} us "
            f"({t_rhs / n * 1e9:.0f} ns per body, {n} bodies); one RK4 step (4 right-hand sides "
            f"+ the stage updates) {t_step * 1e6:.1f} us, of which the right-hand sides "
            f"{4 * t_rhs / t_step:.0%}; outputs and field summary per 1 ms {t_out * 1e6:.1f} us. "
            f"Per 1 ms: {per_ms * 1e6:.0f} us = {steps_per_ms * t_step / per_ms:.0%} integration, "
            f"{t_out / per_ms:.0%} outputs. The bodies cost the same each (section 1): the "
            f"{int(np.sum(m.bodies.length >= 10.0))} pipe bodies take "
            f"{np.sum(m.bodies.length >= 10.0) / n:.0%} of it, the "
            f"{int(np.sum(m.bodies.length < 10.0))} BHA bodies the rest.", "",
            "Largest eigenvalues of the Jacobian at the initial state (RK4's stability limit is "
            "|lambda| h <= 2.8; the contact margin adds sqrt(k_w/m)):", "",
            "| eigenvalue [1/s] | modulus | where | source |", "|---|---:|---|---|", *erows, ""]


def _section_of(m: DrillstringModel, body: int) -> str:
    from drillcosim.plant.sections import string_sections

    return string_sections(m.params)[m.bodies.section[body - 1]].kind


def _eigen_source(m: DrillstringModel, body: int, block: str, comp: str) -> str:
    if body == m.n and block == "angular velocity" and comp == "z":
        b = m.params.bit
        return (f"the bit's regularized stick: dT/domega = T_max / slip_speed "
                f"(slip_speed {b.slip_speed:g} rad/s) over the bottom body's polar inertia "
                f"{m.bodies.j_polar[-1]:.1f} kg m^2")
    if comp == "z" and block in ("velocity", "position"):
        return "axial joint springs of the shortest segments (2 sqrt(k/m))"
    if comp == "z":
        return "torsional joint springs (2 sqrt(k/J_p)), overdamped near the damper cap"
    return "lateral: shear/bending joints"


def _field_run(sc, m0, T: float, H: float, sigs: list[str], method: str,
               max_step: float | None = None, rtol: float = 1e-6, atol: float = 1e-9):
    """field scene plant alone at communication step ``H`` [s] (``method``, its automatic internal
    step unless ``max_step``), sampled at 1 ms: wall [s], values, result."""
    m = DrillstringModel(sc.plant, sc.model)
    m.__dict__["max_eigenvalue"] = m0.max_eigenvalue  # computed once
    t0 = time.perf_counter()
    _, v, r = simulate(m, T, H, sigs, max_step=max_step, method=method, rtol=rtol, atol=atol)
    every = max(1, int(round(1e-3 / H)))
    return time.perf_counter() - t0, {s: v[s][::every] for s in sigs}, r


def _rhs_per_ms(m0: DrillstringModel, method: str, H: float, max_step: float | None) -> str:
    """Right-hand side evaluations per ms of a fixed-step method at communication step H."""
    if method == "dopri5":
        return "adaptive"
    spec = METHODS[method]
    dt = max_step or stable_step(m0.max_eigenvalue, spec.radius)
    return f"{spec.stages * math.ceil(H / dt - 1e-9) * 1e-3 / H:g}"


def work_precision(quick: bool) -> list[str]:
    """field_deviated_3km over its first 2 s: every signal's trajectory error of the plant's
    automatic method at H = 1 ms and 0.25 ms and of finer steps, against DOPRI5 at rtol 1e-10."""
    T = 0.5 if quick else 2.0
    sc = load_scene("field_deviated_3km")
    m0 = DrillstringModel(sc.plant, sc.model)
    h = m0.stable_step()
    smooth = ["bit_rotary_speed", "top_torque", "hook_load"]
    sigs = smooth + ["bit_axial_force", "max_radial_deflection", "wall_contact_force"]
    floor = {"bit_rotary_speed": sc.plant.top_drive.rotary_speed}  # the bit barely turns yet
    _, ref, _ = _field_run(sc, m0, T, 1e-3, sigs, "dopri5", rtol=1e-10, atol=1e-13)
    cases = [("DOPRI5 rtol 1e-11 (the reference's own error)", 1e-3, "dopri5", None, 1e-11)]
    for H in (1e-3, 2.5e-4):
        auto = m0.method_for_step(H)
        cases.append((f"H = {H * 1e3:g} ms, automatic: {auto}", H, auto, None, 0.0))
        cases += [(f"H = {H * 1e3:g} ms, {m}", H, m, None, 0.0)
                  for m in ("rk4", "kutta3", "ralston3") if m != auto]
    cases += [(f"rk4 at h*/{k}", 1e-3, "rk4", h / k, 0.0) for k in (4, 16)]
    rows = []
    for label, H, method, ms, rtol in cases:
        w, v, r = _field_run(sc, m0, T, H, sigs, method, ms, rtol or 1e-6,
                             1e-3 * rtol if rtol else 1e-9)
        err = {s: float(np.max(np.abs(v[s] - ref[s])) / max(np.max(np.abs(ref[s])),
                                                           floor.get(s, 0.0))) for s in sigs}
        worst = max(err[s] for s in smooth)
        rows.append(f"| {label} | {_rhs_per_ms(m0, method, H, ms)} | {w:.2f} | "
                    + " | ".join(f"{err[s]:.1e}" for s in sigs)
                    + f" | {'yes' if r.ok and worst <= 1e-4 else 'no'} |")
    return ["### 5. Work-precision of field_deviated_3km", "",
            f"{T:g} s from the start (the string falls from the hole axis onto the low side and "
            "winds up), plant alone at the communication step H, sampled at 1 ms; error per "
            "signal max |y - y_ref| / max |y_ref| (the bit speed against the drive's "
            f"{floor['bit_rotary_speed']:g} rad/s: it barely turns yet) against DOPRI5 at rtol "
            f"1e-10. h* = {h * 1e3:.3f} ms (RK4). The trajectory bar 1e-4 is judged on the smooth "
            f"signals ({', '.join(smooth)}); the contact signals (bit-rock, {sigs[4]}, {sigs[5]}) "
            "follow ~100 wall impacts and converge slowly with the step (h*/16: 3e-4), the "
            "reference itself only to ~5e-5: their bar is the statistics of section 6.", "",
            "| run | rhs per ms | wall [s] | " + " | ".join(sigs) + " | smooth <= 1e-4 |",
            "|---|---:|---:|" + "---:|" * len(sigs) + "---|", *rows, ""]


def automatic_method(quick: bool) -> list[str]:
    """The plant's automatic method at two communication steps against fine RK4 steps, over
    the scene: stable, and the statistics of the stick-slip and wall contact the same as the
    references' among themselves."""
    sc = load_scene("field_deviated_3km")
    T = 10.0 if quick else 40.0
    sigs = ["bit_rotary_speed", "top_torque", "hook_load", "bit_axial_force",
            "wall_contact_force"]
    m0 = DrillstringModel(sc.plant, sc.model)
    h = m0.stable_step()
    cases = [(f"automatic at H = {H * 1e3:g} ms: {m0.method_for_step(H)}", H,
              m0.method_for_step(H), None) for H in (1e-3, 2.5e-4)]
    cases += [("reference: rk4 at h*/8", 1e-3, "rk4", h / 8),
              ("second reference: rk4 at h*/4", 1e-3, "rk4", h / 4)]
    late = slice(int(round(T / 2 / 1e-3)), None)
    stats, rows = {}, []
    for label, H, method, max_step in cases:
        w, v, r = _field_run(sc, m0, T, H, sigs, method, max_step)
        stats[label] = {s: (float(v[s][late].mean()), float(v[s][late].std())) for s in sigs}
        rows.append((label, w, r))
    ref = stats[cases[2][0]]
    lines = []
    for label, wall, r in rows:
        st = stats[label]
        d_mean = max(abs(st[s][0] / ref[s][0] - 1.0) for s in sigs)
        d_std = {s: st[s][1] / ref[s][1] - 1.0 for s in sigs}
        lines.append(f"| {label} | {wall:.1f} | {T / wall:.2f} | {'yes' if r.ok else r.message} | "
                     f"{d_mean:.1e} | {d_std['bit_rotary_speed']:+.1%} | "
                     f"{d_std['top_torque']:+.1%} | {d_std['bit_axial_force']:+.1%} | "
                     f"{d_std['wall_contact_force']:+.1%} |")
    return ["### 6. The automatic method on field_deviated_3km: statistics", "",
            f"`DrillstringModel.method_for_step` at the scene's H = 1 ms and at the closed loop's "
            f"0.25 ms, plant alone over {T:g} s (stick-slip from ~15 s), sampled at 1 ms, against "
            f"RK4 at h*/8 (h* = {h * 1e3:.3f} ms), and a second reference (RK4 at h*/4) for the "
            "spread of the statistics themselves: means over the second half of "
            f"{', '.join(sigs)} (largest relative difference) and the standard deviations of "
            "the oscillating ones. The wall contact force (the sum over the bodies) is spiky: its "
            "standard deviation is set by a few impacts and differs between the two references "
            "as much as between any run and them.", "",
            "| run | wall [s] | x real time | stable | means, largest difference | std bit speed "
            "| std top torque | std bit axial force | std wall contact force |",
            "|---|---:|---:|---|---:|---:|---:|---:|---:|", *lines, ""]


def _bend_angles(m: DrillstringModel, y: np.ndarray | None = None) -> np.ndarray:
    """Bend angle [rad] of each joint: the angle between consecutive bodies' axes, of the string
    laid along the hole (``y`` None: its reference frames) or in the state ``y``."""
    if y is None:
        z = m.lay.frame[:, :, 2]
    else:
        m.outputs(0.0, y)  # leaves each body's rotation (inertial) in m.wR
        z = m.wR[:m.n, :, 2]
    return np.arccos(np.clip(np.einsum("ki,ki->k", z[:-1], z[1:]), -1.0, 1.0))


def damper_torque(quick: bool) -> list[str]:
    """What the stiffness-proportional joint dampers add to the surface torque of the rotating
    field_deviated_3km string off bottom: runs with and without them, and the formula."""
    T = 20.0 if quick else 40.0
    window = 5.0 if quick else 10.0
    omega = load_scene("field_deviated_3km").plant.top_drive.rotary_speed
    base = {"bit": {"model": "prescribed", "axial_stiffness": 0.0, "weight_on_bit": 0.0,
                    "displacement_amplitude": 0.0, "torque": 0.0},
            "top_drive": {"hoisting_speed": 0.0}}
    cases = [("the scene's dampers", {}),
             ("bending dampers off (damping.lateral_model = 'joint', lateral_ratio = 0)",
              {"damping": {"lateral_model": "joint", "lateral_reference_frequency": 1.0,
                           "lateral_ratio": 0.0}}),
             ("axial, shear and bending dampers off (damping.axial_ratio = 0)",
              {"damping": {"axial_ratio": 0.0}})]
    sigs = ["top_torque", "wall_contact_force", "bit_rotary_speed"]
    rows = []
    for label, over in cases:
        sc = load_scene("field_deviated_3km", overrides={**base, **over})
        m = DrillstringModel(sc.plant, sc.model)
        sim = PlantSimulator(m)
        idx = np.array([m.output_names.index(s) for s in sigs])
        t0 = time.perf_counter()
        rec, r = sim.run_record(1e-3, int(round(T / 1e-3)), idx)
        if not r.ok:
            raise RuntimeError(f"{label}: {r.message}")
        late = rec[-int(round(window / 1e-3)):]
        rows.append((label, late.mean(axis=0), late[:, 0].std(), time.perf_counter() - t0, m,
                     sim.y.copy()))
    ref = rows[0][1][0]
    m, y = rows[0][4], rows[0][5]
    c_be = m.p[lay.NP + lay.J_CBE: lay.NP + lay.NB * (m.n - 1): lay.NB]
    laid = float(np.sum(c_be * omega * _bend_angles(m) ** 2))
    bent = float(np.sum(c_be * omega * _bend_angles(m, y) ** 2))
    lines = [f"| {label} | {mean[0]:.0f} | {std:.0f} | {(ref - mean[0]) / ref:+.2%} | "
             f"{mean[1] / 1e3:.1f} | {mean[2]:.3f} | {wall:.0f} |"
             for label, mean, std, wall, _m, _y in rows]
    return ["### 7. Joint dampers and the rotating torque (field_deviated_3km)", "",
            f"Plant alone, bit off bottom, turning at {omega:g} rad/s (ramp 2 s), no feed, H = 1 "
            f"ms (automatic method), {T:g} s; means over the last {window:g} s (the torque has "
            "settled by ~30 s). A stiffness-proportional bending damper c_be in a joint bent by "
            "theta turning at omega dissipates c_be (omega theta)^2, a torque c_be omega theta^2 "
            f"at the surface: summed over the joints, {laid:.0f} N m ({laid / ref:.2%} of the "
            f"torque) with the bends of the string laid along the hole, {bent:.0f} N m "
            f"({bent / ref:.2%}) with the bends at the end of the run.", "",
            "| run | surface torque [N m] | its std [N m] | below the scene's | wall contact "
            "force [kN] | bit speed [rad/s] | wall [s] |",
            "|---|---:|---:|---:|---:|---:|---:|", *lines, ""]


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="fewer repetitions (a sanity check)")
    ap.add_argument("--only", default="", help="comma list of section numbers (default: all)")
    args = ap.parse_args(argv)
    sections = (section_rhs_per_body, paper_scaling, side_by_side, cost_split, work_precision,
                automatic_method, damper_torque)
    try:
        only = sorted({int(k) for k in args.only.split(",") if k.strip()}) or list(
            range(1, len(sections) + 1))
    except ValueError:
        ap.error(f"--only: {args.only!r} is not a comma list of section numbers 1-{len(sections)}")
    if not set(only) <= set(range(1, len(sections) + 1)):
        ap.error(f"--only: sections are 1-{len(sections)}, got {args.only!r}")
    t0 = time.perf_counter()
    body = [line for k in only for line in sections[k - 1](args.quick)]
    head = ["## Field-scale strings (benchmarks/bench_field.py)", "",
            f"Command: `python benchmarks/bench_field.py{' --quick' if args.quick else ''}"
            f"{' --only ' + args.only if args.only else ''}` on "
            f"{datetime.now().isoformat(timespec='seconds')}, {platform.platform()}, "
            f"{platform.processor() or platform.machine()}, load average "
            f"{Path('/proc/loadavg').read_text().split()[0] if Path('/proc/loadavg').exists() else '?'}"
            f", {time.perf_counter() - t0:.0f} s. Ratios are side by side in this run.", ""]
    print("\n".join(head + body))
    return 0


if __name__ == "__main__":
    sys.exit(main())
