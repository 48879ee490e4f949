"""Master vs theory: delayed-loop stability, coupling order, transport delays."""

from __future__ import annotations

import gc
import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from drillcosim.cosim.master.master import Master
from drillcosim.cosim.master.system import Connection, FmuSpec, SystemSpec
from support.required import import_module

H_LOOP = 0.01


def levin_may_bound(m: int) -> float:
    """x_{k+1} = x_k - a x_{k-m} is stable iff a < 2 cos(m pi / (2m + 1))."""
    return 2.0 * math.cos(m * math.pi / (2 * m + 1))


def loop_system(fmus, kh: float, algorithm: str, delay_steps: int) -> SystemSpec:
    """Integrator plant x' = u and P controller u = -K x, delay on ctrl -> plant."""
    return SystemSpec(
        [FmuSpec("plant", fmus["mt_integrator"], {"x0": 1.0}),
         FmuSpec("ctrl", fmus["mt_gain"], {"k": kh / H_LOOP})],
        [Connection("plant.x", "ctrl.u"),
         Connection("ctrl.y", "plant.u", delay=delay_steps * H_LOOP)],
        H_LOOP, algorithm, ("plant", "ctrl"))


# Loop delay m in steps: Gauss-Seidel uses the controller output computed from
# x_k for the plant step k -> k+1 (m = delay steps); Jacobi exchanges outputs
# sampled at t_k, and the controller output at t_k was computed from the input
# set at t_{k-1}, i.e. x_{k-1}: one step more (m = delay steps + 1).
CASES = [("gauss_seidel", m, m) for m in range(5)] + [("jacobi", m, m - 1) for m in range(1, 5)]


@pytest.mark.parametrize("side", [0.97, 1.03])
@pytest.mark.parametrize("algorithm,m,delay_steps", CASES)
def test_levin_may_stability_bound(fmus, algorithm, m, delay_steps, side):
    kh = side * levin_may_bound(m)
    res = Master(loop_system(fmus, kh, algorithm, delay_steps)).simulate(
        20.0, outputs=["plant.x"])
    x = np.abs(res.data["plant.x"])
    assert len(x) == 2001 and res.diverged is None
    tail = x[-200:].max()
    if side < 1:
        assert tail < 0.05, f"m={m}: should decay at K*H = {kh:.4f}, |x| = {tail:.3g}"
    else:
        assert tail > 20.0, f"m={m}: should grow at K*H = {kh:.4f}, |x| = {tail:.3g}"


def test_gauss_seidel_loop_is_exact_geometric_sequence(fmus):
    """m = 0: x_k = (1 - K H)^k, to rounding."""
    kh = 0.3
    res = Master(loop_system(fmus, kh, "gauss_seidel", 0)).simulate(1.0, outputs=["plant.x"])
    k = np.arange(len(res.data))
    np.testing.assert_allclose(res.data["plant.x"], (1 - kh) ** k, rtol=1e-12)


def test_jacobi_loop_matches_delayed_recursion(fmus):
    """Jacobi, delay 2 steps: x_{k+1} = x_k - a x_{k-3}, x constant before the start."""
    a = 0.2
    res = Master(loop_system(fmus, a, "jacobi", 2)).simulate(1.0, outputs=["plant.x"])
    x = [1.0]
    for k in range(100):
        x.append(x[k] - a * x[max(k - 3, 0)])
    np.testing.assert_allclose(res.data["plant.x"], x, rtol=1e-12)


# --- coupling order --------------------------------------------------------------
M1, K1, M2, K2, KC = 1.0, 1.0, 2.0, 0.5, 2.0
T_OSC = 4.0


def oscillator(fmus, h: float, coupling: str, algorithm: str) -> SystemSpec:
    return SystemSpec(
        [FmuSpec("a", fmus["mt_mass"], {"m": M1, "k": K1, "kc": KC, "x0": 1.0}),
         FmuSpec("b", fmus["mt_mass"], {"m": M2, "k": K2, "kc": KC, "x0": 0.0})],
        [Connection("a.x", "b.x_other", coupling=coupling),
         Connection("b.x", "a.x_other", coupling=coupling)],
        h, algorithm)


