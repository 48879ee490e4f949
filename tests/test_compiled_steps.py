"""Compiled steps through the FMUs (fmpy): the plant, the strain controller (SISO, gain matrix,
saturation, lag, switch-on) and the top-drive controller give the same outputs, statuses and
messages, bit for bit, with their compiled step (``DRILLCOSIM_COMPILED_STEP=1``, the default:
``fmi2DoStep`` calls a numba cfunc through the wrapper without entering Python) and with it
switched off (``=0``: the Python ``do_step``, the reference).

Each case is a script of FMI calls (parameters, inputs, steps, a non-finite input, FMU state
saved, serialized and restored mid-run, tunable parameters changed mid-run) run once each way;
besides the outputs, the test counts the Python ``do_step`` calls and the wrapper's failure
calls (``_fmi2_compiled_step_failed``) by patching the slave class in this process: with the
compiled step the steps stay out of Python except the few the protocol sends there (the first
step of a step size, a step after a parameter change, a refused step).
"""

from __future__ import annotations

import math
import shutil
import sys
from pathlib import Path

import numpy as np
import pytest
from fmpy import extract, read_model_description
from fmpy.fmi1 import FMICallException

from drillcosim.cosim.scenario.config import load_config
from drillcosim.cosim.scenario.scene_fmus import built_for_scene, controller_recipe, plant_recipe
from drillcosim.fmu_src.build import build_one
from drillcosim.plant.model import DrillstringModel
from drillcosim.plant.scene import load_scene
from support.fmi_logging import RecordingCallbacks

pytestmark = [pytest.mark.needs_cc]

H = 2.5e-4  # s, the closed loop's step


class Counter:
    """Counts calls of a slave class's Python step paths (patched in this process)."""

    def __init__(self, monkeypatch: pytest.MonkeyPatch, cls: type) -> None:
        self.python = 0
        self.failed = 0
        do_step, failed = cls.do_step, cls._fmi2_compiled_step_failed

        def counted_do_step(obj, t, h):
            self.python += 1
            return do_step(obj, t, h)

        def counted_failed(obj, code, t, h):
            self.failed += 1
            return failed(obj, code, t, h)

        monkeypatch.setattr(cls, "do_step", counted_do_step)
        monkeypatch.setattr(cls, "_fmi2_compiled_step_failed", counted_failed)


def run_script(fmu: Path, compiled: bool, script: list, monkeypatch: pytest.MonkeyPatch) -> dict:
    """Run ``script`` on a fresh instance; the statuses, outputs and messages of every step.

    Actions: ``("set", {name: value})``, ``("init",)``, ``("step", t, h)``, ``("save",)``,
    ``("restore",)`` (the saved state, serialized and deserialized first).
    """
    from fmpy.fmi2 import FMU2Slave

    monkeypatch.setenv("DRILLCOSIM_COMPILED_STEP", "1" if compiled else "0")
    md = read_model_description(str(fmu))
    var = {v.name: v for v in md.modelVariables}
    outs = [v.valueReference for v in md.modelVariables if v.causality == "output"]
    unzip = extract(str(fmu))
    rec = RecordingCallbacks()
    s = FMU2Slave(guid=md.guid, unzipDirectory=unzip,
                  modelIdentifier=md.coSimulation.modelIdentifier, instanceName="x")
    s.instantiate(callbacks=rec.callbacks, loggingOn=True)
    res = Path(unzip) / "resources"
    cls = getattr(sys.modules[(res / "slavemodule.txt").read_text().strip()],
                  (res / "slaveclass.txt").read_text().strip())
    count = Counter(monkeypatch, cls)
    steps, saved = [], None
    try:
        for action in script:
            kind = action[0]
            if kind == "set":
                for name, value in action[1].items():
                    v = var[name]
                    setter = {"Real": s.setReal, "Integer": s.setInteger,
                              "Boolean": s.setBoolean, "String": s.setString}[v.type]
                    setter([v.valueReference], [value])
            elif kind == "init":
                s.setupExperiment(startTime=0.0)
                s.enterInitializationMode()
                s.exitInitializationMode()
            elif kind == "step":
                status = 0
                try:
                    s.doStep(action[1], action[2])
                except FMICallException as exc:
                    status = exc.status
                steps.append((status, s.getReal(outs)))
            elif kind == "save":
                saved = s.serializeFMUstate(s.getFMUstate())
            elif kind == "restore":
                state = s.deSerializeFMUstate(saved)
                s.setFMUstate(state)
                s.freeFMUstate(state)
        s.terminate()
    finally:
        s.freeInstance()
        shutil.rmtree(unzip, ignore_errors=True)
    n_steps = sum(1 for a in script if a[0] == "step")
    messages = [(st, m) for st, m in rec.messages if st > 0]
    return {"steps": steps, "messages": messages, "python": count.python,
            "failed": count.failed, "n": n_steps}


