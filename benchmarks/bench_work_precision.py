"""Work-precision of the plant integrators on the same right-hand side.

Candidates (all on the physics of ``plant.kernels``):

* ``rk4``: fixed-step RK4 through :class:`plant.simulator.PlantSimulator` (the default), at the
  automatic stable step and at 1/2, 1/4 of it;
* ``verlet``: velocity Verlet on the second-order structure (1 rhs a step);
* ``dopri5``: the numba adaptive Dormand-Prince 5(4), stepping to each 1 ms output;
* ``expeuler`` / ``etd2``: exponential integrators (axial-torsional model only);
* ``scipy-BDF`` / ``scipy-Radau`` with ``jac_sparsity`` from the kernel's body-neighbour structure,
  ``scipy-LSODA`` (dense finite-difference Jacobian when stiff), all on the numba rhs;
* ``naive``: scipy ``solve_ivp`` RK45 on the vectorised numpy rhs (``tests/support/numpy_rhs.py``), the
  baseline a user would write.

Reference: the compiled DOPRI5 at rtol 1e-11, checked against rtol 1e-10 (difference reported).
Errors: max over the signals of max|y - y_ref| / max|y_ref| over the first ``T`` seconds, sampled
every 1 ms. Wall times are best-of-k with the candidates interleaved (the machine is shared).

Run: ``.venv/bin/python benchmarks/run_all.py [--quick]`` (or ``drillcosim bench``).
"""

from __future__ import annotations

import math
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from scipy.integrate import solve_ivp

from drillcosim.plant.model import DrillstringModel
from drillcosim.plant.scene import load_scene
from drillcosim.plant.simulator import simulate

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
from support.numpy_rhs import NumpyRhs  # noqa: E402  (the test oracle: tests/support)

DT_OUT = 1e-3  # s, output interval of every run

SIGNALS = {
    "full3d": ("strain1_C", "body11_radial_deflection", "body26_radial_deflection"),
    "axial_torsional": ("bit_axial_displacement", "bit_axial_force", "hook_load"),
}


@dataclass
class Run:
    """One timed run: label, family, wall time [s], sampled outputs, success."""

    label: str
    family: str
    wall: float
    t: np.ndarray
    values: dict[str, np.ndarray]
    ok: bool
    nfev: int = 0
    info: dict = field(default_factory=dict)


def scene_model(name: str, n: int | None = None, overrides: dict | None = None) -> DrillstringModel:
    """A scene's model (optionally with ``n`` segments)."""
    ov = dict(overrides or {})
    if n is not None:
        ov.setdefault("pipe", {})["n_segments"] = n
        ov["outputs"] = []
        ov["contact"] = {"bodies": []}  # the span middles of this n
    sc = load_scene(name, overrides=ov or None)
    return DrillstringModel(sc.plant, sc.model)


def body_sparsity(model: DrillstringModel):
    """Jacobian sparsity of the kernel: state i and j interact iff their bodies are neighbours.

    Every block of the state (positions, angles, velocities, spin rates; 3 n or n entries each)
    is ordered by body; joints couple bodies k and k+1 only, the boundary springs, stabilizers,
    contact and unbalance act on one body.
    """
    from scipy.sparse import csr_matrix

    n = model.n
    per = 3 if model.kind == "full3d" else 1
    body = (np.arange(model.n_state) % (per * n)) // per
    S = np.abs(body[:, None] - body[None, :]) <= 1
    return csr_matrix(S.astype(np.int8))


def run_plant(model: DrillstringModel, T: float, method: str = "rk4",
              max_step: float | None = None, rtol: float = 1e-6, atol: float = 1e-9,
              label: str | None = None, names: list[str] | None = None) -> Run:
    """Run through ``PlantSimulator`` (what the FMU does) with 1 ms outputs; timed."""
    names = names or list(SIGNALS[model.kind])
    t0 = time.perf_counter()
    t, vals, res = simulate(model, T, DT_OUT, names, max_step=max_step, method=method, rtol=rtol,
                            atol=atol)
    wall = time.perf_counter() - t0
    ok = res.ok
    return Run(label or method, method, wall, t, vals, ok)