@pytest.fixture(scope="module")
def reference():
    def rhs(t, s):
        x1, v1, x2, v2 = s
        return [v1, (-K1 * x1 - KC * (x1 - x2)) / M1, v2, (-K2 * x2 - KC * (x2 - x1)) / M2]

    return solve_ivp(rhs, (0, T_OSC), [1.0, 0.0, 0.0, 0.0], method="DOP853", rtol=1e-12,
                     atol=1e-13, dense_output=True).sol


STEPS = [0.04, 0.02, 0.01, 0.005]


@pytest.mark.parametrize("algorithm", ["jacobi", "gauss_seidel"])
@pytest.mark.parametrize("coupling,order", [("zoh", 1.0), ("linear", 2.0)])
def test_coupling_error_order(fmus, reference, algorithm, coupling, order):
    errors = []
    for h in STEPS:
        res = Master(oscillator(fmus, h, coupling, algorithm)).simulate(
            T_OSC, outputs=["a.x", "b.x"])
        ref = reference(res.data["time"])
        err = max(np.abs(res.data["a.x"] - ref[0]).max(), np.abs(res.data["b.x"] - ref[2]).max())
        errors.append(err)
    slope = np.polyfit(np.log(STEPS), np.log(errors), 1)[0]
    print(f"{algorithm} {coupling}: errors {errors}, slope {slope:.3f}")
    assert abs(slope - order) < 0.15, f"slope {slope:.3f}, expected {order}"


# --- transport delays -------------------------------------------------------------
H_D = 0.01
OMEGA = 3.0


def delay_system(fmus, delay: float, algorithm: str) -> SystemSpec:
    """Sine source -> echo probe (gain k = -1) through a delayed connection."""
    return SystemSpec(
        [FmuSpec("src", fmus["mt_source"], {"omega": OMEGA}),
         FmuSpec("probe", fmus["mt_gain"], {"k": -1.0})],
        [Connection("src.y", "probe.u", delay=delay)], H_D, algorithm, ("src", "probe"))


@pytest.mark.parametrize("algorithm,lag", [("gauss_seidel", 0), ("jacobi", 1)])
@pytest.mark.parametrize("m", [0, 1, 3, 7])
def test_integer_delay_is_exact_shift(fmus, algorithm, lag, m):
    """probe(t_k) = src(t_{k - m - lag}), bit for bit (lag: Jacobi's extra step)."""
    res = Master(delay_system(fmus, m * H_D, algorithm)).simulate(1.0, outputs=["src.y",
                                                                                 "probe.y"])
    src, probe = res.data["src.y"], res.data["probe.y"]
    shift = m + lag
    assert np.array_equal(probe[shift:], src[: len(src) - shift])
    assert np.all(probe[:shift] == src[0])
    np.testing.assert_allclose(src, np.sin(OMEGA * res.data["time"]), atol=1e-14)


@pytest.mark.parametrize("frac_delay", [0.25, 2.6])
def test_fractional_delay_interpolates_linearly(fmus, frac_delay):
    """d = (n + f) H: probe(t) = (1 - f) s(t - n H) + f s(t - (n + 1) H) (Gauss-Seidel)."""
    res = Master(delay_system(fmus, frac_delay * H_D, "gauss_seidel")).simulate(
        1.0, outputs=["probe.y"])
    t = res.data["time"]
    n, f = int(frac_delay), frac_delay - int(frac_delay)
    s = lambda tt: np.sin(OMEGA * np.maximum(tt, 0.0))  # noqa: E731 - held before start
    expected = (1 - f) * s(t - n * H_D) + f * s(t - (n + 1) * H_D)
    np.testing.assert_allclose(res.data["probe.y"], expected, atol=1e-12)
    # and it is not the exact delayed sine: the interpolation error is visible,
    # bounded by f (1 - f) H^2 max|s''| / 2
    late = t > (n + 1) * H_D
    exact = np.sin(OMEGA * (t[late] - frac_delay * H_D))
    dev = np.abs(res.data["probe.y"][late] - exact).max()
    bound = f * (1 - f) * H_D**2 * OMEGA**2 / 2
    assert 0.5 * bound < dev <= bound * (1 + 1e-6)


