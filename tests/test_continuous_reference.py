"""The continuous-time closed loop (law inside the rhs, optional pure delay) against references.

(a) the sampled co-simulation loop (PlantSimulator + controller.StrainController) converges to it
    at O(H) as the communication step H falls; (b) independent integrations by scipy (DOP853 on
    the plain rhs; method of steps with dense output for the delay) agree with it; (c) the delay
    integrator has the order its continuous extension predicts (cubic Hermite: 4, linear: 2);
    (d) the continuous linear prediction (cosim.study.continuous) agrees with its own independent
    discretization, with the limit of the sampled prediction, and with the growth and decay of
    the simulated continuous loop across the predicted boundaries.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp
from threadpoolctl import threadpool_limits

from drillcosim.analysis.closed_loop import ClosedLoopSimulator, StrainLaw
from drillcosim.controller import ControllerParams, StrainController
from drillcosim.cosim.scenario.config import load_config
from drillcosim.cosim.study.continuous import (
    ContinuousLoop,
    envelope_growth_rate,
    law_from_scene,
    operating_point_simulator,
    pade_delay,
)
from drillcosim.cosim.study.stability import LoopModel
from drillcosim.plant.model import DrillstringModel
from drillcosim.plant.scene import load_scene
from drillcosim.plant.simulator import PlantSimulator

STRAINS = ["strain1_C", "strain1_E", "strain2_C", "strain2_E"]
BAND = (150.0, 300.0)  # rad/s: the delay-driven actuator-joint modes (~188-230 rad/s)


def _model(scene: str = "paper_closed_loop", **over) -> DrillstringModel:
    sc = load_scene(scene, overrides=over or None)
    return DrillstringModel(sc.plant, sc.model)


@pytest.fixture(autouse=True)
def _one_blas_thread():
    """Dense eigenvalue problems of ~250 states: one BLAS thread is ~10x faster than several
    on the shared 2-core machine."""
    with threadpool_limits(1):
        yield


@pytest.fixture(scope="module")
def sampled_loop() -> LoopModel:
    """The discrete prediction of the scene's sampled loop (Gauss-Seidel, no loop delay)."""
    return LoopModel.from_scene("paper_closed_loop")


@pytest.fixture(scope="module")
def loop(sampled_loop) -> ContinuousLoop:
    """Its continuous limit: the same linearization without the sampling."""
    return ContinuousLoop.from_loop_model(sampled_loop)


# ------------------------------------------------------------------------------ (a) vs sampled
def _sampled(h: float, stop: float, gain: float) -> np.ndarray:
    """Gauss-Seidel, controller first (no loop delay), zero-order hold: the scene's loop."""
    m = _model()
    sim = PlantSimulator(m)
    ctrl = StrainController(ControllerParams(gain=gain))
    sidx = [m.output_names.index(n) for n in STRAINS]
    rows = [sim.outputs()[sidx].copy()]
    every = round(1e-3 / h)
    for k in range(round(stop / h)):
        sim.set_inputs(ctrl.step(k * h, h, sim.outputs()[sidx]))
        assert sim.do_step(k * h, h).ok
        if (k + 1) % every == 0:
            rows.append(sim.outputs()[sidx].copy())
    return np.array(rows)


def test_sampled_loop_converges_to_the_continuous_reference_at_first_order():
    stop, gain = 0.3, 1e9
    cl = ClosedLoopSimulator(_model(), StrainLaw(gain))
    cl = ClosedLoopSimulator(_model(), StrainLaw(gain), max_step=cl.max_step / 4)
    run = cl.run(stop, 1e-3, STRAINS)
    assert run.result.ok
    ref = np.column_stack([run.outputs[n] for n in STRAINS])
    scale = np.abs(ref).max()
    errs = [np.abs(_sampled(h, stop, gain) - ref).max() / scale for h in (2e-4, 1e-4, 5e-5)]
    ratios = np.array(errs[:-1]) / np.array(errs[1:])
    assert np.all((ratios > 1.8) & (ratios < 2.2)), (errs, ratios)  # O(H): the hold's error
    assert errs[-1] < 2e-3, errs


# ----------------------------------------------------------------------- (b) vs scipy, no delay
def _law_np(m: DrillstringModel, law: StrainLaw):
    sidx = [m.output_names.index(n) for n in STRAINS]
    u0 = np.zeros(m.n_inputs)

    def forces(t: float, y: np.ndarray) -> np.ndarray:
        eps = m.outputs(t, y, u0)[sidx]
        if t < law.switch_on_time:
            return np.zeros(4)
        return np.clip(law.gain * eps, law.lower_limit, law.upper_limit)
    return forces


PULSE = {"loads": [{"kind": "force", "body": 11, "direction": "x", "magnitude": 3000.0,
                    "start": 0.0, "duration": 0.005}]}