def run_scipy(model: DrillstringModel, T: float, method: str, rtol: float, atol: float,
              rhs: str = "numba", label: str | None = None, family: str | None = None) -> Run:
    """``solve_ivp`` on the numba (``model.rhs``) or numpy rhs; outputs computed from t_eval."""
    names = list(SIGNALS[model.kind])
    idx = [model.output_names.index(k) for k in names]
    t_eval = np.arange(int(round(T / DT_OUT)) + 1) * DT_OUT
    calls = [0]
    if rhs == "numpy":
        f: Callable = NumpyRhs(model)
    else:
        def f(t, y):
            calls[0] += 1
            return model.rhs(t, y)
    kw = {}
    if method in ("BDF", "Radau"):
        kw["jac_sparsity"] = body_sparsity(model)
    t0 = time.perf_counter()
    sol = solve_ivp(f, (0.0, t_eval[-1]), model.initial_state(), method=method, t_eval=t_eval,
                    rtol=rtol, atol=atol, **kw)
    rows = np.array([model.outputs(t, sol.y[:, i])[idx] for i, t in enumerate(sol.t)])
    wall = time.perf_counter() - t0
    return Run(label or f"scipy-{method}", family or f"scipy-{method}", wall, sol.t,
               {k: rows[:, i] for i, k in enumerate(names)}, bool(sol.success), sol.nfev)


def traj_error(run: Run, ref: Run, T: float | None = None) -> float:
    """max over signals of max|y - y_ref| / max|y_ref| over [0, T] (inf if the run failed)."""
    k = len(ref.t) if T is None else int(round(T / DT_OUT)) + 1
    if not run.ok or len(run.t) < k:
        return math.inf
    err = 0.0
    for name, yr in ref.values.items():
        y = run.values[name][:k]
        scale = np.abs(yr[:k]).max()
        if scale == 0.0:
            continue
        e = np.abs(y - yr[:k]).max() / scale
        err = max(err, float(e) if np.isfinite(e) else math.inf)
    return err


def stats_error(run: Run, ref: Run, names: tuple[str, ...]) -> dict[str, float]:
    """Relative errors of RMS and peak of the given signals (whole run)."""
    out = {}
    for nm in names:
        y, yr = run.values[nm], ref.values[nm]
        if len(y) != len(yr):
            out[f"rms {nm}"] = out[f"peak {nm}"] = math.inf
            continue
        rr = math.sqrt(float(np.mean(yr**2)))
        out[f"rms {nm}"] = abs(math.sqrt(float(np.mean(y**2))) - rr) / rr
        pr = float(np.abs(yr).max())
        out[f"peak {nm}"] = abs(float(np.abs(y).max()) - pr) / pr
    return out


def reference(model: DrillstringModel, T: float) -> tuple[Run, float]:
    """Numba DOPRI5 at rtol 1e-11 and its self-check against rtol 1e-10 (returns the difference).

    scipy's DOP853 at rtol 1e-10 needs ~6e5 rhs calls a simulated second here (its Python
    per-step overhead makes it ~20x slower than the compiled DOPRI5), Radau at 1e-10 more than
    3 min for 0.2 s: the compiled tight solve is the practical reference; the test suite checks
    DOPRI5 against scipy's DOP853 on short horizons.
    """
    r10 = run_plant(model, T, "dopri5", rtol=1e-10, atol=1e-13, label="ref DOPRI5 rtol 1e-10")
    r11 = run_plant(model, T, "dopri5", rtol=1e-11, atol=1e-14, label="ref DOPRI5 rtol 1e-11")
    r10.family = r11.family = "ref"
    return r11, traj_error(r10, r11)


def timed_best(factories: list[tuple[str, Callable[[], Run]]], repeat: int) -> list[Run]:
    """Run each factory ``repeat`` times, interleaved; keep the best wall time of each."""
    best: dict[str, Run] = {}
    for _ in range(repeat):
        for key, fac in factories:
            r = fac()
            if key not in best or r.wall < best[key].wall:
                best[key] = r
    return [best[k] for k, _ in factories]