@pytest.mark.interop
def test_jacobi_loop_delay_agrees_with_libcosim(fmus):
    """libcosim's fixed-step (Jacobi) master shows the same one-step loop delay:
    both sequences obey x_{k+1} = x_k - a x_{k-1}; only the first step differs
    (libcosim steps first with the input's start value u = 0)."""
    lc = import_module("libcosimpy.CosimExecution")
    from fmpy import read_model_description
    from libcosimpy.CosimLogging import CosimLogLevel, log_output_level
    from libcosimpy.CosimObserver import CosimObserver
    from libcosimpy.CosimSlave import CosimLocalSlave

    log_output_level(CosimLogLevel.ERROR)
    a, n = 0.3, 30
    ex = lc.CosimExecution.from_step_size(int(round(H_LOOP * 1e9)))
    p = ex.add_local_slave(CosimLocalSlave(str(fmus["mt_integrator"]), "plant"))
    c = ex.add_local_slave(CosimLocalSlave(str(fmus["mt_gain"]), "ctrl"))
    vr = {}
    for key in ("mt_integrator", "mt_gain"):
        vr[key] = {v.name: v.valueReference
                   for v in read_model_description(str(fmus[key])).modelVariables}
    ex.real_initial_value(p, vr["mt_integrator"]["x0"], 1.0)
    ex.real_initial_value(c, vr["mt_gain"]["k"], a / H_LOOP)
    ex.connect_real_variables(p, vr["mt_integrator"]["x"], c, vr["mt_gain"]["u"])
    ex.connect_real_variables(c, vr["mt_gain"]["y"], p, vr["mt_integrator"]["u"])
    obs = CosimObserver.create_last_value()
    ex.add_observer(obs)
    x_lc = [1.0]
    for _ in range(n):
        assert ex.step(1)
        x_lc.append(obs.last_real_values(p, [vr["mt_integrator"]["x"]])[0])
    x_lc = np.array(x_lc)
    del obs, ex  # free libcosim now, not at interpreter shutdown (it aborts there)
    gc.collect()
    x_us = Master(loop_system(fmus, a, "jacobi", 0)).simulate(n * H_LOOP,
                                                               outputs=["plant.x"]).data
    x_us = x_us["plant.x"]
    for x in (x_lc[1:], x_us):
        np.testing.assert_allclose(x[2:], x[1:-1] - a * x[:-2], atol=1e-14)
    assert x_lc[1] == 1.0 and x_us[1] == pytest.approx(1.0 - a)


# --- exchange timing, multirate ---------------------------------------------------------
@pytest.mark.parametrize("algorithm,order", [("jacobi", ("src", "probe")),
                                             ("gauss_seidel", ("src", "probe")),
                                             ("gauss_seidel", ("probe", "src"))])
@pytest.mark.parametrize("p_src,p_dst", [(1, 1), (3, 1), (1, 2), (3, 2), (2, 3)])
def test_linear_coupling_extrapolates_a_ramp_to_the_middle_of_the_target_step(
        fmus, algorithm, order, p_src, p_dst):
    """A ramp x = t through a linear-coupling connection: whichever source samples the target
    sees (cosim.master.algorithms.newest_sample_tick, any periods, either order), their linear
    extrapolant is the ramp itself, so the probe must hold exactly t_mid = the middle of its
    own step over the step; a horizon off by a sample would miss it by a source period."""
    H = 0.01
    system = SystemSpec(
        [FmuSpec("src", fmus["mt_integrator"], {"u": 1.0}, sample_period_ticks=p_src),
         FmuSpec("probe", fmus["mt_gain"], {"k": -1.0}, sample_period_ticks=p_dst)],
        [Connection("src.x", "probe.u", coupling="linear")], H, algorithm, order)
    res = Master(system).simulate(60 * H, outputs=["probe.y"], output_interval=p_dst * H)
    t, y = res.data["time"], res.data["probe.y"]
    late = t >= 3 * max(p_src, p_dst) * H + p_dst * H     # two samples exist by then
    assert late.sum() >= 10
    np.testing.assert_allclose(y[late], t[late] - p_dst * H / 2, rtol=0, atol=1e-12)
