"""The ZTorque top-drive law (``controller/ztorque.py``, ``[top_drive_controller] kind =
"ztorque"``) against a formula and in the stick-slip scenes.

* The drive alone (a rotor of inertia J driven by the law's motor torque against a sinusoidal
  top torque): the impedance ``-delta T / delta Omega`` the sampled law gives equals the
  continuous formula of the module docstring, ``(i w J + C) / (1 + C k H / zeta)``, to O(h),
  and tends to ``zeta / k`` (the tuning rule: a matched drive does not reflect);
* a constant top torque: the mean speed is the target (the high-pass keeps the mean out);
* ``stick_slip_ztorque`` and ``field_vertical_3km_ztorque``: the bit keeps turning, where the
  same stiff speed loop without the torque feedback (``torque_factor = 0``) sticks and slips.
"""

from __future__ import annotations

import numpy as np
import pytest

import drillcosim
from drillcosim.controller.ztorque import ZTorqueController, ZTorqueParams

J, ZETA, TAU, P, I = 500.0, 300.0, 10.0, 15000.0, 2500.0


def _drive(law: ZTorqueController, torque, h: float, n: int) -> np.ndarray:
    """The drive speed [rad/s] of a rotor J dOmega/dt = T_m - T_s under ``law``, the top
    torque ``torque(t)`` and the motor torque held over each step (exact for held torques)."""
    speed, motor = 2.0, 0.0
    out = np.empty(n)
    for k in range(n):
        t = k * h
        out[k] = speed
        nxt = law.step(t, h, speed, torque(t))
        speed += h * (motor - torque(t)) / J
        motor = nxt
    return out


def _phasor(t: np.ndarray, x: np.ndarray, w: float) -> complex:
    a = np.column_stack([np.sin(w * t), np.cos(w * t), np.ones(t.size)])
    c = np.linalg.lstsq(a, x, rcond=None)[0]
    return complex(c[1], -c[0])  # x = Re(X exp(i w t))


@pytest.mark.parametrize(("w", "k"), [(2.0, 1.0), (2.0, 0.5), (5.0, 0.25)])
def test_sampled_law_has_the_impedance_of_the_formula(w: float, k: float) -> None:
    errors = {}
    for h in (1e-3, 2.5e-4):
        law = ZTorqueController(ZTorqueParams(ramp_time=0.0, impedance=ZETA, torque_factor=k,
                                              highpass_time_constant=TAU, p_gain=P, i_gain=I))
        n = int(120.0 / h)
        speed = _drive(law, lambda t: 5e3 + 1e3 * np.sin(w * t), h, n)
        t = np.arange(n) * h
        sel = t > 80.0
        z = -_phasor(t[sel], 1e3 * np.sin(w * t[sel]), w) / _phasor(t[sel], speed[sel], w)
        c = P + I / (1j * w)
        hp = 1j * w * TAU / (1 + 1j * w * TAU)
        formula = (1j * w * J + c) / (1 + c * k * hp / ZETA)
        errors[h] = abs(z - formula) / abs(formula)
        assert abs(formula - ZETA / k) < 0.2 * ZETA / k  # stiff loop: nearly zeta / k
    assert errors[2.5e-4] < 1.5e-3
    assert errors[2.5e-4] < 0.4 * errors[1e-3]  # first order in h


def test_mean_speed_is_the_target_under_a_constant_torque() -> None:
    law = ZTorqueController(ZTorqueParams(target_speed=3.0, ramp_time=1.0, impedance=ZETA,
                                          torque_factor=1.0, highpass_time_constant=2.0,
                                          p_gain=P, i_gain=I))
    speed = _drive(law, lambda t: 4e3 if t > 0.5 else 0.0, 1e-3, 60000)
    # the slow pole of the PI loop is I / P = 0.17 /s: exp(-0.17 * 60) = 4e-5
    assert abs(speed[-1] - 3.0) < 1e-4 and abs(speed[-1] - 3.0) < 0.01 * abs(speed[20000] - 3.0)


def test_compiled_step_equals_python_step() -> None:
    pytest.importorskip("numba")  # compiled steps exist where numba is loaded
    params = ZTorqueParams(ramp_time=0.05, torque_factor=0.5, highpass_time_constant=0.2)
    fast, ref = ZTorqueController(params), ZTorqueController(params)
    inputs, outputs = np.zeros(2), np.zeros(1)
    step = fast.compiled_step(inputs, outputs)
    assert step is not None
    rng = np.random.default_rng(5)
    codes = []
    for k in range(300):
        h = 1e-3 if k < 200 else 5e-4
        t = k * 1e-3
        inputs[:] = rng.normal(2.0, 0.3), rng.normal(4e3, 500.0)
        code = step.step(t, h)
        codes.append(code)
        if code != 0:
            fast.advance(t, h, inputs, outputs)
        expect = ref.step(t, h, float(inputs[0]), float(inputs[1]))
        assert outputs[0].tobytes() == np.float64(expect).tobytes(), k
    assert codes.count(0) >= 297  # Python only for the first step of each step size


@pytest.mark.parametrize(("scene", "limit"), [("stick_slip_ztorque", 0.05),
                                              ("field_vertical_3km_ztorque", 0.1)])
def test_ztorque_scene_keeps_the_bit_turning_a_stiff_speed_loop_does_not(scene, limit) -> None:
    on = drillcosim.simulate(scene, engine="inprocess").summary["torsional"]
    off = drillcosim.simulate(scene, engine="inprocess",
                              overrides={"top_drive_controller.torque_factor": 0.0}
                              ).summary["torsional"]
    assert on["stick_slip_severity"] < limit and on["bit_speed_min_rad_s"] > 1.0
    assert off["stick_slip_severity"] > 1.5