def assert_same(fmu: Path, script: list, monkeypatch, max_python: int) -> dict:
    """Both paths equal bit for bit; the compiled one stays out of Python but ``max_python``
    steps (Python do_step calls plus failure calls); the reference runs every step in Python."""
    fast = run_script(fmu, True, script, monkeypatch)
    ref = run_script(fmu, False, script, monkeypatch)
    assert [st for st, _ in fast["steps"]] == [st for st, _ in ref["steps"]]
    a = np.array([o for _, o in fast["steps"]])
    b = np.array([o for _, o in ref["steps"]])
    np.testing.assert_array_equal(a.view(np.int64), b.view(np.int64))  # the bits, -0.0 too
    assert fast["messages"] == ref["messages"]
    assert ref["python"] == ref["n"] and ref["failed"] == 0
    assert fast["python"] + fast["failed"] <= max_python, (fast["python"], fast["failed"])
    assert np.ptp(a, axis=0).max() > 0  # something happened
    return fast


def _inputs(fmu: Path) -> list[str]:
    return [v.name for v in read_model_description(str(fmu)).modelVariables
            if v.causality == "input"]


def _steps(names: list[str], n: int, scale, seed: int, t0: float = 0.0, h: float = H) -> list:
    rng = np.random.default_rng(seed)
    out = []
    for k in range(n):
        out.append(("set", dict(zip(names, (rng.normal(size=len(names)) * scale).tolist()))))
        out.append(("step", t0 + k * h, h))
    return out


# ----------------------------------------------------------------------------------- plant
def test_plant_compiled_equals_python_with_state_restore_and_a_bad_input(project_fmus,
                                                                        monkeypatch) -> None:
    fmu = project_fmus["DrillstringPlant"]
    names = _inputs(fmu)
    script = [("set", {"scene": "paper_closed_loop"}), ("init",)]
    script += _steps(names, 120, 2e3, 1)
    script += [("save",)]
    script += _steps(names, 60, 2e3, 2, t0=120 * H)
    # a non-finite input: fmi2Error, state unchanged; the retry continues as if it never was
    script += [("set", {names[1]: math.nan}), ("step", 180 * H, H)]
    script += _steps(names, 40, 2e3, 3, t0=180 * H)
    script += [("restore",)]
    script += _steps(names, 60, 2e3, 4, t0=120 * H)
    fast = assert_same(fmu, script, monkeypatch, max_python=3)
    statuses = [st for st, _ in fast["steps"]]
    assert statuses.count(3) == 1 and statuses[180] == 3  # fmi2Error, the bad input only
    assert fast["steps"][179][1] == fast["steps"][180][1]  # outputs unchanged
    assert "is not finite at t = " in fast["messages"][0][1]
    assert "step rejected (state unchanged)" in fast["messages"][0][1]


def test_plant_divergence_is_discarded_naming_time_and_quantity(project_fmus,
                                                                 monkeypatch) -> None:
    fmu = project_fmus["DrillstringPlant"]
    names = _inputs(fmu)
    script = [("set", {"scene": "paper_closed_loop"}), ("init",)]
    script += _steps(names, 20, 1e3, 5)
    script += [("save",)]
    script += [("set", {names[0]: 5e8}), *[("step", (20 + k) * H, H) for k in range(40)]]
    script += [("restore",)]
    script += _steps(names, 10, 1e3, 6, t0=20 * H)
    fast = assert_same(fmu, script, monkeypatch, max_python=45)
    statuses = [st for st, _ in fast["steps"]]
    first = statuses.index(2)  # fmi2Discard
    assert 20 < first < 60 and set(statuses[first:60]) == {2}  # and every step after it
    assert set(statuses[60:]) == {0}  # until a state saved before is restored
    text = fast["messages"][0][1]
    assert "discarded: diverged at t = " in text and "quantity " in text, text
    assert all("the simulation diverged earlier" in m for _, m in fast["messages"][1:])


