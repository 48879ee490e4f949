"""StrainController.fmu through fmpy: validation, formulas, isolation, state, errors.

The FMU is built the default way, i.e. with the native FMI wrapper
(``fmu_src/wrapper``). Error statuses (see the adapter's module docstring):

* parameter out of range -> fmi2ExitInitializationMode returns fmi2Error with a
  message (status fmi2Error) naming the parameter; every doStep then -> fmi2Error;
* NaN input, bad tunable parameter, fixed parameter changed, doStep before
  initialization -> fmi2Error from that doStep (state unchanged, instance usable);
* unknown value reference / wrong type / setting an output -> fmi2Error from that
  get/set call itself, message naming it; the next doStep is OK;
* never fmi2Fatal, and freeing an instance after any of these never crashes.
"""

from __future__ import annotations

import ctypes
import importlib.util
import json
import math
import os
import subprocess
import sys
import textwrap
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest
from fmpy import simulate_fmu
from fmpy.fmi1 import FMICallException
from fmpy.validation import validate_fmu

from drillcosim import controller
from drillcosim.fmu_src.build import PYTHONFMU_VENDORED, REGISTRY, shipped_modules
from support.fmi_logging import RecordingInstance, fmu_fixtures

ROOT = Path(__file__).resolve().parents[1]
SPEC = next(r for r in REGISTRY if r.name == "StrainController")
CANONICAL = dict(SPEC.vendored)["controller"]  # the name in the source
INPUTS = ["strain1_C", "strain1_E", "strain2_C", "strain2_E"]
OUTPUTS = ["actuator1_force_C", "actuator1_force_E", "actuator2_force_C", "actuator2_force_E"]
OK, DISCARD, ERROR, FATAL = 0, 2, 3, 4


fmu_path, md, vr, unzipdir = fmu_fixtures(SPEC)


@pytest.fixture(scope="session")
def shipped(fmu_path: Path) -> dict[str, str]:
    """Canonical module name -> the name the session build ships it under (build hash)."""
    return shipped_modules(fmu_path)


class Instance(RecordingInstance):
    """A recording FMU2Slave of this FMU."""

    def __init__(self, md, unzipdir: str) -> None:
        super().__init__(md, unzipdir, "ctl")

    def initialize(self, reals: dict[int, float] | None = None,
                   integers: dict[int, int] | None = None) -> None:
        self.fmu.setupExperiment(startTime=0.0)
        self.fmu.enterInitializationMode()
        for vr_, value in (reals or {}).items():
            self.fmu.setReal([vr_], [value])
        for vr_, value in (integers or {}).items():
            self.fmu.setInteger([vr_], [value])
        self.fmu.exitInitializationMode()


@pytest.fixture
def make(md, unzipdir) -> Iterator:
    made: list[Instance] = []

    def factory() -> Instance:
        made.append(Instance(md, unzipdir))
        return made[-1]

    yield factory
    for inst in made:  # freeInstance also unloads the library handle (ref-counted by dlopen)
        inst.fmu.freeInstance()


def run(inst: Instance, vr: dict[str, int], strains: np.ndarray, dt: float = 1e-3,
        t0: float = 0.0) -> np.ndarray:
    out = []
    ins = [vr[n] for n in INPUTS]
    outs = [vr[n] for n in OUTPUTS]
    for k, row in enumerate(strains):
        inst.fmu.setReal(ins, list(row))
        inst.fmu.doStep(t0 + k * dt, dt)
        out.append(inst.fmu.getReal(outs))
    return np.array(out)


# ------------------------------------------------------------------ model description
def test_validate_fmu_finds_no_problems(fmu_path: Path) -> None:
    assert validate_fmu(str(fmu_path)) == []


def test_model_description_interface(md) -> None:
    v = {x.name: x for x in md.modelVariables}
    for name in INPUTS:
        assert (v[name].type, v[name].causality, v[name].variability, v[name].unit,
                float(v[name].start)) == ("Real", "input", "continuous", "1", 0.0)
    for name in OUTPUTS:
        assert (v[name].type, v[name].causality, v[name].unit) == ("Real", "output", "N")
    for name in ["gain", "force_limit", "symmetric_force_limit", "switch_on_time"]:
        assert (v[name].causality, v[name].variability) == ("parameter", "tunable")
    for name in ["mode", "lag_time_constant", "enabled"]:
        assert (v[name].causality, v[name].variability) == ("parameter", "fixed")
    assert v["mode"].type == "Integer" and v["enabled"].type == "Boolean"
    assert (v["gain"].unit, v["switch_on_time"].unit, v["lag_time_constant"].unit) == (
        "N", "s", "s")
    assert all(x.description for x in md.modelVariables)
    assert float(v["gain"].start) == 1e9 and float(v["force_limit"].start) == 5000.0
    assert md.defaultExperiment.stopTime == "30.0"
    assert float(md.defaultExperiment.stepSize) == 1e-3
    assert md.coSimulation.canGetAndSetFMUstate and md.coSimulation.canSerializeFMUstate
    assert not md.coSimulation.canInterpolateInputs
    # no direct feedthrough: outputs change only in doStep
    assert all(u.dependencies == [] for u in md.outputs)


