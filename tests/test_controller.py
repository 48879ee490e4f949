"""Strain-feedback law (controller/) against closed-form formulas."""

from __future__ import annotations

import ast
import copy
import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from drillcosim.controller import CHANNELS, ControllerParams, StrainController

ROOT = Path(__file__).resolve().parents[1]


def one_hot(value: float, channel: int = 0) -> np.ndarray:
    x = np.zeros(4)
    x[channel] = value
    return x


# --------------------------------------------------------------------------- sign / gain
@pytest.mark.parametrize("channel", range(4))
def test_force_is_gain_times_strain_per_channel(channel: int) -> None:
    c = StrainController(ControllerParams(gain=1e9))
    f = c.step(0.0, 1e-3, one_hot(2e-6, channel))
    assert f.tolist() == one_hot(2000.0, channel).tolist()


def test_sign_positive_strain_gives_positive_force_in_both_modes() -> None:
    # F > 0 means "compressive at D / tensile at C": the couple reducing positive strain.
    strains = np.array([1e-6, -1e-6, 3e-6, -3e-6])
    free = StrainController(ControllerParams(gain=1e9, mode="unrestricted"))
    push = StrainController(ControllerParams(gain=1e9, mode="compressive_only"))
    np.testing.assert_array_equal(free.step(0, 1e-3, strains), [1000.0, -1000.0, 3000.0, -3000.0])
    np.testing.assert_array_equal(push.step(0, 1e-3, strains), [1000.0, 0.0, 3000.0, 0.0])


def test_channel_order() -> None:
    assert CHANNELS == ("strain1_C", "strain1_E", "strain2_C", "strain2_E")


# ----------------------------------------------------------------------------- saturation
def test_compressive_only_clips_to_zero_and_force_limit() -> None:
    c = StrainController(ControllerParams(gain=1e9, mode="compressive_only", force_limit=5000.0))
    f = c.step(0.0, 1e-3, np.array([-1e-3, 2e-6, 5e-6, 1.0]))
    np.testing.assert_array_equal(f, [0.0, 2000.0, 5000.0, 5000.0])


def test_unrestricted_is_unclipped_by_default() -> None:
    c = StrainController(ControllerParams(gain=1e9, mode="unrestricted", force_limit=1.0))
    f = c.step(0.0, 1e-3, np.array([-1e-3, 2e-6, 5e-6, 1.0]))
    np.testing.assert_array_equal(f, [-1e6, 2000.0, 5000.0, 1e9])


def test_unrestricted_symmetric_limit() -> None:
    p = ControllerParams(gain=1e9, mode="unrestricted", symmetric_force_limit=3000.0)
    f = StrainController(p).step(0.0, 1e-3, np.array([-1e-3, 2e-6, 5e-6, -2e-6]))
    np.testing.assert_array_equal(f, [-3000.0, 2000.0, 3000.0, -2000.0])


@settings(max_examples=200, deadline=None)
@given(
    strain=st.floats(-1e-2, 1e-2, allow_nan=False),
    gain=st.floats(0.0, 1e12, allow_nan=False),
    limit=st.floats(0.0, 1e6, allow_nan=False),
    mode=st.sampled_from(["unrestricted", "compressive_only"]),
)
def test_saturation_formula(strain: float, gain: float, limit: float, mode: str) -> None:
    p = ControllerParams(gain=gain, mode=mode, force_limit=limit, symmetric_force_limit=limit)
    f = StrainController(p).step(0.0, 1e-3, np.full(4, strain))
    lo = 0.0 if mode == "compressive_only" else -limit
    expected = min(max(gain * strain, lo), limit)
    assert f.tolist() == [expected] * 4


# ------------------------------------------------------------------------------ switch-on
def test_zero_output_before_switch_on_time() -> None:
    dt = 1e-3
    c = StrainController(ControllerParams(gain=1e9, switch_on_time=0.025))
    outputs = [c.step(k * dt, dt, np.full(4, 1e-6))[0] for k in range(50)]
    n_off = sum(1 for f in outputs if f == 0.0)
    assert n_off == 25  # steps starting at t = 0 .. 0.024
    assert all(f == 1000.0 for f in outputs[25:])


