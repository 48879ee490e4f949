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
5. Work-precision of field_deviated_3km over 2 s against RK4 at h*/8.
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
from drillcosim.plant.integrators import advance_rk4  # noqa: E402
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
from drillcosim.plant.simulator import simulate  # noqa: E402

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
        bit=BitParams(axial_stiffness=0.0), unbalance=UnbalanceParams(enabled=False),
        top_drive=TopDriveParams(rotary_speed=4.0), gravity=9.81)


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
            f"{rep}, the cases interleaved in one run. Target (issue 25): at most (bodies / 30) x "
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


def work_precision(quick: bool) -> list[str]:
    T = 0.5 if quick else 2.0
    sc = load_scene("field_deviated_3km")
    sigs = ["bit_rotary_speed", "top_torque", "hook_load", "bit_axial_force"]
    m0 = DrillstringModel(sc.plant, sc.model)
    h = m0.stable_step()

    def run(method, max_step=None, rtol=1e-6):
        m = DrillstringModel(sc.plant, sc.model)
        m.__dict__["max_eigenvalue"] = m0.max_eigenvalue
        t0 = time.perf_counter()
        _, v, r = simulate(m, T, 1e-3, sigs, max_step=max_step, method=method, rtol=rtol)
        return time.perf_counter() - t0, v, r

    _, ref, _ = run("rk4", h / 8)
    floor = {"bit_rotary_speed": sc.plant.top_drive.rotary_speed}  # the bit barely turns yet
    rows = []
    for label, method, ms, rtol in (("rk4 h*", "rk4", None, 1e-6),
                                    ("rk4 h*/2", "rk4", h / 2, 1e-6),
                                    ("dopri5 rtol 1e-6", "dopri5", None, 1e-6),
                                    ("dopri5 rtol 1e-8", "dopri5", None, 1e-8)):
        w, v, r = run(method, ms, rtol)
        err = max(np.max(np.abs(v[s] - ref[s])) / max(np.max(np.abs(ref[s])), floor.get(s, 0.0))
                  for s in sigs)
        rows.append(f"| {label} | {w:.2f} | {T / w:.1f} | {err:.2e} | {r.ok} |")
    return ["### 5. Work-precision of field_deviated_3km", "",
            f"{T:g} s from the start (the string falls onto the wall and winds up), error = max "
            f"over {', '.join(sigs)} of max |y - y_ref| / max |y_ref| at 1 ms (the bit speed "
            f"against the drive's {floor['bit_rotary_speed']:g} rad/s); reference RK4 at h*/8 "
            f"(h* = {h * 1e3:.3f} ms). The impacts of 100 bodies on the wall make the bit axial "
            "force converge slowly (~2e-3 between h*/8 and h*/16).", "",
            "| integrator | wall [s] | x real time | rel. error | ok |", "|---|---:|---:|---:|---|",
            *rows, ""]


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="fewer repetitions (a sanity check)")
    args = ap.parse_args(argv)
    t0 = time.perf_counter()
    body = (section_rhs_per_body(args.quick) + paper_scaling(args.quick)
            + side_by_side(args.quick) + cost_split(args.quick) + work_precision(args.quick))
    head = ["## Field-scale strings (benchmarks/bench_field.py)", "",
            f"Command: `python benchmarks/bench_field.py{' --quick' if args.quick else ''}` on "
            f"{datetime.now().isoformat(timespec='seconds')}, {platform.platform()}, "
            f"{platform.processor() or platform.machine()}, load average "
            f"{Path('/proc/loadavg').read_text().split()[0] if Path('/proc/loadavg').exists() else '?'}"
            f", {time.perf_counter() - t0:.0f} s. Ratios are side by side in this run.", ""]
    print("\n".join(head + body))
    return 0


if __name__ == "__main__":
    sys.exit(main())
