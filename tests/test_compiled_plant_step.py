"""The compiled steps in process (``plant/compiled_step.py``, ``controller/compiled.py``, through
ctypes) against the Python reference: every fixed-step method, load switches inside steps,
auxiliary states and a top-drive input, the automatic method per step size, refused steps and
divergence; the controller laws with any number of sites, a gain matrix, saturation, lag and
switch-on. Equal bit for bit: state, time, outputs and results (messages included)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from drillcosim.controller import (
    ControllerParams,
    StrainController,
    TopDriveController,
    TopDriveControllerParams,
)
from drillcosim.plant.model import DrillstringModel
from drillcosim.plant.scene import load_scene
from drillcosim.plant.simulator import MAX_SUBSTEPS, PlantSimulator


def _pair(scene, method="auto", max_step=None, model=None, **overrides):
    """(compiled step + its buffers, Python reference simulator) of the same plant."""
    sc = load_scene(scene, overrides=overrides or None)
    kind = model or sc.model
    fast = PlantSimulator(DrillstringModel(sc.plant, kind), max_step, method)
    ref = PlantSimulator(DrillstringModel(sc.plant, kind), max_step, method)
    inp = np.zeros(fast.u.size)
    out = np.zeros(len(fast.model.output_names))
    step = fast.compiled_step(inp, np.arange(inp.size), out, np.arange(out.size))
    assert step is not None
    return step, inp, out, ref


def _bits(a) -> np.ndarray:
    return np.asarray(a, dtype=np.float64).view(np.int64)


def _run_both(step, inp, out, ref, times, h, rng, scale):
    fast = step.sim
    for t in times:
        u = rng.normal(size=inp.size) * scale
        inp[:] = u
        ref.u[:] = u
        a, b = step.step(t, h), ref.do_step(t, h)
        assert a == b
        np.testing.assert_array_equal(_bits(fast.y), _bits(ref.y))
        assert fast.time == ref.time
        if a.ok:
            np.testing.assert_array_equal(_bits(out), _bits(ref.outputs()))
        assert fast.method == ref.method


SWITCHES = {"top_drive": {"ramp_time": 0.0101},  # the ramp ends, a lateral pulse on and off
            "loads": [{"kind": "force", "body": 11, "direction": "x", "magnitude": 10.0,
                       "start": 0.0033, "duration": 0.0053}]}


@pytest.mark.parametrize("method", ["rk4", "kutta3", "ssprk3", "ralston3", "verlet"])
def test_3d_methods_with_load_switches_inside_steps(method):
    step, inp, out, ref = _pair("paper_open_loop", method, **SWITCHES)
    h = 7e-4
    bps = step.sim.model.breakpoints
    n = int(math.ceil((bps[-1] + 5e-3) / h))
    assert sum(any(k * h < b < (k + 1) * h for k in range(n)) for b in bps) == 3
    _run_both(step, inp, out, ref, [k * h for k in range(n)], h, np.random.default_rng(1), 1e3)


@pytest.mark.parametrize("method", ["expeuler", "etd2", "rk4", "heun2"])
def test_chain_methods_with_a_pulse(method):
    step, inp, out, ref = _pair("table1_axial_pulse", method,
                                max_step=2.5e-4 if method == "heun2" else None)
    h = 7e-4  # the pulse ends inside a step: the exponential operators fall back there
    n = 40
    _run_both(step, inp, out, ref, [k * h for k in range(n)], h, np.random.default_rng(2), 0.0)
    assert np.ptp(ref.y) > 0


def test_auxiliary_states_and_a_top_drive_input():
    step, inp, out, ref = _pair("stick_slip_soft_torque")
    assert step.sim.model.aux_names and "top_drive_torque" in step.sim.input_names
    _run_both(step, inp, out, ref, [k * 1e-3 for k in range(300)], 1e-3,
              np.random.default_rng(3), 3e3)


def test_the_automatic_method_follows_the_step_size():
    step, inp, out, ref = _pair("paper_closed_loop")
    rng = np.random.default_rng(4)
    _run_both(step, inp, out, ref, [k * 1e-3 for k in range(20)], 1e-3, rng, 1e3)
    assert step.sim.method == "rk4"
    t0 = 20e-3
    _run_both(step, inp, out, ref, [t0 + k * 2.5e-4 for k in range(40)], 2.5e-4, rng, 1e3)
    assert step.sim.method == "kutta3"


@pytest.mark.parametrize("method, h", [("rk4", 1e-3), ("kutta3", 2.5e-4)])
def test_field_string_in_a_curved_hole(method, h):
    """A field string (sections, a build-and-hold well: per-body frames, contact at every body
    and blade, mud, a cutting bit, hoisting, a BHA actuator site): the longer header, the
    per-body records and the contact-point table read as the Python step reads them."""
    step, inp, out, ref = _pair("field_deviated_3km_bha_control", method)
    m = step.sim.model
    assert m.framed and m.n > 100 and m.ip[m.ip.size - 1] == 116  # the site's joint
    n = int(round(0.05 / h))
    _run_both(step, inp, out, ref, [k * h for k in range(n)], h, np.random.default_rng(8), 1e4)
    assert ref.outputs()[m.output_names.index("bodies_in_contact")] > 0


def test_field_string_divergence_is_reported_like_python():
    """The strain guard on a curved hole (the bodies' inertial rotations, per-joint factors)."""
    step, inp, out, ref = _pair("field_deviated_3km_bha_control", "rk4")
    h = 1e-3
    for k in range(100):
        inp[:] = 0.0
        inp[0] = 5e7  # N: a bending couple far beyond the collars' elastic range
        ref.u[:] = inp
        a, b = step.step(k * h, h), ref.do_step(k * h, h)
        assert a == b
        if not a.ok:
            break
    assert not a.ok and a.quantity == "joint117.strain", a
    np.testing.assert_array_equal(_bits(step.sim.y), _bits(ref.y))


def test_refused_steps_leave_the_state_and_give_the_python_message():
    step, inp, out, ref = _pair("paper_closed_loop")
    rng = np.random.default_rng(5)
    _run_both(step, inp, out, ref, [k * 2.5e-4 for k in range(10)], 2.5e-4, rng, 1e3)
    t = step.sim.time
    y0 = step.sim.y.copy()
    out0 = out.copy()
    cases = [(t, 0.0, 0.0), (t, math.nan, 0.0), (t, -1e-3, 0.0), (t + 1e-3, 2.5e-4, 0.0),
             (math.inf, 2.5e-4, 0.0), (t, 2.5e-4, math.nan), (t, 2.5e-4, -math.inf),
             (t, 2.5e-4 * 4e6, 0.0)]
    for tt, h, bad in cases:
        inp[:] = 1.0
        inp[1] = bad if bad != 0.0 else 1.0
        ref.u[:] = inp
        a, b = step.step(tt, h), ref.do_step(tt, h)
        assert a == b and not a.ok and not a.quantity, (tt, h, bad, a)
        assert "step rejected (state unchanged)" in a.message
        np.testing.assert_array_equal(step.sim.y, y0)
        np.testing.assert_array_equal(out, out0)
    assert math.ceil(2.5e-4 * 4e6 / step.sim.max_step) > MAX_SUBSTEPS


def test_divergence_is_reported_like_python():
    step, inp, out, ref = _pair("paper_closed_loop")
    h = 2.5e-4
    for k in range(40):
        inp[:] = 0.0
        inp[0] = 5e8
        ref.u[:] = inp
        a, b = step.step(k * h, h), ref.do_step(k * h, h)
        assert a == b
        if not a.ok:
            break
    assert not a.ok and a.quantity == "joint11.strain" and a.message.startswith("diverged at t")
    np.testing.assert_array_equal(_bits(step.sim.y), _bits(ref.y))


def test_state_restore_in_place_is_seen_by_the_compiled_step():
    step, inp, out, ref = _pair("paper_closed_loop")
    rng = np.random.default_rng(6)
    _run_both(step, inp, out, ref, [k * 2.5e-4 for k in range(20)], 2.5e-4, rng, 1e3)
    saved = step.sim.get_state()
    _run_both(step, inp, out, ref, [(20 + k) * 2.5e-4 for k in range(20)], 2.5e-4, rng, 1e3)
    step.sim.set_state(saved)
    ref.set_state(saved)
    _run_both(step, inp, out, ref, [(20 + k) * 2.5e-4 for k in range(20)], 2.5e-4, rng, 1e3)


# ------------------------------------------------------------------------------ controllers
@pytest.mark.parametrize("params, n_sites", [
    (ControllerParams(gain=1e9, symmetric_force_limit=4e3, lag_time_constant=3e-3,
                      switch_on_time=0.01), 2),
    (ControllerParams(gain=5e8, mode="compressive_only", force_limit=2e3), 2),
    (ControllerParams(gain=2e8, lag_time_constant=1e-3,
                      gain_matrix=((1.0, 0.5, -0.2), (0.3, 1.0, 0.0), (0.1, -0.7, 0.9))), 3),
    (ControllerParams(enabled=False, lag_time_constant=1e-3), 2),
])
def test_strain_law_compiled_equals_python(params, n_sites):
    fast, ref = StrainController(params, n_sites), StrainController(params, n_sites)
    inp, out = np.zeros(2 * n_sites), np.zeros(2 * n_sites)
    step = fast.compiled_step(inp, out)
    rng = np.random.default_rng(7)
    codes = []
    for k, h in enumerate([1e-3] * 30 + [5e-4] * 30):
        t = k * 1e-3
        eps = rng.normal(size=inp.size) * 1e-5
        inp[:] = eps
        code = step.step(t, h)
        codes.append(code)
        want = ref.step(t, h, eps)
        if code != 0:  # left to Python (a new decay): nothing changed, the law steps
            got = fast.step(t, h, eps)
        else:
            got = out
        np.testing.assert_array_equal(_bits(got), _bits(want))
        np.testing.assert_array_equal(_bits(fast.get_state()), _bits(ref.get_state()))
    assert codes.count(0) >= 58  # all but the first step of each step size with a lag
    inp[0] = math.nan
    assert step.step(1.0, 1e-3) != 0  # refused: the Python law gives the error
    with pytest.raises(ValueError, match="non-finite strain"):
        fast.step(1.0, 1e-3, inp)


def test_top_drive_law_compiled_equals_python():
    params = TopDriveControllerParams(target_speed=3.0, ramp_time=0.05, torque_feedback=0.4)
    fast, ref = TopDriveController(params), TopDriveController(params)
    inp, out = np.zeros(2), np.zeros(1)
    step = fast.compiled_step(inp, out)
    rng = np.random.default_rng(8)
    for k in range(100):
        t = k * 1e-3 - 0.01  # also before t = 0: the ramp's max(t, 0)
        inp[:] = rng.normal(size=2) * (2.0, 1e3)
        assert step.step(t, 1e-3) == 0
        want = ref.step(t, 1e-3, float(inp[0]), float(inp[1]))
        assert _bits(out[0]) == _bits(want)
        np.testing.assert_array_equal(_bits(fast.get_state()), _bits(ref.get_state()))
    inp[1] = math.inf
    assert step.step(1.0, 1e-3) != 0


def test_an_exception_inside_the_compiled_step_is_an_internal_error():
    """numba's cfunc wrapper would print an exception and return 0 (success): the step catches
    it and returns INTERNAL, which the Python side raises (an internal error, with traceback).
    Provoked by a context whose internal step bound is 0 (a division by an exact zero)."""
    from drillcosim.plant import compiled_step as cs

    step, inp, out, ref = _pair("paper_closed_loop", "rk4")
    assert step.step(0.0, 2.5e-4).ok
    step._arrays["settings"][cs.S_MAX_STEP] = 0.0
    y = step.sim.y.copy()
    assert step._call(step.context, 2.5e-4, 2.5e-4) == cs.INTERNAL
    np.testing.assert_array_equal(step.sim.y, y)  # it raised before integrating
    with pytest.raises(RuntimeError, match="raised an exception inside its compiled code"):
        step.step(2.5e-4, 2.5e-4)


def test_a_law_compiles_only_where_numba_is_loaded_already():
    """Importing numba (~0.5 s) only for a law of a few microseconds is not worth it: a law
    alone in a process runs in Python; once numba is loaded (the plant does), it compiles."""
    import subprocess
    import sys
    import textwrap

    script = textwrap.dedent("""
        import sys
        import numpy as np
        from drillcosim.controller import StrainController
        law = StrainController()
        buf = np.zeros(4)
        print(law.compiled_step(buf, buf.copy()) is None, "numba" in sys.modules)
        import numba  # noqa: F401
        print(law.compiled_step(buf, buf.copy()) is None)
    """)
    out = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True,
                         check=True, timeout=300).stdout.split()
    assert out == ["True", "False", "False"]
