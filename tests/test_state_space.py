"""The generic discrete state-space law (controller/state_space.py): against scipy's dlsim (a
second implementation), its compiled step against its numpy step, timing, saturation, and
one-line errors for bad matrices and signals."""

import json
import math

import numpy as np
import pytest
import scipy.signal

from drillcosim.controller.state_space import (
    Signal,
    StateSpaceController,
    StateSpaceParams,
    load_state_space,
    state_space_from_mapping,
)

TS = 2.5e-4


def random_params(n=6, m=4, p=3, seed=0, lower=-math.inf, upper=math.inf):
    rng = np.random.default_rng(seed)
    A = rng.normal(size=(n, n))
    A *= 0.95 / max(abs(np.linalg.eigvals(A)))       # stable: values stay O(1)
    return StateSpaceParams(A, rng.normal(size=(n, m)), rng.normal(size=(p, n)),
                            rng.normal(size=(p, m)), [Signal(f"y{i}") for i in range(m)],
                            [Signal(f"u{i}", "N", lower, upper) for i in range(p)], TS)


def test_law_equals_scipy_dlsim():
    prm = random_params()
    y = np.random.default_rng(1).normal(size=(200, 4))
    _t, ref, _x = scipy.signal.dlsim((prm.A, prm.B, prm.C, prm.D, TS), y)
    law = StateSpaceController(prm)
    out = np.array([law.step(k * TS, TS, y[k]) for k in range(len(y))])
    assert np.max(np.abs(out - ref)) <= 1e-14 * np.max(np.abs(ref))


def compiled(law):
    """The law's compiled step on fresh buffers (numba loaded: it is in the test process)."""
    inputs, outputs = np.zeros(len(law.params.inputs)), np.zeros(len(law.params.outputs))
    step = law.compiled_step(inputs, outputs)
    assert step is not None
    return step, inputs, outputs


def test_compiled_step_equals_numpy_step():
    prm = random_params(n=9, m=5, p=4, seed=3, lower=-1.0, upper=1.5)
    a, b = StateSpaceController(prm), StateSpaceController(prm)
    step, inputs, outputs = compiled(b)
    rng = np.random.default_rng(2)
    for k in range(300):
        y = rng.normal(size=5)
        ua = a.step(k * TS, 2 * TS, y)
        inputs[:] = y
        assert step.step(k * TS, 2 * TS) == 0
        # the same law; numba's BLAS and numpy's may round the products differently
        np.testing.assert_allclose(outputs, ua, rtol=0, atol=1e-13)
        np.testing.assert_array_equal(outputs, b.workspace.outputs)
    np.testing.assert_allclose(b.workspace.state, a.workspace.state, rtol=0, atol=1e-13)
    assert a.workspace.samples == b.workspace.samples == 600


def test_samples_per_step_saturation_and_timing():
    prm = random_params(lower=-0.5, upper=0.5)
    y = np.array([0.3, -1.0, 2.0, 0.1])
    one, three = StateSpaceController(prm), StateSpaceController(prm)
    for _ in range(3):
        u1 = one.step(0.0, TS, y)
    u3 = three.step(0.0, 3 * TS, y)
    np.testing.assert_array_equal(u1, u3)
    assert np.all(u3 <= 0.5) and np.all(u3 >= -0.5)
    # the output after the first step comes from the inputs set before it: u = C x0 + D y
    fresh = StateSpaceController(prm)
    np.testing.assert_array_equal(fresh.step(0.0, TS, y), np.clip(prm.D @ y, -0.5, 0.5))
    assert fresh.step(0.0, 0.0, y) is not None and fresh.workspace.samples == 1  # h = 0: none


def test_static_gain_is_the_p_law():
    from drillcosim.controller import ControllerParams, StrainController

    prm = StateSpaceParams([], [], [], 1e9 * np.eye(4), [Signal(f"s{i}") for i in range(4)],
                           [Signal(f"f{i}", "N") for i in range(4)], TS)
    p_law = StrainController(ControllerParams(gain=1e9))
    law = StateSpaceController(prm)
    for k, y in enumerate(np.random.default_rng(4).normal(scale=1e-5, size=(20, 4))):
        np.testing.assert_array_equal(law.step(k * TS, TS, y), p_law.step(k * TS, TS, y))


def test_bad_step_or_input_changes_nothing():
    prm = random_params()
    law = StateSpaceController(prm)
    law.step(0.0, TS, np.ones(4))
    before = law.workspace.array.copy()
    with pytest.raises(ValueError, match="not an integer multiple"):
        law.step(TS, 1.5 * TS, np.ones(4))
    with pytest.raises(ValueError, match="non-finite input.*y2"):
        law.step(TS, TS, np.array([0, 0, np.nan, 0]))
    np.testing.assert_array_equal(law.workspace.array, before)
    from drillcosim.controller.compiled import REFUSED

    step, inputs, outputs = compiled(law)
    inputs[:] = [0, np.inf, 0, 0]
    assert step.step(TS, TS) == REFUSED
    inputs[:] = 1.0
    assert step.step(TS, 0.7 * TS) == REFUSED
    assert step.step(TS, math.nan) == REFUSED
    assert step.step(math.inf, TS) == REFUSED
    np.testing.assert_array_equal(law.workspace.array, before)
    assert not outputs.any()


@pytest.mark.parametrize("change, message", [
    ({"A": np.ones((2, 3))}, "A is 2 x 3; allowed: a square matrix"),
    ({"B": np.ones((6, 2))}, r"B is 6 x 2; allowed: 6 x 4 \(states x inputs\)"),
    ({"C": np.ones((3, 5))}, r"C is 3 x 5; allowed: 3 x 6 \(outputs x states\)"),
    ({"D": np.full((3, 4), np.nan)}, r"D\[1, 1\] = nan: every entry must be finite"),
    ({"inputs": [Signal("y0"), Signal("y0"), Signal("y2"), Signal("y3")]}, "repeated: y0"),
    ({"outputs": [Signal("u 0"), Signal("u1"), Signal("u2")]}, "'u 0' is not allowed"),
    ({"outputs": [Signal("u0", "N", 1.0, -1.0), Signal("u1"), Signal("u2")]},
     "output u0: limits"),
    ({"sample_period": 0.0}, "sample_period = 0.0; allowed"),
])
def test_bad_params_one_line(change, message):
    prm = random_params()
    kw = {k: getattr(prm, k) for k in ("A", "B", "C", "D", "inputs", "outputs",
                                       "sample_period")}
    kw.update(change)
    with pytest.raises(ValueError, match=message) as info:
        StateSpaceParams(**kw)
    assert "\n" not in str(info.value)


def test_json_round_trip_is_exact(tmp_path):
    prm = random_params(lower=-2.0)
    back = load_state_space(prm.save(tmp_path / "c.json"))
    for k in "ABCD":
        np.testing.assert_array_equal(getattr(back, k), getattr(prm, k))
    assert back.outputs == prm.outputs and back.inputs == prm.inputs
    assert back.sample_period == prm.sample_period
    data = prm.to_mapping()
    data["n_states"] = 5
    with pytest.raises(ValueError, match=r"^where: n_states = 5 does not match A"):
        state_space_from_mapping(data, "where")
    (tmp_path / "bad.json").write_text(json.dumps({**prm.to_mapping(), "E": 1}))
    with pytest.raises(ValueError, match=r"bad\.json: unknown key\(s\) E"):
        load_state_space(tmp_path / "bad.json")