def test_law_inside_the_rhs_matches_scipy_dop853_with_saturation_and_switch_on():
    """A lateral pulse bends the long span; the compressive-only actuator (limit 150 N) clips
    and saturates; the law switches on at 12 ms. scipy integrates the same equations written
    with the model's plain rhs and outputs (no kernel of the closed loop involved)."""
    m = _model("paper_open_loop", **PULSE)
    law = StrainLaw(1e9, lower_limit=0.0, upper_limit=150.0, switch_on_time=0.012)
    cl = ClosedLoopSimulator(m, law, max_step=5e-5)
    run = cl.run(0.03, 1e-3, STRAINS)
    assert run.result.ok
    forces = _law_np(m, law)

    def f(t, y):
        return m.rhs(t, y, forces(t, y))

    y = m.initial_state()
    out = [m.outputs(0.0, y, np.zeros(4))[[m.output_names.index(n) for n in STRAINS]]]
    t_pts = np.arange(0, 31) * 1e-3
    sidx = [m.output_names.index(n) for n in STRAINS]
    for a, b in [(0.0, 0.005), (0.005, 0.012), (0.012, 0.03)]:
        sol = solve_ivp(f, (a, b), y, method="DOP853", rtol=1e-11, atol=1e-13, dense_output=True)
        assert sol.success
        for t in t_pts[(t_pts > a + 1e-12) & (t_pts <= b + 1e-12)]:
            yt = sol.sol(t)
            out.append(m.outputs(t, yt, forces(t, yt))[sidx])
        y = sol.y[:, -1]
    ref = np.array(out)
    got = np.column_stack([run.outputs[n] for n in STRAINS])
    assert np.abs(ref).max() > 1e-6  # the pulse bends the string
    assert np.any(run.forces[:, [0, 1]] == 150.0) and np.all(run.forces >= 0.0)  # saturated
    assert np.all(run.forces[:12] == 0.0) and np.any(run.forces[13:] != 0.0)  # switch-on
    assert np.abs(got - ref).max() / np.abs(ref).max() < 1e-6


# ------------------------------------------------------------------- (b) vs scipy, with delay
def test_delay_equation_matches_a_method_of_steps_solution():
    """Independent DDE solution: scipy DOP853 interval by interval [k tau, (k+1) tau], the
    delayed force read from the previous interval's dense output (no history kernel)."""
    tau, stop = 1e-3, 0.008
    m = _model("paper_open_loop", **PULSE)
    law = StrainLaw(3e8, delay=tau)
    run = ClosedLoopSimulator(m, law, max_step=tau / 16).run(stop, 1e-3, STRAINS)
    assert run.result.ok
    sidx = [m.output_names.index(n) for n in STRAINS]
    u0 = np.zeros(4)
    y = m.initial_state()
    prev = None
    out = [m.outputs(0.0, y, u0)[sidx]]
    for k in range(round(stop / tau)):
        a, b = k * tau, (k + 1) * tau

        def f(t, yy, prev=prev):
            if prev is None:
                return m.rhs(t, yy, u0)
            return m.rhs(t, yy, law.gain * m.outputs(t, prev(t - tau), u0)[sidx])

        pieces = [(a, min(b, 0.005)), (0.005, b)] if a < 0.005 < b else [(a, b)]
        sols = []
        for lo, hi in pieces:
            sol = solve_ivp(f, (lo, hi), y, method="DOP853", rtol=1e-11, atol=1e-13,
                            dense_output=True)
            assert sol.success
            sols.append(sol)
            y = sol.y[:, -1]
        out.append(m.outputs(b, y, u0)[sidx])

        def prev(t, sols=sols):
            for s in sols:
                if t <= s.t[-1] + 1e-15:
                    return s.sol(t)
            return sols[-1].sol(t)
    ref = np.array(out)
    got = np.column_stack([run.outputs[n] for n in STRAINS])
    assert np.any(run.forces[-1] != 0.0)
    assert np.abs(got - ref).max() / np.abs(ref).max() < 1e-7


# ----------------------------------------------------------------------------- (c) DDE order
@pytest.mark.parametrize("interpolation, order", [("hermite", 4.0), ("linear", 2.0)])
def test_delay_integrator_order_follows_its_continuous_extension(interpolation, order):
    """Global error vs the internal step (dt = tau / k): cubic Hermite keeps RK4's order 4,
    linear interpolation of the history lowers it to 2 (Bellen & Zennaro: min(p, q + 1))."""
    tau, stop = 2e-4, 0.05

    def run(dt: float, interp: str) -> np.ndarray:
        cl = ClosedLoopSimulator(_model(), StrainLaw(1e9, delay=tau), max_step=dt,
                                 interpolation=interp)
        r = cl.run(stop, 1e-3, STRAINS)
        assert r.result.ok
        return np.column_stack([r.outputs[n] for n in STRAINS])

    ref = run(tau / 64, "hermite")
    errs = [np.abs(run(tau / k, interpolation) - ref).max() / np.abs(ref).max()
            for k in (1, 2, 4)]
    slopes = np.log2(np.array(errs[:-1]) / np.array(errs[1:]))
    assert np.all(np.abs(slopes - order) < 0.35), (errs, slopes)