def test_switch_on_tolerates_accumulated_round_off() -> None:
    t_acc = sum([0.1] * 10)  # 0.9999999999999999: one ulp below 1.0
    assert t_acc < 1.0
    c = StrainController(ControllerParams(switch_on_time=1.0))
    assert c.is_active(t_acc)
    assert c.is_active(1.0)
    assert not c.is_active(1.0 - 1e-9)


def test_disabled_controller_outputs_zero() -> None:
    c = StrainController(ControllerParams(enabled=False, lag_time_constant=0.1))
    for k in range(10):
        assert c.step(k * 1e-3, 1e-3, np.full(4, 1e-3)).tolist() == [0.0] * 4


# ------------------------------------------------------------------------------------ lag
@pytest.mark.parametrize(("tau", "dt"), [(0.05, 1e-3), (0.2, 7e-3), (1.0, 0.5)])
def test_lag_step_response_is_exact_at_sample_points(tau: float, dt: float) -> None:
    c = StrainController(ControllerParams(gain=1.0, lag_time_constant=tau))
    for k in range(1, 400):
        f = c.step((k - 1) * dt, dt, np.ones(4))
        expected = 1.0 - math.exp(-k * dt / tau)
        # exact discretisation: only round-off, no O(dt) error
        np.testing.assert_allclose(f, expected, rtol=0, atol=1e-13)