def test_fmu_ships_only_the_versioned_vendored_package(fmu_path: Path, shipped: dict[str, str]) -> None:
    vendored_name = shipped[CANONICAL]
    import zipfile

    names = zipfile.ZipFile(fmu_path).namelist()
    assert f"resources/{vendored_name}/__init__.py" in names
    assert not any(n.startswith("resources/controller/") for n in names)
    assert not any("__pycache__" in n for n in names)


# ----------------------------------------------------------------------- simulate_fmu
def input_signal(t: np.ndarray, values: np.ndarray) -> np.ndarray:
    dtype = [("time", np.float64)] + [(n, np.float64) for n in INPUTS]
    sig = np.zeros(len(t), dtype=dtype)
    sig["time"] = t
    for i, n in enumerate(INPUTS):
        sig[n] = values[:, i]
    return sig


def test_simulate_fmu_force_equals_gain_times_strain(fmu_path: Path) -> None:
    dt, n = 1e-3, 200
    t = np.arange(n + 1) * dt
    strains = 1e-6 * np.stack([np.sin(2 * np.pi * 5 * t + p) for p in range(4)], axis=1)
    res = simulate_fmu(str(fmu_path), stop_time=n * dt, step_size=dt, output_interval=dt,
                       input=input_signal(t, strains), output=OUTPUTS,
                       start_values={"gain": 2e9})
    assert len(res) == n + 1
    for i, name in enumerate(OUTPUTS):
        assert res[name][0] == 0.0  # initial exact, start 0
        # the force after doStep(t_k, dt) is gain * strain(t_k): held over the step
        np.testing.assert_allclose(res[name][1:], 2e9 * strains[:-1, i], rtol=1e-12, atol=1e-9)


def test_simulate_fmu_lag_step_response(fmu_path: Path) -> None:
    dt, n, tau = 1e-3, 300, 0.05
    t = np.arange(n + 1) * dt
    strains = np.full((n + 1, 4), 1e-6)
    res = simulate_fmu(str(fmu_path), stop_time=n * dt, step_size=dt, output_interval=dt,
                       input=input_signal(t, strains), output=OUTPUTS,
                       start_values={"lag_time_constant": tau})
    expected = 1e3 * (1.0 - np.exp(-res["time"] / tau))
    for name in OUTPUTS:
        np.testing.assert_allclose(res[name], expected, rtol=0, atol=1e-9)


def test_simulate_fmu_compressive_only_and_switch_on(fmu_path: Path) -> None:
    dt, n = 1e-3, 40
    t = np.arange(n + 1) * dt
    strains = np.tile([1e-5, -1e-5, 2e-6, 0.0], (n + 1, 1))
    res = simulate_fmu(str(fmu_path), stop_time=n * dt, step_size=dt, output_interval=dt,
                       input=input_signal(t, strains), output=OUTPUTS,
                       start_values={"mode": 1, "switch_on_time": 0.02})
    steps_before = 20  # doStep at t = 0 .. 0.019 give zero
    for name in OUTPUTS:
        assert np.all(res[name][: steps_before + 1] == 0.0)
    np.testing.assert_array_equal(res["actuator1_force_C"][steps_before + 1:], 5000.0)
    np.testing.assert_array_equal(res["actuator1_force_E"], 0.0)
    np.testing.assert_allclose(res["actuator2_force_C"][steps_before + 1:], 2000.0, rtol=1e-15)