def _setup(scene: str, T: float):
    """Model, horizon [s], automatic step h* [s], reference run, its check and wall time [s]."""
    m = scene_model(scene)
    t0 = time.perf_counter()
    ref, ref_check = reference(m, T)
    return m, T, m.stable_step(), ref, ref_check, time.perf_counter() - t0


def work_precision_3d(quick: bool) -> dict:
    """paper_open_loop (full 3D, n = 30): all candidates over the first T seconds."""
    m, T, h0, ref, ref_check, ref_wall = _setup("paper_open_loop", 0.5 if quick else 2.0)
    cands: list[tuple[str, Callable[[], Run]]] = [
        ("rk4 h*", lambda: run_plant(m, T, "rk4", label="rk4 (auto step h*)")),
        ("rk4 h*/2", lambda: run_plant(m, T, "rk4", h0 / 2, label="rk4 h*/2")),
        ("rk4 h*/4", lambda: run_plant(m, T, "rk4", h0 / 4, label="rk4 h*/4")),
        ("verlet", lambda: run_plant(m, T, "verlet", label="verlet (auto step)")),
        ("verlet h*/10", lambda: run_plant(m, T, "verlet", h0 * 0.1, label="verlet h*/10")),
    ]
    for rt in ((1e-5, 1e-8) if quick else (1e-4, 1e-6, 1e-8, 1e-10)):
        cands.append((f"dopri5 {rt:g}",
                      lambda rt=rt: run_plant(m, T, "dopri5", rtol=rt, atol=rt * 1e-3,
                                              label=f"dopri5 rtol {rt:g}")))
    repeat = 2 if quick else 3
    runs = timed_best(cands, repeat)
    slow: list[tuple[str, Callable[[], Run]]] = []
    for meth in (("BDF",) if quick else ("BDF", "Radau", "LSODA")):
        for rt in ((1e-6,) if quick else (1e-4, 1e-7)):
            slow.append((f"{meth} {rt:g}",
                         lambda meth=meth, rt=rt: run_scipy(m, T, meth, rt, rt * 1e-3,
                                                            label=f"scipy {meth} rtol {rt:g}")))
    for rt in ((1e-4, 1e-6) if quick else (1e-3, 1e-5, 1e-7, 1e-9)):
        slow.append((f"naive {rt:g}",
                     lambda rt=rt: run_scipy(m, T, "RK45", rt, rt * 1e-3, rhs="numpy",
                                             label=f"naive RK45+numpy rtol {rt:g}",
                                             family="naive")))
    runs += timed_best(slow, 1)
    # numba vs numpy rhs per call, side by side
    y = m.initial_state()
    f_np = NumpyRhs(m)
    per = {"numba": math.inf, "numpy": math.inf}
    for _ in range(3):
        for key, fn, k in (("numba", m.rhs, 2000), ("numpy", f_np, 200)):
            t1 = time.perf_counter()
            for _i in range(k):
                fn(0.5, y)
            per[key] = min(per[key], (time.perf_counter() - t1) / k)
    return {"scene": "paper_open_loop", "model": m, "T": T, "ref": ref, "ref_check": ref_check,
            "ref_wall": ref_wall, "runs": runs, "errors": [traj_error(r, ref) for r in runs],
            "rhs_call": per, "h_star": h0}