@pytest.fixture(scope="module")
def variant_fmus(tmp_path_factory) -> dict[str, Path]:
    """Plant variants: the torque-driven axial-torsional chain (aux states, an input that is not
    the model's first), the linear time-invariant pulse scene (exponential Euler, load switch
    times inside steps) and a field string in a curved hole (sections, per-body frames and
    records, contact at every body, mud, a cutting bit, a BHA site); a two-site controller
    with a gain matrix."""
    out = tmp_path_factory.mktemp("compiled_variants")
    pulse = out / "pulse_chain.toml"  # the axial-torsional chain only: its own FMU
    pulse.write_text('extends = "table1_axial_pulse"\nmodel = "axial_torsional"\n\n'
                     '[contact]\nbodies = [10, 20]\n')
    fmus = {}
    for key, scene in (("stick_slip_soft_torque", "stick_slip_soft_torque"),
                       ("pulse_chain", pulse), ("field", "field_deviated_3km_bha_control")):
        recipe = plant_recipe(load_scene(scene))
        assert built_for_scene(recipe)  # a variant
        fmus[key] = build_one(recipe, out)
    fmus["pulse_chain_scene"] = pulse
    mimo = load_config("paper_closed_loop",
                       {"controller.gain_matrix": [[1.0, -0.4], [0.3, 0.8]]})
    recipe = controller_recipe(mimo.controller, mimo.scene, 2)
    fmus["mimo"] = build_one(recipe, out)
    return fmus


def test_plant_variants_compiled_equal_python(variant_fmus, monkeypatch) -> None:
    torque = variant_fmus["stick_slip_soft_torque"]
    script = [("init",)] + _steps(_inputs(torque), 300, 2e3, 7, h=1e-3)
    assert_same(torque, script, monkeypatch, max_python=1)
    # exponential Euler: the first step of a step size builds its operator in Python, and a
    # step with a load switch inside runs there too (its parts need other operators)
    pulse = variant_fmus["pulse_chain"]
    sc = load_scene(variant_fmus["pulse_chain_scene"])
    assert DrillstringModel(sc.plant, sc.model).default_method == "expeuler"  # (LTI)
    switches = sorted(t for ld in sc.plant.loads for t in (ld.start, ld.start + ld.duration))
    h = 7e-4  # not a divisor of the switch times: they fall inside steps
    n = int(math.ceil((switches[-1] + 0.01) / h))
    inside = sum(1 for b in switches if any(k * h < b < (k + 1) * h for k in range(n)))
    assert inside >= 1  # the pulse starts at 0 and ends inside a step
    fast = assert_same(pulse, [("init",)] + [("step", k * h, h) for k in range(n)], monkeypatch,
                       max_python=1 + 2 * inside)
    assert fast["failed"] >= 1 + inside


def test_field_plant_compiled_equals_python(variant_fmus, monkeypatch) -> None:
    """The field scene's FMU: its first step picks the method in Python (RK4 at 1 ms), the
    others run compiled; then at 0.25 ms (Kutta's method) after one more Python step."""
    fmu = variant_fmus["field"]
    names = _inputs(fmu)
    assert names == ["actuator1_force_C", "actuator1_force_E"]
    script = [("init",)] + _steps(names, 100, 1e4, 9, h=1e-3)
    script += _steps(names, 200, 1e4, 10, t0=0.1, h=H)
    assert_same(fmu, script, monkeypatch, max_python=2)


# ----------------------------------------------------------------------------- controllers
def test_strain_controller_siso_lag_saturation_switch_on(project_fmus, monkeypatch) -> None:
    fmu = project_fmus["StrainController"]
    names = _inputs(fmu)
    script = [("set", {"lag_time_constant": 5e-3, "switch_on_time": 0.02,
                       "symmetric_force_limit": 3e3}), ("init",)]
    script += _steps(names, 200, 1e-5, 8, h=1e-3)
    script += [("save",)]
    script += [("set", {"gain": 4e8, "switch_on_time": 0.25})]  # tunable: through Python once
    script += _steps(names, 100, 1e-5, 9, t0=0.2, h=1e-3)
    script += [("set", {names[2]: math.inf}), ("step", 0.3, 1e-3)]  # fmi2Error, unchanged
    script += _steps(names, 50, 1e-5, 10, t0=0.3, h=5e-4)  # a new step size: a new decay
    script += [("restore",)]
    script += _steps(names, 50, 1e-5, 11, t0=0.2, h=1e-3)
    fast = assert_same(fmu, script, monkeypatch, max_python=8)
    assert [st for st, _ in fast["steps"]].count(3) == 1
    assert "non-finite strain in channel(s) strain2_C" in fast["messages"][0][1]


def test_strain_controller_compressive_only(project_fmus, monkeypatch) -> None:
    fmu = project_fmus["StrainController"]
    script = [("set", {"mode": 1, "force_limit": 2e3}), ("init",)]
    script += _steps(_inputs(fmu), 300, 1e-5, 12, h=1e-3)
    fast = assert_same(fmu, script, monkeypatch, max_python=0)
    forces = np.array([o for _, o in fast["steps"]])
    assert forces.min() == 0.0 and forces.max() == 2e3  # both limits reached


