"""Step loads are piecewise-constant inputs: no integration step straddles or half-sees a switch.

Before the fix a stage evaluated at a switch time saw the next load value (``start <= t < end``
at a point), an O(h) error: RK4 on the Table 1 pulse converged at first order (1.0e-2 at h*,
3.1e-3 at h*/4). These tests assert the methods' own orders across switches, on the grid and
between grid points, against a reference with the same breakpoints and a tiny step.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from drillcosim.plant.kernels import one_minus_cos_small, sin_small
from drillcosim.plant.model import DrillstringModel
from drillcosim.plant.scene import load_scene
from drillcosim.plant.simulator import PlantSimulator


def _pulse_model(start: float, duration: float, kind: str = "axial_torsional") -> DrillstringModel:
    sc = load_scene("table1_torsional_pulse", overrides={
        "loads": [{"kind": "torque", "body": 30, "direction": "z", "magnitude": 1000.0,
                   "start": start, "duration": duration}]})
    return DrillstringModel(sc.plant, kind)


def _run(m: DrillstringModel, T: float, H: float, max_step: float, method: str = "rk4"):
    sim = PlantSimulator(m, max_step=max_step, method=method)
    for k in range(int(round(T / H))):
        assert sim.do_step(k * H, H).ok
    return sim.y.copy()


def _err(m, T, H, dt, ref, method="rk4"):
    y = _run(m, T, H, dt, method)
    return np.abs(y - ref).max() / np.abs(ref).max()


@pytest.mark.parametrize("start, duration", [(0.0, 0.01), (0.01234, 0.00777)])
def test_rk4_keeps_fourth_order_across_load_switches(start, duration):
    m = _pulse_model(start, duration)
    T, H = 0.05, 1e-3
    ref = _run(m, T, H, 1e-3 / 64)
    e1 = _err(m, T, H, 1e-3 / 4, ref)
    e2 = _err(m, T, H, 1e-3 / 8, ref)
    assert e1 / e2 > 12.0, (e1, e2)  # 2^4 = 16; first order would give 2


def test_switch_between_grid_points_is_a_breakpoint():
    m = _pulse_model(0.01234, 0.00777)
    np.testing.assert_allclose(m.breakpoints, [0.01234, 0.02011])
    # a communication step containing the switch gives the same state as two steps split at it
    a = PlantSimulator(m, max_step=1e-4)
    b = PlantSimulator(m, max_step=1e-4)
    assert a.do_step(0.0, 0.02).ok
    for t0, t1 in [(0.0, 0.01234), (0.01234, 0.02)]:
        assert b.do_step(t0, t1 - t0).ok
    np.testing.assert_allclose(a.y, b.y, rtol=0, atol=1e-12 * np.abs(b.y).max())


@pytest.mark.parametrize("method, order", [("verlet", 2), ("dopri5", None)])
def test_other_methods_see_the_switch_once(method, order):
    m = _pulse_model(0.0, 0.01)
    T, H = 0.05, 1e-3
    ref = _run(m, T, H, 1e-3 / 64)
    if order is None:  # adaptive: tolerance-bound error
        sim = PlantSimulator(m, method="dopri5", rtol=1e-10, atol=1e-13)
        for k in range(int(round(T / H))):
            assert sim.do_step(k * H, H).ok
        assert np.abs(sim.y - ref).max() <= 1e-8 * np.abs(ref).max()
        return
    e1 = _err(m, T, H, 1e-4, ref, method)
    e2 = _err(m, T, H, 5e-5, ref, method)
    assert e1 / e2 > 2 ** order * 0.75, (e1, e2)


def test_exponential_euler_is_exact_for_the_pulse():
    m = _pulse_model(0.0, 0.01)
    T, H = 0.05, 1e-3
    ref = _run(m, T, H, 1e-3 / 64)
    assert _err(m, T, H, 1e-3, ref, "expeuler") < 1e-8


def test_small_angle_functions_match_the_library():
    xs = np.concatenate([np.linspace(-0.04, 0.04, 4001), [1e-300, -1e-12, 0.5, -2.0, 3.0, 1e3]])
    for x in xs:
        s = sin_small(float(x))
        assert abs(s - math.sin(x)) <= 2.3e-16 * abs(math.sin(x)) + 1e-300, x
        c = one_minus_cos_small(float(x))
        exact = 2.0 * math.sin(0.5 * x) ** 2
        assert abs(c - exact) <= 4.5e-16 * exact + 1e-300, x


def test_auto_method_is_exponential_euler_only_where_it_is_exact():
    for name in ("table1_axial_pulse", "table1_torsional_pulse"):
        sc = load_scene(name)
        m = DrillstringModel(sc.plant, sc.model)
        assert m.kind == "axial_torsional" and m.default_method == "expeuler"
        assert PlantSimulator(m).method == "expeuler"
    # a prescribed rotation ramp is integrated exactly (tests/test_drive_ramps.py);
    # a bit torque (tanh) or the bit's sinusoidal displacement are not
    sc = load_scene("table1_torsional_pulse", overrides={"top_drive": {"rotary_speed": 10.0}})
    assert DrillstringModel(sc.plant, "axial_torsional").default_method == "expeuler"
    for ov in ({"top_drive": {"rotary_speed": 10.0},
                "bit": {"axial_stiffness": 1e9, "displacement_amplitude": 0.003}},
               {"bit": {"torque": 100.0}}):
        sc = load_scene("table1_torsional_pulse", overrides=ov)
        assert DrillstringModel(sc.plant, "axial_torsional").default_method == "rk4"
    sc = load_scene("paper_open_loop")
    assert DrillstringModel(sc.plant, sc.model).default_method == "rk4"


@pytest.mark.parametrize("start", [0.0, 0.01234])
def test_compiled_recording_equals_stepping_for_exponential_euler(start):
    m = _pulse_model(start, 0.01)
    idx = np.arange(len(m.output_names))
    a = PlantSimulator(m, method="expeuler")
    rec, res = a.run_record(1e-3, 50, idx)
    assert res.ok and rec.shape == (51, idx.size)
    b = PlantSimulator(m, method="expeuler")
    rows = [b.outputs().copy()]
    for k in range(50):
        assert b.do_step(k * 1e-3, 1e-3).ok
        rows.append(b.outputs().copy())
    np.testing.assert_array_equal(rec, np.array(rows))
    assert a.time == pytest.approx(0.05, abs=1e-15)


def test_exponential_operator_is_two_blocks_on_the_chain():
    m = _pulse_model(0.0, 0.01)
    idx, sizes, blocks, ramp = m.expeuler_operator(1e-3)
    assert ramp.shape == (0, m.n_state)  # no drive moves
    assert sizes.tolist() == [2 * m.n, 2 * m.n]  # axial and torsional states never couple
    P1 = m.exponential_matrices(1e-3)[0]
    x = np.random.default_rng(0).normal(size=P1.shape[0])
    from drillcosim.plant.integrators import block_matvec_add
    out = np.zeros_like(x)
    block_matvec_add(idx, sizes, blocks, x, out, np.zeros_like(x))
    np.testing.assert_allclose(out, P1 @ x, rtol=1e-13, atol=1e-13 * np.abs(P1 @ x).max())