def work_precision_at(quick: bool) -> dict:
    """table1_axial_pulse (axial-torsional, n = 30): RK4, Verlet, DOPRI5, exponential."""
    m, T, h0, ref, ref_check, ref_wall = _setup("table1_axial_pulse", 2.0 if quick else 3.0)
    cands: list[tuple[str, Callable[[], Run]]] = [
        ("rk4 h*", lambda: run_plant(m, T, "rk4", label="rk4 (auto step h*)")),
        ("rk4 h*/4", lambda: run_plant(m, T, "rk4", h0 / 4, label="rk4 h*/4")),
        ("verlet", lambda: run_plant(m, T, "verlet", label="verlet (auto step)")),
        ("expeuler", lambda: run_plant(m, T, "expeuler", label="expeuler h = 1 ms")),
        ("expeuler/4", lambda: run_plant(m, T, "expeuler", DT_OUT / 4,
                                         label="expeuler h = 0.25 ms")),
        ("etd2", lambda: run_plant(m, T, "etd2", label="etd2 h = 1 ms")),
        ("etd2/4", lambda: run_plant(m, T, "etd2", DT_OUT / 4, label="etd2 h = 0.25 ms")),
    ]
    for rt in ((1e-6,) if quick else (1e-4, 1e-6, 1e-8)):
        cands.append((f"dopri5 {rt:g}",
                      lambda rt=rt: run_plant(m, T, "dopri5", rtol=rt, atol=rt * 1e-3,
                                              label=f"dopri5 rtol {rt:g}")))
    runs = timed_best(cands, 3 if quick else 5)
    slow = [(f"BDF {rt:g}", lambda rt=rt: run_scipy(m, T, "BDF", rt, rt * 1e-3,
                                                   label=f"scipy BDF rtol {rt:g}"))
            for rt in ((1e-6,) if quick else (1e-4, 1e-7))]
    runs += timed_best(slow, 1)
    # kernel only: the whole run in one advance call (no per-ms Python), RK4 vs exponential Euler
    kern = {}
    for _ in range(3):
        for meth, dt in (("rk4", None), ("expeuler", DT_OUT)):
            y = m.initial_state()
            h = h0 if dt is None else dt
            nst = int(math.ceil(T / h))
            m.advance(0.0, y.copy(), 2, T / nst, method=meth)  # compile / matrices
            t1 = time.perf_counter()
            m.advance(0.0, y, nst, T / nst, method=meth)
            kern[meth] = min(kern.get(meth, math.inf), time.perf_counter() - t1)
    default = {"expeuler": "expeuler h = 1 ms", "rk4": "rk4 (auto step h*)"}[m.default_method]
    return {"scene": "table1_axial_pulse", "model": m, "T": T, "ref": ref, "default_label": default,
            "ref_check": ref_check, "ref_wall": ref_wall, "runs": runs,
            "errors": [traj_error(r, ref) for r in runs], "kernel_wall": kern, "h_star": h0}


def long_run_stats(quick: bool) -> dict:
    """RMS and peak of the radial deflections over a long paper_open_loop run (contact active).

    Reference: RK4 at h*/8 checked against DOPRI5 at rtol 1e-10 (independent methods).
    """
    m = scene_model("paper_open_loop")
    T = 5.0 if quick else 30.0
    names = ("body11_radial_deflection", "body26_radial_deflection")
    ref = run_plant(m, T, "rk4", m.stable_step() / 8, label="ref rk4 h*/8")
    rt = 1e-9 if quick else 1e-10
    ref2 = run_plant(m, T, "dopri5", rtol=rt, atol=rt * 1e-3, label=f"ref dopri5 {rt:g}")
    cands = [("rk4", lambda: run_plant(m, T, "rk4", label="rk4 (auto step h*)")),
             ("dopri5", lambda: run_plant(m, T, "dopri5", rtol=1e-6, atol=1e-9,
                                          label="dopri5 rtol 1e-6")),
             ("verlet", lambda: run_plant(m, T, "verlet", label="verlet (auto step)"))]
    runs = timed_best(cands, 1 if quick else 2)
    clear = m.params.contact.clearance
    return {"T": T, "ref": ref, "ref_check": stats_error(ref2, ref, names), "runs": runs,
            "stats": [stats_error(r, ref, names) for r in runs],
            "traj2": [traj_error(r, ref, 2.0) for r in runs], "names": names,
            "rms_ref": {nm: math.sqrt(float(np.mean(ref.values[nm] ** 2))) for nm in names},
            "peak_ref": {nm: float(np.abs(ref.values[nm]).max()) for nm in names},
            "contact_seen": any(float(np.abs(ref.values[nm]).max()) > clear for nm in names)}