def test_lag_with_saturated_command_stays_inside_limits() -> None:
    p = ControllerParams(gain=1e9, mode="compressive_only", force_limit=5000.0,
                         lag_time_constant=0.01)
    c = StrainController(p)
    for k in range(200):
        f = c.step(k * 1e-3, 1e-3, np.full(4, 1e-2 * (-1) ** (k // 20)))
        assert np.all(f >= 0.0) and np.all(f <= 5000.0)


def test_lag_free_response_and_variable_steps() -> None:
    tau = 0.3
    c = StrainController(ControllerParams(gain=1.0, lag_time_constant=tau))
    c.set_state(np.array([2.0, -1.0, 0.5, 0.0]))
    t = 0.0
    for dt in [0.01, 0.1, 0.013, 0.2]:
        c.step(t, dt, np.zeros(4))
        t += dt
    np.testing.assert_allclose(c.forces, np.array([2.0, -1.0, 0.5, 0.0]) * math.exp(-t / tau),
                               rtol=1e-14, atol=0)


def test_zero_step_keeps_lag_state() -> None:
    c = StrainController(ControllerParams(gain=1.0, lag_time_constant=0.1))
    c.set_state(np.array([1.0, 2.0, 3.0, 4.0]))
    assert c.step(0.0, 0.0, np.zeros(4)).tolist() == [1.0, 2.0, 3.0, 4.0]


# ---------------------------------------------------------------------------------- state
def test_get_set_state_reproduces_run_bit_for_bit() -> None:
    rng = np.random.default_rng(1)
    strains = rng.normal(scale=1e-5, size=(200, 4))
    c = StrainController(ControllerParams(lag_time_constant=0.02, switch_on_time=0.01))
    for k in range(100):
        c.step(k * 1e-3, 1e-3, strains[k])
    saved = c.get_state()
    saved_copy = copy.deepcopy(saved)
    first = [c.step(k * 1e-3, 1e-3, strains[k]) for k in range(100, 200)]
    c.set_state(saved)
    second = [c.step(k * 1e-3, 1e-3, strains[k]) for k in range(100, 200)]
    assert np.array_equal(np.array(first), np.array(second))
    assert np.array_equal(saved, saved_copy)  # get_state returned a copy, not a view


def test_reset_zeroes_state() -> None:
    c = StrainController(ControllerParams(lag_time_constant=1.0))
    c.step(0.0, 0.1, np.full(4, 1e-6))
    c.reset()
    assert c.get_state().tolist() == [0.0] * 4


def test_failed_step_leaves_state_unchanged() -> None:
    c = StrainController(ControllerParams(lag_time_constant=1.0))
    c.step(0.0, 0.1, np.full(4, 1e-6))
    before = c.get_state()
    with pytest.raises(ValueError, match="strain2_C"):
        c.step(0.1, 0.1, np.array([0.0, 0.0, np.nan, 0.0]))
    with pytest.raises(ValueError, match="dt"):
        c.step(0.1, -0.1, np.zeros(4))
    with pytest.raises(ValueError, match="shape"):
        c.step(0.1, 0.1, np.zeros(3))
    assert np.array_equal(c.get_state(), before)


def test_set_state_validates() -> None:
    c = StrainController()
    with pytest.raises(ValueError, match="shape"):
        c.set_state(np.zeros(5))
    with pytest.raises(ValueError, match="finite"):
        c.set_state(np.array([0.0, np.inf, 0.0, 0.0]))


def test_changing_params_keeps_state_and_updates_decay() -> None:
    c = StrainController(ControllerParams(gain=1.0, lag_time_constant=0.1))
    c.step(0.0, 0.1, np.ones(4))
    c.params = ControllerParams(gain=1.0, lag_time_constant=0.2)
    f = c.step(0.1, 0.1, np.ones(4))
    expected = 1.0 - math.exp(-1.0) * math.exp(-0.5)
    np.testing.assert_allclose(f, expected, rtol=0, atol=1e-15)
    with pytest.raises(TypeError):
        c.params = {"gain": 1.0}  # type: ignore[assignment]


# ----------------------------------------------------------------------------- validation
@pytest.mark.parametrize(
    ("kwargs", "fragments"),
    [
        ({"gain": -1.0}, ["gain", "-1.0", "0 <= gain < inf"]),
        ({"gain": math.inf}, ["gain", "inf", "0 <= gain < inf"]),
        ({"gain": math.nan}, ["gain", "nan", "0 <= gain < inf"]),
        ({"gain": "1e9"}, ["gain", "'1e9'", "real number"]),
        ({"gain": True}, ["gain", "True", "real number"]),
        ({"force_limit": -5.0}, ["force_limit", "-5.0", "0 <= force_limit <= inf"]),
        ({"force_limit": math.nan}, ["force_limit", "nan"]),
        ({"symmetric_force_limit": -1.0}, ["symmetric_force_limit", "-1.0", "<= inf"]),
        ({"switch_on_time": -0.5}, ["switch_on_time", "-0.5", "0 <= switch_on_time < inf"]),
        ({"switch_on_time": math.nan}, ["switch_on_time", "nan"]),
        ({"lag_time_constant": -1e-3}, ["lag_time_constant", "-0.001", "0 <= lag_time_constant"]),
        ({"lag_time_constant": math.nan}, ["lag_time_constant", "nan"]),
        ({"mode": "tensile_only"}, ["mode", "'tensile_only'", "'unrestricted'",
                                    "'compressive_only'"]),
        ({"enabled": 1}, ["enabled", "1", "True or False"]),
    ],
)
def test_validation_messages(kwargs: dict, fragments: list[str]) -> None:
    with pytest.raises(ValueError) as info:
        ControllerParams(**kwargs)
    for fragment in fragments:
        assert fragment in str(info.value)


def test_defaults_and_frozen() -> None:
    p = ControllerParams()
    assert (p.gain, p.mode, p.force_limit, p.switch_on_time, p.lag_time_constant, p.enabled) == (
        1e9, "unrestricted", 5000.0, 0.0, 0.0, True)
    assert p.symmetric_force_limit == math.inf
    assert isinstance(ControllerParams(gain=10).gain, float)
    with pytest.raises(AttributeError):
        p.gain = 2.0  # type: ignore[misc]


def test_controller_package_imports_are_relative_and_numpy_only() -> None:
    """The package is vendored under another name: no absolute self-imports; numpy and the
    standard library only, but for the compiled steps (``compiled.py``, numba), which
    ``acceleration.py`` imports inside a function, only where numba is loaded (the controller
    FMUs run in a Python with only numpy)."""
    base = {"__future__", "math", "numbers", "dataclasses", "typing", "collections", "numpy"}
    extra = {"compiled.py": {"ctypes", "numba", "hashlib", "pathlib", "sys"},
             "acceleration.py": {"os", "sys"}, "registry.py": {"importlib"},
             "state_space.py": {"json", "pathlib"}}  # its matrices file
    for path in (ROOT / "controller").rglob("*.py"):
        allowed = base | extra.get(path.name, set())
        tree = ast.parse(path.read_text(), filename=str(path))
        for node in ast.walk(tree):
            if isinstance(node, ast.Import):
                names = [a.name.split(".")[0] for a in node.names]
            elif isinstance(node, ast.ImportFrom):
                if node.level > 0:
                    continue
                names = [(node.module or "").split(".")[0]]
            else:
                continue
            assert set(names) <= allowed, f"{path.name}: absolute import of {names}"