# ------------------------------------------------------------------------- isolation
CLEAN_SCRIPT = textwrap.dedent("""
    import importlib.util, json, sys, time
    for name in ("controller", "pythonfmu", "fmu_src", "plant", "scipy", "numba"):
        assert importlib.util.find_spec(name) is None, name
    from fmpy import extract, read_model_description
    from fmpy.fmi2 import FMU2Slave
    fmu = sys.argv[1]
    md = read_model_description(fmu)
    d = extract(fmu)
    vr = {v.name: v.valueReference for v in md.modelVariables}
    t0 = time.perf_counter()
    s = FMU2Slave(guid=md.guid, unzipDirectory=d, modelIdentifier="StrainController",
                  instanceName="clean")
    s.instantiate()
    s.setupExperiment(startTime=0.0)
    s.enterInitializationMode()
    s.exitInitializationMode()
    s.setReal([vr["strain2_E"]], [-3e-6])
    s.doStep(0.0, 1e-3)
    t1 = time.perf_counter()
    force = s.getReal([vr["actuator2_force_E"]])[0]
    print(json.dumps({
        "force": force, "cold_start_s": t1 - t0,
        "vendored_file": sys.modules["%(vendored)s"].__file__, "unzipdir": str(d),
        "pythonfmu_file": sys.modules["%(pythonfmu)s"].__file__,
        "generic_pythonfmu": "pythonfmu" in sys.modules,
        "controller_imported": "controller" in sys.modules,
    }))
""")


def clean_site(tmp_path: Path) -> Path:
    """A folder exposing only numpy and fmpy (with fmpy's own dependencies)."""
    site = tmp_path / "site"
    site.mkdir()
    for mod in ("numpy", "fmpy", "attr", "attrs", "lxml"):
        spec = importlib.util.find_spec(mod)
        assert spec is not None and spec.origin is not None
        src = Path(spec.origin).parent
        (site / src.name).symlink_to(src)
    libs = Path(importlib.util.find_spec("numpy").origin).parent.parent / "numpy.libs"
    if libs.exists():
        (site / "numpy.libs").symlink_to(libs)
    return site


