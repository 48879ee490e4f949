"""The table of fixed-step methods (``plant.integrators.METHODS``) is data: its invariants.

* every explicit Runge-Kutta tableau is consistent (row sums = nodes, strictly lower
  triangular, at most 4 stages: the compiled kernel's scratch) and satisfies the order
  conditions of its stated order and not all of the next (Butcher's rooted trees up to order 4);
* the stated order is the order measured on a linear test problem (a damped oscillator with
  harmonic forcing, against scipy's DOP853 at rtol 1e-13), with an independent numpy stepper of
  the tableau, and on the plant (the compiled kernel ``advance_erk``, the axial-torsional chain
  against RK4 at 2 us);
* the stability radius used for the automatic step lies inside the stability region in every
  left-half-plane direction (from the tableau's stability polynomial) and close to its edge;
  a radius of 0 means the region holds no part of the imaginary axis;
* the automatic choice per communication step takes the fewest rhs evaluations per step among
  the methods marked automatic for the model kind.
"""

from __future__ import annotations

import math
from fractions import Fraction

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from drillcosim.plant.integrators import (
    KERNEL_ERK,
    KERNEL_RK4,
    METHODS,
    stability_function,
    stable_step,
)
from drillcosim.plant.model import DrillstringModel
from drillcosim.plant.scene import load_scene

RK = {name: m for name, m in METHODS.items() if m.tableau is not None}


def _conditions(A, b, c) -> dict[int, list[float]]:
    """Residuals of the order conditions per order (Butcher trees up to order 4)."""
    one = np.ones_like(b)
    Ac = A @ c
    return {
        1: [b @ one - 1.0],
        2: [b @ c - 0.5],
        3: [b @ c**2 - 1 / 3, b @ Ac - 1 / 6],
        4: [b @ c**3 - 1 / 4, b @ (c * Ac) - 1 / 8, b @ (A @ c**2) - 1 / 12,
            b @ (A @ Ac) - 1 / 24],
    }


@pytest.mark.parametrize("name", list(RK))
def test_tableau_consistency_and_order_conditions(name):
    m = METHODS[name]
    A, b, c = m.tableau
    assert A.shape == (b.size, b.size) and c.size == b.size == m.stages <= 4
    assert np.all(np.triu(A) == 0.0)  # explicit
    np.testing.assert_allclose(A.sum(axis=1), c, atol=1e-15)
    res = _conditions(A, b, c)
    for order in range(1, m.order + 1):
        assert max(abs(r) for r in res[order]) < 1e-14, (name, order)
    if m.order < 4:
        assert max(abs(r) for r in res[m.order + 1]) > 1e-3  # the order is not higher
    if m.kernel == KERNEL_RK4:
        assert name == "rk4"  # the special kernel is the classic tableau
        np.testing.assert_array_equal(b, [1 / 6, 1 / 3, 1 / 3, 1 / 6])


def _rk_solve(A, b, c, f, y0, T, n):
    """A plain numpy stepper of a tableau (independent of the compiled kernel)."""
    y = np.array(y0, dtype=float)
    h = T / n
    K = np.zeros((b.size, y.size))
    for s in range(n):
        t = s * h
        for i in range(b.size):
            K[i] = f(t + c[i] * h, y + h * (A[i, :i] @ K[:i]))
        y = y + h * (b @ K)
    return y


@pytest.mark.parametrize("name", list(RK))
def test_order_measured_on_a_linear_forced_oscillator(name):
    w, zeta = 7.0, 0.05
    J = np.array([[0.0, 1.0], [-w * w, -2 * zeta * w]])

    def f(t, y):
        return J @ y + np.array([0.0, math.sin(3.0 * t) + math.cos(11.0 * t)])

    y0, T = [1.0, 0.0], 2.0
    ref = solve_ivp(f, (0, T), y0, method="DOP853", rtol=1e-13, atol=1e-15).y[:, -1]
    A, b, c = METHODS[name].tableau
    errs = [np.abs(_rk_solve(A, b, c, f, y0, T, n) - ref).max() for n in (200, 400, 800)]
    slopes = np.log2(np.array(errs[:-1]) / np.array(errs[1:]))
    assert np.all(np.abs(slopes - METHODS[name].order) < 0.25), (name, errs, slopes)