def test_strain_controller_gain_matrix(variant_fmus, monkeypatch) -> None:
    fmu = variant_fmus["mimo"]
    script = [("set", {"lag_time_constant": 2e-3}), ("init",)]
    script += _steps(_inputs(fmu), 200, 1e-6, 13, h=H)
    script += [("set", {"gain_matrix_1_2": 0.7})]
    script += _steps(_inputs(fmu), 100, 1e-6, 14, t0=200 * H, h=H)
    # the first step (a new lag decay) and the one after the parameter change run in Python
    fast = assert_same(fmu, script, monkeypatch, max_python=3)
    assert (fast["python"], fast["failed"]) == (2, 1)


def test_top_drive_controller(project_fmus, monkeypatch) -> None:
    fmu = project_fmus["TopDriveController"]
    names = _inputs(fmu)
    script = [("set", {"ramp_time": 0.1, "torque_feedback": 0.3}), ("init",)]
    script += _steps(names, 150, np.array([2.0, 1e3]), 15, h=1e-3)
    script += [("save",), ("set", {"p_gain": 600.0})]
    script += _steps(names, 100, np.array([2.0, 1e3]), 16, t0=0.15, h=1e-3)
    script += [("set", {names[0]: math.nan}), ("step", 0.25, 1e-3)]
    script += [("restore",)] + _steps(names, 50, np.array([2.0, 1e3]), 17, t0=0.15, h=1e-3)
    fast = assert_same(fmu, script, monkeypatch, max_python=4)
    assert "non-finite input: top_rotary_speed = nan" in fast["messages"][0][1]


def test_pd_strain_controller(project_fmus, monkeypatch) -> None:
    fmu = project_fmus["PDStrainController"]
    names = _inputs(fmu)
    script = [("set", {"gain": 2e8, "derivative_gain": 3e5, "derivative_time_constant": 2e-3,
                       "lag_time_constant": 1e-3, "symmetric_force_limit": 4e3}), ("init",)]
    script += _steps(names, 200, 1e-5, 18, h=1e-3)
    script += [("save",), ("set", {"derivative_gain": 1e5})]
    script += _steps(names, 100, 1e-5, 19, t0=0.2, h=1e-3)
    script += [("set", {names[1]: math.inf}), ("step", 0.3, 1e-3)]
    script += [("restore",)] + _steps(names, 50, 1e-5, 20, t0=0.2, h=5e-4)
    fast = assert_same(fmu, script, monkeypatch, max_python=6)
    assert "non-finite strain in channel(s) strain1_E" in fast["messages"][0][1]


def test_ztorque_controller(project_fmus, monkeypatch) -> None:
    fmu = project_fmus["ZTorqueController"]
    names = _inputs(fmu)
    script = [("set", {"ramp_time": 0.1, "torque_factor": 0.5, "highpass_time_constant": 0.5}),
              ("init",)]
    script += _steps(names, 150, np.array([2.0, 1e3]), 21, h=1e-3)
    script += [("save",), ("set", {"impedance": 600.0})]
    script += _steps(names, 100, np.array([2.0, 1e3]), 22, t0=0.15, h=1e-3)
    script += [("set", {names[1]: math.nan}), ("step", 0.25, 1e-3)]
    script += [("restore",)] + _steps(names, 50, np.array([2.0, 1e3]), 23, t0=0.15, h=1e-3)
    # in Python: the first step (a new high-pass decay), the step after the parameter change,
    # the refused one and the first after the restore
    fast = assert_same(fmu, script, monkeypatch, max_python=6)
    assert "non-finite input: top_rotary_speed" in fast["messages"][0][1]


def test_every_entry_points_source_is_its_template() -> None:
    """numba writes each compiled law's type annotations (read with ``inspect.getsource``) into
    its cache: the source Python finds for an entry point must be the template it was compiled
    from, a ``def`` of its own name, on every Python (3.12's tokenizer raises a TokenError on a
    block that starts inside a docstring, where 3.11's did not)."""
    import inspect

    from drillcosim.controller import compiled

    key = compiled._sources_key()
    for kind in compiled.ENTRIES:
        entry = compiled._entry(kind, key)
        lines, first = inspect.getsourcelines(entry)
        assert lines[0].startswith("def {name}("), (kind, first, lines[:2])
        assert first == entry.__code__.co_firstlineno