def test_fmu_runs_in_a_clean_python_with_only_numpy(
        fmu_path: Path, tmp_path: Path, shipped: dict[str, str]) -> None:
    vendored_name = shipped[CANONICAL]
    site = clean_site(tmp_path)
    script = tmp_path / "host.py"
    script.write_text(CLEAN_SCRIPT % {"vendored": vendored_name,
                                      "pythonfmu": shipped[PYTHONFMU_VENDORED]})
    work = tmp_path / "cwd"
    work.mkdir()
    env = {"PATH": os.environ.get("PATH", "/usr/bin:/bin"), "PYTHONPATH": str(site),
           "PYTHONNOUSERSITE": "1", "HOME": str(tmp_path)}
    proc = subprocess.run([sys.executable, "-S", "-s", str(script), str(fmu_path)], cwd=work,
                          env=env, capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    out = json.loads(proc.stdout.strip().splitlines()[-1])
    assert out["force"] == -3000.0
    assert out["vendored_file"].startswith(out["unzipdir"])
    assert out["pythonfmu_file"].startswith(out["unzipdir"])  # the FMU's own copy
    assert not out["generic_pythonfmu"]  # under its unique name only
    assert not out["controller_imported"]
    print(f"cold start (load library + instantiate + init + first doStep): "
          f"{out['cold_start_s'] * 1e3:.1f} ms")


SHADOW_SCRIPT = textwrap.dedent("""
    import importlib.util, json, sys
    order, fmu = sys.argv[1], sys.argv[2]
    from fmpy import extract, read_model_description
    from fmpy.fmi2 import FMU2Slave
    if order == "controller_first":
        from drillcosim import controller
    md = read_model_description(fmu)
    d = extract(fmu)
    s = FMU2Slave(guid=md.guid, unzipDirectory=d, modelIdentifier="StrainController",
                  instanceName="x")
    s.instantiate()
    s.setupExperiment(startTime=0.0)
    s.enterInitializationMode()
    s.exitInitializationMode()
    s.setReal([0], [1e-6])
    s.doStep(0.0, 1e-3)
    if order == "fmu_first":
        from drillcosim import controller
    print(json.dumps({
        "force": s.getReal([4])[0],
        "controller": controller.__file__,
        "vendored": sys.modules["%(vendored)s"].__file__,
        "unzipdir": str(d),
        "same_class": controller.StrainController is
                      sys.modules["%(vendored)s"].StrainController,
    }))
""")


@pytest.mark.parametrize("order", ["controller_first", "fmu_first"])
def test_no_shadowing_between_host_controller_and_vendored_copy(
        fmu_path: Path, tmp_path: Path, order: str, shipped: dict[str, str]) -> None:
    vendored_name = shipped[CANONICAL]
    script = tmp_path / "host.py"
    script.write_text(SHADOW_SCRIPT % {"vendored": vendored_name})
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    proc = subprocess.run([sys.executable, str(script), order, str(fmu_path)], cwd=tmp_path,
                          env=env, capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    out = json.loads(proc.stdout.strip().splitlines()[-1])
    assert out["force"] == 1000.0
    assert Path(out["controller"]).resolve() == (ROOT / "controller" / "__init__.py").resolve()
    # numba is installed here: the vendored copy is imported from its stable per-user copy
    # (named by content hash, for numba's cache of the compiled law), never the host's
    assert Path(out["vendored"]).parents[1].name.startswith(f"{vendored_name}-")
    assert not out["same_class"]


def test_no_shadowing_in_this_process(make, vr, shipped: dict[str, str]) -> None:
    vendored_name = shipped[CANONICAL]
    before = controller.__file__
    inst = make()
    inst.initialize()
    run(inst, vr, np.full((3, 4), 1e-6))
    assert controller.__file__ == before
    # a top-level `controller` (importable only from a checkout's root, e.g. under `python -m
    # pytest`) must never resolve into the FMU's resources/ folder
    spec = importlib.util.find_spec("controller")
    assert spec is None or "resources" not in Path(spec.origin).parts
    vendored = sys.modules[vendored_name]
    assert Path(vendored.__file__).parents[1].name.startswith(f"{vendored_name}-")  # stable copy
    assert vendored.StrainController is not controller.StrainController


# ----------------------------------------------------------------------------- state
def test_fmu_state_get_set_reproduces_run_bit_for_bit(make, vr) -> None:
    rng = np.random.default_rng(7)
    strains = rng.normal(scale=2e-6, size=(300, 4))
    inst = make()
    inst.initialize(reals={vr["lag_time_constant"]: 0.02, vr["switch_on_time"]: 0.05})
    run(inst, vr, strains[:100])
    state = inst.fmu.getFMUstate()
    first = run(inst, vr, strains[100:], t0=0.1)
    inst.fmu.setFMUstate(state)
    second = run(inst, vr, strains[100:], t0=0.1)
    assert np.array_equal(first, second)
    assert np.any(first != 0.0)
    inst.fmu.freeFMUstate(state)


def test_serialized_state_restores_lag_and_parameters_in_another_instance(make, vr) -> None:
    rng = np.random.default_rng(3)
    strains = rng.normal(scale=2e-6, size=(200, 4))
    a = make()
    a.initialize(reals={vr["lag_time_constant"]: 0.03, vr["gain"]: 3e9})
    run(a, vr, strains[:100])
    blob = a.fmu.serializeFMUstate(a.fmu.getFMUstate())
    first = run(a, vr, strains[100:], t0=0.1)

    b = make()
    b.initialize(reals={vr["lag_time_constant"]: 0.03, vr["gain"]: 1.0})  # other gain
    state = b.fmu.deSerializeFMUstate(blob)
    b.fmu.setFMUstate(state)
    second = run(b, vr, strains[100:], t0=0.1)
    assert np.array_equal(first, second)
    assert b.fmu.getReal([vr["gain"]]) == [3e9]


def test_instances_are_independent(make, vr) -> None:
    a, b = make(), make()
    a.initialize(reals={vr["gain"]: 1e9, vr["lag_time_constant"]: 0.01})
    b.initialize(reals={vr["gain"]: 2e9, vr["lag_time_constant"]: 0.02})
    for k in range(20):
        fa = run(a, vr, np.full((1, 4), 1e-6), t0=k * 1e-3)[0]
        fb = run(b, vr, np.full((1, 4), 1e-6), t0=k * 1e-3)[0]
    t = 20e-3
    np.testing.assert_allclose(fa, 1e3 * (1 - math.exp(-t / 0.01)), rtol=1e-12)
    np.testing.assert_allclose(fb, 2e3 * (1 - math.exp(-t / 0.02)), rtol=1e-12)


# ------------------------------------------------------------------------- parameters
def test_tunable_gain_change_between_steps(make, vr) -> None:
    inst = make()
    inst.initialize()
    assert run(inst, vr, np.full((1, 4), 1e-6))[0].tolist() == [1000.0] * 4
    inst.fmu.setReal([vr["gain"]], [5e8])
    assert run(inst, vr, np.full((1, 4), 1e-6), t0=1e-3)[0].tolist() == [500.0] * 4


def test_invalid_tunable_parameter_between_steps_is_an_error(make, vr) -> None:
    inst = make()
    inst.initialize()
    run(inst, vr, np.full((1, 4), 1e-6))
    inst.fmu.setReal([vr["force_limit"]], [float("nan")])
    with pytest.raises(FMICallException) as info:
        inst.fmu.doStep(1e-3, 1e-3)
    assert info.value.status == ERROR
    assert [m for s, m in inst.messages if s == ERROR and "force_limit = nan" in m]
    inst.fmu.setReal([vr["force_limit"]], [100.0])
    inst.fmu.doStep(1e-3, 1e-3)  # usable again (raises on any non-OK status)
    assert inst.fmu.getReal([vr["actuator1_force_C"]]) == [1000.0]  # the step ran: 1e9 * 1e-6


def test_fixed_parameter_change_after_initialization_is_an_error(make, vr) -> None:
    inst = make()
    inst.initialize()
    with pytest.raises(FMICallException) as info:  # the set itself; nothing set
        inst.fmu.setInteger([vr["mode"]], [1])
    assert info.value.status == ERROR
    assert [m for s, m in inst.messages if s == ERROR and "mode (value reference "
            f"{vr['mode']}) is a fixed parameter" in m]
    assert inst.fmu.getInteger([vr["mode"]]) == [0]
    inst.fmu.doStep(0.0, 1e-3)  # the instance steps on


@pytest.mark.parametrize(
    ("name", "value", "fragment"),
    [
        ("gain", -1.0, "gain = -1.0 is out of range; allowed: 0 <= gain < inf"),
        ("gain", float("nan"), "gain = nan"),
        ("lag_time_constant", -0.1, "lag_time_constant = -0.1"),
        ("switch_on_time", float("inf"), "switch_on_time = inf"),
        ("force_limit", -1.0, "force_limit = -1.0"),
        ("mode", 2, "mode = 2 is not allowed"),
    ],
)
def test_parameter_out_of_range_fails_initialization_with_message(
        make, vr, name: str, value: float, fragment: str) -> None:
    inst = make()
    inst.fmu.setupExperiment(startTime=0.0)
    inst.fmu.enterInitializationMode()
    if name == "mode":
        inst.fmu.setInteger([vr[name]], [value])
    else:
        inst.fmu.setReal([vr[name]], [value])
    with pytest.raises(FMICallException) as info:
        inst.fmu.exitInitializationMode()
    assert info.value.status == ERROR
    assert [(s, m) for s, m in inst.messages if fragment in m and s == ERROR], inst.messages
    assert "invalid parameter" in inst.text()
    for _ in range(2):  # never a silent run: every step fails
        with pytest.raises(FMICallException) as info:
            inst.fmu.doStep(0.0, 1e-3)
        assert info.value.status == ERROR


def test_reset_after_invalid_parameters_allows_a_valid_run(make, vr) -> None:
    inst = make()
    with pytest.raises(FMICallException) as info:
        inst.initialize(reals={vr["gain"]: -5.0})
    assert info.value.status == ERROR
    inst.fmu.reset()  # FMI 2.0: after fmi2Error only reset / free / set state
    inst.initialize(reals={vr["gain"]: 5.0})
    assert run(inst, vr, np.full((1, 4), 0.5))[0].tolist() == [2.5] * 4


# ------------------------------------------------------------------------- bad calls
def test_nan_input_is_an_error_and_keeps_state(make, vr) -> None:
    strains = np.full((10, 4), 1e-6)
    ref = make()
    ref.initialize(reals={vr["lag_time_constant"]: 0.01})
    expected = run(ref, vr, strains)

    inst = make()
    inst.initialize(reals={vr["lag_time_constant"]: 0.01})
    run(inst, vr, strains[:5])
    inst.fmu.setReal([vr["strain1_E"]], [float("nan")])
    with pytest.raises(FMICallException) as info:
        inst.fmu.doStep(5e-3, 1e-3)
    assert info.value.status == ERROR
    assert "strain1_E" in inst.text() and "t = 0.005" in inst.text()
    assert any(status == ERROR for status, _ in inst.messages)  # logged with error status
    got = run(inst, vr, strains[5:], t0=5e-3)  # retry with a valid input
    assert np.array_equal(got, expected[5:])


def test_do_step_before_initialization_is_an_error_status(make) -> None:
    inst = make()
    with pytest.raises(FMICallException) as info:
        inst.fmu.doStep(0.0, 1e-3)
    assert info.value.status == ERROR
    assert [m for s, m in inst.messages if s == ERROR and "before initialization" in m]
    inst.initialize()  # the instance is still usable
    inst.fmu.doStep(0.0, 1e-3)


@pytest.mark.parametrize(
    ("call", "args", "fragment"),
    [
        ("getReal", ([999],), "getReal: unknown value reference 999"),
        ("setReal", ([999], [1.0]), "setReal: unknown value reference 999"),
        ("getInteger", ([999],), "getInteger: unknown value reference 999"),
        ("getBoolean", ([999],), "getBoolean: unknown value reference 999"),
        ("getInteger", ([8],), "value reference 8 (gain) is not of type Integer"),
        ("setReal", ([4], [1.0]), "actuator1_force_C (value reference 4) is an output"),
    ],
)
def test_bad_value_reference_is_an_error_of_that_call(
        make, call: str, args: tuple, fragment: str) -> None:
    inst = make()
    inst.initialize()
    with pytest.raises(FMICallException) as info:
        getattr(inst.fmu, call)(*args)
    assert info.value.status == ERROR
    assert [(s, m) for s, m in inst.messages if fragment in m and s == ERROR], inst.messages
    inst.fmu.doStep(0.0, 1e-3)  # no deferred failure: the next step is OK
    assert "an earlier call failed" not in inst.text()


def test_mixed_valid_and_unknown_references_in_one_call(make, vr) -> None:
    inst = make()
    inst.initialize()
    refs = (ctypes.c_uint * 3)(vr["gain"], 12345, vr["force_limit"])
    values = (ctypes.c_double * 3)()
    status = inst.fmu.dll.fmi2GetReal(inst.fmu.component, refs, 3, values)  # raw: no raise
    assert status == ERROR
    assert values[0] == 1e9 and math.isnan(values[1]) and values[2] == 5000.0


FREE_SCRIPT = textwrap.dedent("""
    import gc, json, os, sys
    from fmpy import extract, read_model_description
    from fmpy.fmi1 import FMICallException
    from fmpy.fmi2 import FMU2Slave
    fmu = sys.argv[1]
    md = read_model_description(fmu)
    d = extract(fmu)
    def call(f, *args):
        try:
            f(*args)
            return 0
        except FMICallException as exc:
            return int(exc.status)
    statuses = {"exit": [], "get_set": [], "step": []}
    for i in range(12):
        s = FMU2Slave(guid=md.guid, unzipDirectory=d, modelIdentifier="StrainController",
                      instanceName=f"i{i}")
        s.instantiate()
        s.setupExperiment(startTime=0.0)
        s.enterInitializationMode()
        s.setReal([8], [-1.0 if i % 2 else 1.0])   # invalid gain on odd instances
        exit_status = call(s.exitInitializationMode)
        statuses["exit"].append(exit_status)
        statuses["get_set"].append([call(s.getReal, [999]), call(s.setReal, [999], [0.0]),
                                    call(s.getInteger, [8])])
        s.setReal([0], [float("nan")])
        statuses["step"].append([call(s.doStep, 0.0, 1e-3) for _ in range(3)])
        if exit_status == 0:  # FMI 2.0: no fmi2Terminate after an fmi2Error
            s.terminate()
        s.freeInstance()
        gc.collect()
    print(json.dumps(statuses), flush=True)
""")


def test_error_paths_then_free_instance_never_crash(fmu_path: Path, tmp_path: Path) -> None:
    """Errors, then free: fmi2Error as documented, never Fatal, never a crash (heap checked).

    Regression for pythonfmu 0.7.0's binary, which released an instance's Python objects
    twice after an exception (its fallback build is gone; our wrapper runs every FMU).
    """
    script = tmp_path / "free.py"
    script.write_text(FREE_SCRIPT)
    proc = subprocess.run([sys.executable, str(script), str(fmu_path)],
                          cwd=tmp_path, capture_output=True, text=True, timeout=120,
                          env=dict(os.environ, MALLOC_CHECK_="3"))
    assert proc.returncode == 0, proc.stderr[-2000:]
    st = json.loads(proc.stdout.strip().splitlines()[-1])
    assert st["exit"] == [ERROR if i % 2 else OK for i in range(12)]
    assert st["get_set"] == [[ERROR] * 3] * 12
    assert st["step"] == [[ERROR] * 3] * 12  # NaN input, or not initialised