@pytest.mark.parametrize("name", [n for n, m in RK.items() if m.kernel == KERNEL_ERK])
def test_compiled_kernel_converges_at_the_stated_order(name):
    sc = load_scene("paper_open_loop", overrides={"model": "axial_torsional", "outputs": [],
                                                  "unbalance": {"enabled": False}})
    m = DrillstringModel(sc.plant, "axial_torsional")
    T = 0.05
    y0 = m.initial_state()
    ref = y0.copy()
    m.advance(0.0, ref, int(round(T / 2e-6)), T / round(T / 2e-6), method="rk4")
    dts = [1e-4, 5e-5, 2.5e-5]
    errs = []
    for dt in dts:
        y = y0.copy()
        n = int(round(T / dt))
        assert m.advance(0.0, y, n, T / n, method=name) == n
        errs.append(np.abs(y - ref).max())
    slope = float(np.polyfit(np.log(dts), np.log(errs), 1)[0])
    assert abs(slope - METHODS[name].order) < 0.4, (name, errs, slope)


def _boundary(method, theta: float) -> float:
    """Distance from 0 to the edge of the stability region in direction ``theta``."""
    r = np.linspace(1e-6, 4.0, 40001)
    bad = np.abs(stability_function(method, r * np.exp(1j * theta))) > 1.0 + 1e-12
    return float(r[np.argmax(bad)]) if bad.any() else math.inf


@pytest.mark.parametrize("name", list(RK))
def test_stability_radius_inside_the_region(name):
    m = METHODS[name]
    edge = min(_boundary(m, th) for th in np.linspace(np.pi / 2, np.pi, 181))
    if m.radius == 0.0:
        assert edge < 0.01  # nothing of the imaginary axis: no automatic step
        y = np.array([0.1, 0.5, 1.0])
        assert np.all(np.abs(stability_function(m, 1j * y)) > 1.0)
        assert not m.automatic
    else:
        assert 0.93 * edge <= m.radius <= edge, (name, m.radius, edge)


def test_radius_values_from_the_stability_polynomials():
    """RK3 (any 3-stage 3rd-order method): sqrt(3) on the imaginary axis; RK4: 2 sqrt(2)."""
    for name in ("kutta3", "ssprk3", "ralston3"):
        np.testing.assert_allclose(_boundary(METHODS[name], np.pi / 2), math.sqrt(3), atol=1e-3)
        # the stability polynomial is the truncated exponential
        z = np.array([0.3 + 0.2j, -1.0 + 0.5j])
        np.testing.assert_allclose(stability_function(METHODS[name], z),
                                   1 + z + z**2 / 2 + z**3 / 6, rtol=1e-14)
    np.testing.assert_allclose(_boundary(METHODS["rk4"], np.pi / 2), 2 * math.sqrt(2), atol=1e-3)


def test_rational_tableaus_are_exact_fractions():
    """The tableau entries are the published fractions (to the last bit of a double)."""
    for name, m in RK.items():
        for x in (*m.tableau[0].ravel(), *m.tableau[1], *m.tableau[2]):
            frac = Fraction(float(x)).limit_denominator(100)
            assert float(frac) == float(x), (name, x)


def test_automatic_choice_is_the_fewest_rhs_per_step():
    sc = load_scene("paper_closed_loop")
    m = DrillstringModel(sc.plant, sc.model)
    h_star = m.stable_step()

    def cost(name, h):
        spec = METHODS[name]
        return spec.stages * max(1, math.ceil(h / stable_step(m.max_eigenvalue, spec.radius)
                                              - 1e-9))

    for h in (1e-4, 2.5e-4, h_star, 5e-4, 1e-3, 2e-3):
        chosen = m.method_for_step(h)
        assert m.kind in METHODS[chosen].automatic
        auto = [n for n, s in METHODS.items() if m.kind in s.automatic]
        assert cost(chosen, h) == min(cost(n, h) for n in auto)
    assert m.method_for_step(2.5e-4) == "kutta3"  # 3 rhs against RK4's 4 (BENCHMARKS.md)
    assert m.method_for_step(1e-3) == "rk4"  # a tie at 12 rhs: 3 RK4 steps against 4
    assert m.method_for_step(None) == m.default_method == "rk4"
    at = DrillstringModel(load_scene("stick_slip").plant, "axial_torsional")
    assert at.method_for_step(2.5e-4) == "rk4"  # kutta3 is not automatic for the chain
    lti = DrillstringModel(load_scene("table1_axial_pulse").plant, "axial_torsional")
    assert lti.method_for_step(2.5e-4) == "expeuler"