# --------------------------------------------------------------------- (d) linear prediction
def test_pade_roots_refined_on_the_exact_equation_match_chebyshev_collocation(loop):
    for tau in (3e-4,):
        pade = loop.roots(1e9, tau, count=3)
        cheb = loop.chebyshev_roots(1e9, tau, nodes=4, count=6)
        cheb = np.concatenate([cheb, cheb.conj()])  # a truncated list may hold one of a pair
        for r in pade:
            assert np.min(np.abs(cheb - r)) < 1e-6 * abs(r), (pade, cheb)
    # the refined roots do not depend on the Pade order that seeded them
    a, b = loop.roots(1e9, 3e-4, count=2, order=2), loop.roots(1e9, 3e-4, count=2, order=8)
    assert np.allclose(np.sort_complex(a), np.sort_complex(b), rtol=1e-10)


def test_pade_realization_is_the_pade_approximant():
    a, b, c, d = pade_delay(4, 1e-3)
    for w in (10.0, 300.0, 1000.0):
        s = 1j * w
        G = (c @ np.linalg.solve(s * np.eye(4) - a, b) + d)[0, 0]
        assert abs(G) == pytest.approx(1.0, abs=1e-12)  # all-pass
        assert G == pytest.approx(np.exp(-s * 1e-3), abs=1e-9 if w < 400 else 1e-6)


def test_no_delay_the_loop_is_stable_for_every_gain_and_the_sampled_boundary_moves_away(
        loop, sampled_loop):
    """Collocated P feedback on a joint's bending angle is a joint spring: no finite critical
    gain in continuous time. The sampled loop's critical gain grows like 1/H (K_c H ~ const)."""
    assert loop.critical_gain(0.0, gain_min=1e6, gain_max=1e13, per_decade=1) == math.inf
    kh = [sampled_loop.critical_gain(h, 0.0, gain_min=1e8, gain_max=1e11, per_decade=2,
                                     rtol=0.01) * h for h in (2.5e-4, 1e-4)]
    assert kh[1] == pytest.approx(kh[0], rel=0.1)


def test_sampled_critical_delay_plus_half_a_step_tends_to_the_continuous_one(loop, sampled_loop):
    """The hold adds ~H/2 of delay: tau_c(H) + H/2 -> tau_c(continuous) as H -> 0."""
    tc = loop.critical_delay(1e9, delay_max=3e-4, points=3, atol=1e-8)
    assert 1.9e-4 < tc < 2.1e-4
    gaps = []
    for h in (2.5e-4, 1e-4, 5e-5):
        td = sampled_loop.critical_delay(1e9, h, delay_max=3e-4, per_step=1, atol=h * 1e-3)
        gaps.append(abs(td + h / 2 - tc))
        assert td < tc
    # measured: the gap is < 0.1 us at every H (the hold's phase lag is exactly H/2 and its
    # gain sinc(w H / 2) ~ 1 for the 228 rad/s mode)
    assert max(gaps) < 0.005 * tc, gaps


def _growth(gain: float, tau: float, stop: float = 4.0) -> float:
    sim = operating_point_simulator("paper_closed_loop", gain, tau)
    run = sim.run(stop, 2.5e-4, ["strain1_C"])
    assert run.result.ok, run.result.message
    return envelope_growth_rate(run.time, run.outputs["strain1_C"], BAND, t_start=0.5)


def _predicted_in_band(loop: ContinuousLoop, gain: float, tau: float) -> float:
    """Real part [1/s] of the rightmost root whose frequency lies in BAND (seeded at 228 rad/s
    and refined when the Pade eigenvalues near the axis hold none there)."""
    ev = loop.roots(gain, tau, count=40)
    inb = ev[(np.abs(ev.imag) > BAND[0]) & (np.abs(ev.imag) < BAND[1])]
    if inb.size:
        return float(inb.real.max())
    return float(loop.refine(-1.0 + 228j, gain, tau).real)


def test_simulated_growth_flips_sign_across_the_predicted_critical_delay(loop):
    """K = 1e9: continuous critical delay ~198 us. Below it the actuator-joint modes decay, above
    they grow, at the predicted rates (within 15 %)."""
    for tau in (1.5e-4, 2.5e-4):
        pred = _predicted_in_band(loop, 1e9, tau)
        got = _growth(1e9, tau)
        assert np.sign(got) == np.sign(pred), (tau, pred, got)
        assert got == pytest.approx(pred, rel=0.15), (tau, pred, got)


def test_simulated_growth_flips_sign_across_the_predicted_critical_gain(loop):
    """With 0.5 ms of delay the critical gain is finite: 0.7 K_c decays, 1.4 K_c grows."""
    tau = 5e-4
    kc = loop.critical_gain(tau, gain_min=1e7, gain_max=1e11, per_decade=2, rtol=1e-3)
    assert 1e8 < kc < 1e9
    for k, sign in ((0.7 * kc, -1.0), (1.4 * kc, 1.0)):
        pred = _predicted_in_band(loop, k, tau)
        got = _growth(k, tau)
        assert np.sign(pred) == sign and np.sign(got) == sign, (k, pred, got)
        assert got == pytest.approx(pred, rel=0.25, abs=0.1), (k, pred, got)


def test_sampling_alone_destabilizes_what_the_continuous_loop_keeps_stable(loop, sampled_loop):
    """K = 3e9, no delay (2x the sampled critical gain at H = 0.25 ms). From the same perturbed
    operating point the continuous loop decays and the sampled loop (PlantSimulator +
    StrainController, zero-order hold) grows, each at its own prediction's rate in the band of
    the sampling-driven mode (~330 rad/s)."""
    K, h, band = 3e9, 2.5e-4, (250.0, 420.0)
    ev = loop.roots(K, 0.0, count=loop.A.shape[0])
    cont_pred = float(ev[(np.abs(ev.imag) > band[0]) & (np.abs(ev.imag) < band[1])].real.max())
    samp_pred = sampled_loop.growth_rate(K, 0.0, h)
    assert cont_pred < 0.0 < samp_pred
    sim = operating_point_simulator("paper_closed_loop", K, 0.0)
    y0, m = sim.y.copy(), sim.model
    run = sim.run(3.0, h, ["strain1_C"])
    assert run.result.ok
    got = envelope_growth_rate(run.time, run.outputs["strain1_C"], band, t_start=0.5)
    assert got == pytest.approx(cont_pred, rel=0.15), (cont_pred, got)
    ps = PlantSimulator(m)
    ps.y[:] = y0
    ctrl = StrainController(ControllerParams(gain=K))
    sidx = [m.output_names.index(n) for n in STRAINS]
    rec = [ps.outputs()[sidx[0]]]
    for k in range(round(3.0 / h)):
        ps.set_inputs(ctrl.step(k * h, h, ps.outputs()[sidx]))
        assert ps.do_step(k * h, h).ok
        rec.append(ps.outputs()[sidx[0]])
    got = envelope_growth_rate(np.arange(len(rec)) * h, np.array(rec), band, t_start=0.5)
    assert got == pytest.approx(samp_pred, rel=0.15), (samp_pred, got)


def test_law_from_scene_uses_the_controller_table():
    law = law_from_scene(load_config("paper_restricted_actuator"), delay=1e-4)
    assert (law.gain, law.lower_limit, law.upper_limit, law.delay) == (1e9, 0.0, 5000.0, 1e-4)


@pytest.mark.parametrize("kw, msg", [
    ({"gain": -1.0}, "law.gain = -1.0 is out of range"),
    ({"gain": 1.0, "delay": math.nan}, "law.delay = nan is not allowed"),
    ({"gain": 1.0, "upper_limit": -5.0}, "law.upper_limit = -5.0 is out of range"),
    ({"gain": 1.0, "lag_time_constant": -1e-3}, "law.lag_time_constant = -0.001 is out of range"),
])
def test_bad_law_parameters_are_refused_in_one_line(kw, msg):
    with pytest.raises(ValueError) as exc:
        StrainLaw(**kw)
    assert msg in str(exc.value) and "\n" not in str(exc.value)


def test_lag_in_the_loop_matches_the_linear_prediction(loop):
    """A 0.2 ms actuator lag (no delay) behaves like ~0.2 ms of delay for the fast modes: the
    lagged loop's predicted growth is reproduced by the simulated lag state."""
    lagged = ContinuousLoop(loop.A, loop.B, loop.C, lag_time_constant=4e-4, dropped=loop.dropped)
    pred = lagged.roots(1e9, 0.0, count=60)
    pred = pred[(np.abs(pred.imag) > BAND[0]) & (np.abs(pred.imag) < BAND[1])]
    sc = load_config("paper_closed_loop", {"controller.lag_time_constant": 4e-4})
    sim = operating_point_simulator(sc, 1e9, 0.0)
    assert sim.law.lag_time_constant == 4e-4
    run = sim.run(4.0, 2.5e-4, ["strain1_C"])
    assert run.result.ok
    got = envelope_growth_rate(run.time, run.outputs["strain1_C"], BAND, t_start=0.5)
    assert pred.size and got == pytest.approx(float(pred.real.max()), rel=0.2, abs=0.1)
