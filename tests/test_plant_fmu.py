"""DrillstringPlant.fmu through fmpy: validation, second implementation, isolation, errors.

The FMU is built the default way, i.e. with the native FMI wrapper
(``fmu_src/wrapper``). Error statuses (see the adapter's module docstring):

* parameter out of range / missing outputs -> fmi2ExitInitializationMode returns
  fmi2Error, message (status fmi2Error) naming it; a doStep after that -> fmi2Error;
* NaN input, doStep before initialization -> fmi2Error, state unchanged;
* divergence -> fmi2Discard naming time and quantity, and for every later doStep
  until a saved state is restored;
* unknown value reference -> fmi2Error from that getReal, naming it; next doStep OK;
* never fmi2Fatal.

Misuse cases run in subprocesses so that a crash would show as a failed exit code.
They follow FMI 2.0's state machine at the end: after an fmi2Error the instance is
freed without fmi2Terminate.
"""

from __future__ import annotations

import importlib.util
import json
import os
import subprocess
import sys
import textwrap
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest
from fmpy import simulate_fmu
from fmpy.validation import validate_fmu

from drillcosim import plant
from drillcosim.fmu_src.build import PYTHONFMU_VENDORED, REGISTRY, shipped_modules
from drillcosim.plant.model import DrillstringModel
from drillcosim.plant.params import PlantParams
from drillcosim.plant.scene import SECTIONS, load_scene
from drillcosim.plant.simulator import PlantSimulator
from support.fmi_logging import RecordingInstance, fmu_fixtures

ROOT = Path(__file__).resolve().parents[1]
SPEC = next(s for s in REGISTRY if s.name == "DrillstringPlant")
CANONICAL = dict(SPEC.vendored)["plant"]  # the name in the source
INPUTS = ["actuator1_force_C", "actuator1_force_E", "actuator2_force_C", "actuator2_force_E"]
OK, DISCARD, ERROR, FATAL = 0, 2, 3, 4
DT = 1e-3
#: Subprocesses use one BLAS thread: OpenBLAS's spinning threads on this shared, often
#: oversubscribed 2-core machine made a model build (eigh/eigvals) 10x slower (8 s vs 0.8 s).
SUBPROCESS_ENV = dict(os.environ, OPENBLAS_NUM_THREADS="1")


def cache_root() -> Path:
    """Where the adapter keeps its stable package copy (mirrors ``cache_root`` there)."""
    if os.environ.get("DRILLCOSIM_CACHE"):
        return Path(os.environ["DRILLCOSIM_CACHE"])
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(base) / "drillcosim"


def reference(scene: str = "paper_open_loop", overrides: dict | None = None) -> PlantSimulator:
    """The second implementation: plant.simulator on the same scene (full 3D)."""
    sc = load_scene(scene, folder=ROOT / "scenes",
                    overrides={"model": "full3d", **(overrides or {})})
    return PlantSimulator(DrillstringModel(sc.plant, sc.model))


fmu_path, md, vr, unzipdir = fmu_fixtures(SPEC)


@pytest.fixture(scope="session")
def shipped(fmu_path: Path) -> dict[str, str]:
    """Canonical module name -> the name the session build ships it under (build hash)."""
    return shipped_modules(fmu_path)


@pytest.fixture(scope="session")
def outputs(md) -> list[str]:
    return [v.name for v in md.modelVariables if v.causality == "output"]


class Instance(RecordingInstance):
    """A recording FMU2Slave of this FMU."""

    def __init__(self, md, unzipdir: str) -> None:
        super().__init__(md, unzipdir, "plant")
        self.vr = {v.name: v.valueReference for v in md.modelVariables}
        self.outs = [v.valueReference for v in md.modelVariables if v.causality == "output"]

    def initialize(self, **values) -> None:
        self.fmu.setupExperiment(startTime=0.0)
        self.fmu.enterInitializationMode()
        for name, value in values.items():
            setter = {str: self.fmu.setString, int: self.fmu.setInteger,
                      bool: self.fmu.setBoolean}.get(type(value), self.fmu.setReal)
            setter([self.vr[name]], [value])
        self.fmu.exitInitializationMode()

    def run(self, forces: np.ndarray, t0: float = 0.0) -> np.ndarray:
        ins = [self.vr[n] for n in INPUTS]
        rows = []
        for k, row in enumerate(forces):
            self.fmu.setReal(ins, list(row))
            self.fmu.doStep(t0 + k * DT, DT)
            rows.append(self.fmu.getReal(self.outs))
        return np.array(rows)


@pytest.fixture
def make(md, unzipdir) -> Iterator:
    made: list[Instance] = []

    def factory() -> Instance:
        made.append(Instance(md, unzipdir))
        return made[-1]

    yield factory
    for inst in made:
        inst.fmu.freeInstance()


def forces_signal(n: int) -> np.ndarray:
    t = np.arange(n) * DT
    return 200.0 * np.stack([np.sin(2 * np.pi * 3 * t + p) for p in range(4)], axis=1)


# ------------------------------------------------------------------ model description
def test_validate_fmu_finds_no_problems(fmu_path: Path) -> None:
    assert validate_fmu(str(fmu_path)) == []


def test_interface_matches_the_plant_model(md) -> None:
    v = {x.name: x for x in md.modelVariables}
    model = DrillstringModel(load_scene("paper_open_loop").plant, "full3d")
    names = [x.name for x in md.modelVariables if x.causality == "output"]
    assert names == model.output_names
    for name in names:
        assert v[name].unit == model.output_units[name].replace(" ", ".")
        assert v[name].initial in (None, "calculated") and v[name].description
    for name in INPUTS:
        assert (v[name].type, v[name].causality, v[name].unit, float(v[name].start)) == (
            "Real", "input", "N", 0.0)
    assert (v["scene"].type, v["scene"].start) == ("String", "paper_open_loop")
    assert (v["model"].type, v["model"].start) == ("String", "full3d")
    assert (v["max_internal_step"].unit, float(v["max_internal_step"].start)) == ("s", 0.0)
    # every scalar PlantParams field, start = default, unit from the metadata
    defaults = PlantParams()
    for section in SECTIONS:
        if getattr(defaults, section) is None:  # [trajectory]: tables only, none by default
            assert not any(name.startswith(f"{section}.") for name in v)
            continue
        for field_name, default in vars(getattr(defaults, section)).items():
            if isinstance(default, (tuple, str)):
                assert f"{section}.{field_name}" not in v  # scene-only
                continue
            var = v[f"{section}.{field_name}"]
            assert (var.causality, var.variability) == ("parameter", "fixed")
            start = {"true": True, "false": False}.get(var.start, var.start)
            assert type(default)(float(start) if var.type != "Boolean" else start) == default
    assert v["pipe.n_segments"].type == "Integer" and v["contact.enabled"].type == "Boolean"
    assert (v["pipe.density"].unit, v["contact.stiffness"].unit, v["gravity"].unit) == (
        "kg/m3", "N/m", "m/s2")
    assert v["top_drive.torsional_stiffness"].start == "INF"
    assert float(md.defaultExperiment.stopTime) == 30.0
    assert float(md.defaultExperiment.stepSize) == 1e-3
    assert md.coSimulation.canGetAndSetFMUstate and md.coSimulation.canSerializeFMUstate
    assert all(u.dependencies == [] for u in md.outputs)  # no direct feedthrough


def test_fmu_ships_scenes_and_only_the_versioned_package(fmu_path: Path, shipped: dict[str, str]) -> None:
    vendored_name = shipped[CANONICAL]
    import zipfile

    names = zipfile.ZipFile(fmu_path).namelist()
    for scene in (ROOT / "scenes").glob("*.toml"):
        assert f"resources/scenes/{scene.name}" in names
    assert f"resources/{vendored_name}/__init__.py" in names
    assert not any(n.startswith("resources/plant/") or "__pycache__" in n for n in names)
    # controller matrices beside the scenes are not the plant's (recipe exclude scenes/*.json)
    assert not any(n.startswith("resources/scenes/") and n.endswith(".json") for n in names)


# ------------------------------------------------------------ second implementation
def test_simulate_fmu_equals_plant_simulator(fmu_path: Path, outputs: list[str]) -> None:
    n = 500
    res = simulate_fmu(str(fmu_path), stop_time=n * DT, step_size=DT, output_interval=DT,
                       output=outputs)
    sim = reference()
    ref = [sim.outputs().copy()]
    for k in range(n):  # fmpy's communication points: t_k = k dt, h = t_{k+1} - t_k
        assert sim.do_step(k * DT, (k + 1) * DT - k * DT).ok
        ref.append(sim.outputs().copy())
    ref = np.array(ref)
    assert len(res) == n + 1
    for i, name in enumerate(sim.model.output_names):
        np.testing.assert_array_equal(res[name], ref[:, i], err_msg=name)
    assert np.abs(res["body26_X"]).max() > 1e-6  # lateral motion is there


def test_inputs_and_parameter_override_equal_plant_simulator(fmu_path: Path) -> None:
    n = 300
    forces = forces_signal(n + 1)
    sig = np.zeros(n + 1, dtype=[("time", float)] + [(x, float) for x in INPUTS])
    sig["time"] = np.arange(n + 1) * DT
    for i, name in enumerate(INPUTS):
        sig[name] = forces[:, i]
    res = simulate_fmu(str(fmu_path), stop_time=n * DT, step_size=DT, output_interval=DT,
                       input=sig, start_values={"top_drive.rotary_speed": 15.0,
                                                "contact.clearance": 1e-5},
                       output=["strain1_C", "actuator1_power", "top_rotary_speed"])
    sim = reference(overrides={"top_drive": {"rotary_speed": 15.0},
                               "contact": {"clearance": 1e-5}})
    idx = [sim.model.output_names.index(x) for x in ("strain1_C", "actuator1_power")]
    for k in range(n):
        sim.set_inputs(forces[k])
        assert sim.do_step(k * DT, (k + 1) * DT - k * DT).ok
        for j, name in zip(idx, ("strain1_C", "actuator1_power")):
            assert abs(res[name][k + 1] - sim.outputs()[j]) <= 1e-12 * max(
                abs(res[name]).max(), 1e-300)
    assert res["top_rotary_speed"][-1] == pytest.approx(15.0 * n * DT)
    assert np.abs(res["actuator1_power"]).max() > 0.0


def test_parameter_rule_scene_first_then_values_different_from_start(make, tmp_path) -> None:
    scene_ref = reference()  # paper_open_loop: gravity = 9.81 (PlantParams default: 0)
    i_hook = scene_ref.model.output_names.index("hook_load")
    hook = scene_ref.outputs()[i_hook]
    assert hook > 1e4
    base = make()
    base.fmu.setupExperiment(startTime=0.0)
    base.fmu.enterInitializationMode()
    base.fmu.setReal([base.vr["gravity"]], [0.0])  # = start: does not override the scene
    in_init = base.fmu.getReal([base.vr["hook_load"]])[0]  # initial unknown, computed
    base.fmu.exitInitializationMode()
    assert in_init == base.fmu.getReal([base.vr["hook_load"]])[0] == hook
    other = make()
    other.initialize(gravity=4.905)  # differs from start: overrides the scene
    half = reference(overrides={"gravity": 4.905}).outputs()[i_hook]
    assert other.fmu.getReal([other.vr["hook_load"]])[0] == half != hook
    # the documented way back to a default: a scene file extending the shipped scene
    scene = tmp_path / "no_gravity.toml"
    scene.write_text('extends = "paper_open_loop"\ngravity = 0.0\n')
    mine = make()
    mine.initialize(scene=str(scene))
    got = mine.fmu.getReal([mine.vr["hook_load"]])[0]
    assert got == reference(str(scene)).outputs()[i_hook] != hook


def test_axial_pulse_scene_runs_as_full3d_by_default(make) -> None:
    inst = make()
    inst.initialize(scene="table1_axial_pulse")
    got = inst.run(np.zeros((20, 4)))
    sim = reference("table1_axial_pulse")
    for k in range(20):
        sim.do_step(k * DT, DT)
    np.testing.assert_allclose(got[-1], sim.outputs(), rtol=1e-12, atol=1e-300)


# ------------------------------------------------------------------------- isolation
CLEAN_SCRIPT = textwrap.dedent("""
    import importlib.util, json, sys, time
    for name in ("plant", "fmu_src", "pythonfmu", "controller", "cosim"):
        assert importlib.util.find_spec(name) is None, name
    from fmpy import extract, read_model_description
    from fmpy.fmi2 import FMU2Slave
    fmu = sys.argv[1]
    md = read_model_description(fmu)
    d = extract(fmu)
    vr = {v.name: v.valueReference for v in md.modelVariables}
    t0 = time.perf_counter()
    s = FMU2Slave(guid=md.guid, unzipDirectory=d, modelIdentifier="DrillstringPlant",
                  instanceName="clean")
    s.instantiate()
    s.setupExperiment(startTime=0.0)
    s.enterInitializationMode()
    s.exitInitializationMode()
    s.setReal([vr["actuator1_force_C"]], [100.0])
    s.doStep(0.0, 1e-3)
    t1 = time.perf_counter()
    print(json.dumps({
        "hook": s.getReal([vr["hook_load"]])[0], "cold_start_s": t1 - t0,
        "vendored_file": sys.modules["%(vendored)s"].__file__, "unzipdir": str(d),
        "pythonfmu_file": sys.modules["%(pythonfmu)s"].__file__,
        "generic_pythonfmu": "pythonfmu" in sys.modules,
        "plant_imported": "plant" in sys.modules,
        "plant_modules": sorted(m for m in sys.modules if m.startswith("%(vendored)s")),
        # compiled kernels loaded from numba's on-disk cache, none compiled anew
        "numba_compiled": sorted(
            f"{m}.{k}" for m in list(sys.modules) if m.startswith("%(vendored)s")
            for k, f in vars(sys.modules[m]).items()
            if hasattr(f, "stats") and getattr(f.stats, "cache_misses", None)),
    }))
    s.terminate()
    s.freeInstance()
""")


def clean_site(tmp_path: Path) -> Path:
    """A folder exposing only numpy, scipy, numba and fmpy (with their dependencies)."""
    site = tmp_path / "site"
    site.mkdir()
    for mod in ("numpy", "scipy", "numba", "llvmlite", "fmpy", "attr", "attrs", "lxml"):
        spec = importlib.util.find_spec(mod)
        assert spec is not None and spec.origin is not None
        src = Path(spec.origin).parent
        (site / src.name).symlink_to(src)
    for libs in ("numpy.libs", "scipy.libs"):
        path = Path(importlib.util.find_spec("numpy").origin).parent.parent / libs
        if path.exists():
            (site / libs).symlink_to(path)
    return site


def test_self_contained_and_cold_start(fmu_path: Path, tmp_path: Path, make, shipped: dict[str, str]) -> None:
    vendored_name = shipped[CANONICAL]
    warm = make()  # first use (same content hash, same cache): compiles if ever needed
    warm.initialize()
    warm.run(np.zeros((1, 4)))
    site = clean_site(tmp_path)
    script = tmp_path / "host.py"
    script.write_text(CLEAN_SCRIPT % {"vendored": vendored_name,
                                      "pythonfmu": shipped[PYTHONFMU_VENDORED]})
    work = tmp_path / "cwd"
    work.mkdir()
    env = {"PATH": os.environ.get("PATH", "/usr/bin:/bin"), "PYTHONPATH": str(site),
           "PYTHONNOUSERSITE": "1", "HOME": str(tmp_path),
           "DRILLCOSIM_CACHE": str(cache_root()),  # the per-user numba cache
           "OPENBLAS_NUM_THREADS": "1"}  # see SUBPROCESS_ENV
    if os.environ.get("NUMBA_CACHE_DIR"):  # numba's cache of the first use lives there (CI sets it)
        env["NUMBA_CACHE_DIR"] = os.environ["NUMBA_CACHE_DIR"]
    proc = subprocess.run([sys.executable, "-S", "-s", str(script), str(fmu_path)],
                          cwd=work, env=env, capture_output=True, text=True, timeout=180)
    assert proc.returncode == 0, proc.stderr[-3000:]
    out = json.loads(proc.stdout.strip().splitlines()[-1])
    assert out["hook"] > 1e4
    assert Path(out["vendored_file"]).is_relative_to(cache_root())
    assert out["pythonfmu_file"].startswith(out["unzipdir"])  # the FMU's own copy
    assert not out["generic_pythonfmu"]  # under its unique name only
    assert not out["plant_imported"]
    # the payload is what the FMU runs: every shipped module of the plant is imported
    import zipfile

    payload = {n[len("resources/"):-len(".py")].replace("/", ".").removesuffix(".__init__")
               for n in zipfile.ZipFile(fmu_path).namelist()
               if n.startswith(f"resources/{vendored_name}/") and n.endswith(".py")}
    assert payload == set(out["plant_modules"])
    # after first use nothing is compiled again: every kernel comes from numba's cache (the
    # time is reported by benchmarks/bench_fmu_boundary.py, not asserted here)
    assert out["numba_compiled"] == []
    print(f"cold start after first use (instantiate + init + first doStep): "
          f"{out['cold_start_s']:.3f} s")


SHADOW_SCRIPT = textwrap.dedent("""
    import json, sys
    order, fmu = sys.argv[1], sys.argv[2]
    from fmpy import extract, read_model_description
    from fmpy.fmi2 import FMU2Slave
    if order == "plant_first":
        import drillcosim.plant.simulator as simulator
    md = read_model_description(fmu)
    d = extract(fmu)
    s = FMU2Slave(guid=md.guid, unzipDirectory=d, modelIdentifier="DrillstringPlant",
                  instanceName="x")
    s.instantiate()
    s.setupExperiment(startTime=0.0)
    s.enterInitializationMode()
    s.exitInitializationMode()
    s.doStep(0.0, 1e-3)
    if order == "fmu_first":
        import drillcosim.plant.simulator as simulator
    vendored = sys.modules["%(vendored)s.simulator"]
    print(json.dumps({
        "plant": simulator.__file__, "vendored": vendored.__file__,
        "same_class": simulator.PlantSimulator is vendored.PlantSimulator,
    }))
    s.terminate()
    s.freeInstance()
""")


@pytest.mark.parametrize("order", ["plant_first", "fmu_first"])
def test_no_shadowing_between_host_plant_and_vendored_copy(
        fmu_path: Path, tmp_path: Path, order: str, shipped: dict[str, str]) -> None:
    vendored_name = shipped[CANONICAL]
    script = tmp_path / "host.py"
    script.write_text(SHADOW_SCRIPT % {"vendored": vendored_name})
    env = dict(SUBPROCESS_ENV, PYTHONPATH=str(ROOT))
    proc = subprocess.run([sys.executable, str(script), order, str(fmu_path)], cwd=tmp_path,
                          env=env, capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr[-3000:]
    out = json.loads(proc.stdout.strip().splitlines()[-1])
    assert Path(out["plant"]).resolve() == (ROOT / "plant" / "simulator.py").resolve()
    assert Path(out["vendored"]).is_relative_to(cache_root())
    assert not out["same_class"]


def test_no_shadowing_in_this_process(make, shipped: dict[str, str]) -> None:
    vendored_name = shipped[CANONICAL]
    before = plant.__file__
    inst = make()
    inst.initialize()
    inst.run(np.zeros((2, 4)))
    assert plant.__file__ == before
    # a top-level `plant` (importable only from a checkout's root, e.g. under `python -m
    # pytest`) must never resolve into the FMU's resources/ folder
    spec = importlib.util.find_spec("plant")
    assert spec is None or "resources" not in Path(spec.origin).parts
    assert f"{vendored_name}-" in sys.modules[vendored_name].__file__


# ----------------------------------------------------------------------------- state
def test_fmu_state_get_set_reproduces_run_bit_for_bit(make) -> None:
    forces = forces_signal(120)
    inst = make()
    inst.initialize()
    inst.run(forces[:60])
    state = inst.fmu.getFMUstate()
    first = inst.run(forces[60:], t0=60 * DT)
    inst.fmu.setFMUstate(state)
    second = inst.run(forces[60:], t0=60 * DT)
    assert np.array_equal(first, second)
    # serialised into another instance built with other parameters: rebuilt, identical
    blob = inst.fmu.serializeFMUstate(state)
    inst.fmu.freeFMUstate(state)
    other = make()
    other.initialize(**{"top_drive.rotary_speed": 5.0})
    other.fmu.setFMUstate(other.fmu.deSerializeFMUstate(blob))
    assert np.array_equal(other.run(forces[60:], t0=60 * DT), first)


def test_two_instances_with_different_parameters_are_independent(make) -> None:
    forces = forces_signal(60)
    solo = make()
    solo.initialize(**{"top_drive.rotary_speed": 10.0})
    expected = solo.run(forces)
    a, b = make(), make()
    a.initialize(**{"top_drive.rotary_speed": 10.0})
    b.initialize(**{"contact.stiffness": 3e7, "max_internal_step": 2e-4})
    rows = []
    for k in range(60):
        rows.append(a.run(forces[k:k + 1], t0=k * DT)[0])
        b.run(-forces[k:k + 1], t0=k * DT)
    assert np.array_equal(np.array(rows), expected)
    assert b.fmu.getReal([b.vr["top_rotary_speed"]])[0] != rows[-1][-5]


# ------------------------------------------------------------------ errors (subprocess)
MISUSE_SCRIPT = textwrap.dedent("""
    import ctypes, json, math, os, sys
    import fmpy
    from fmpy import read_model_description
    from fmpy.fmi1 import FMICallException
    from fmpy.fmi2 import (FMU2Slave, fmi2CallbackAllocateMemoryTYPE,
                           fmi2CallbackFreeMemoryTYPE, fmi2CallbackFunctions,
                           fmi2CallbackLoggerTYPE)
    from fmpy.logging import addLoggerProxy
    case, fmu, unzipdir = sys.argv[1:4]
    md = read_model_description(fmu)
    vr = {v.name: v.valueReference for v in md.modelVariables}
    messages = []
    def log(env, inst, status, category, message):
        messages.append([int(status), message.decode()])
    cb = fmi2CallbackFunctions()
    cb.logger = fmi2CallbackLoggerTYPE(log)
    cb.allocateMemory = fmi2CallbackAllocateMemoryTYPE(fmpy.calloc)
    cb.freeMemory = fmi2CallbackFreeMemoryTYPE(fmpy.free)
    addLoggerProxy(ctypes.byref(cb))
    s = FMU2Slave(guid=md.guid, unzipDirectory=unzipdir, modelIdentifier="DrillstringPlant",
                  instanceName=case)
    s.instantiate(callbacks=cb, loggingOn=True)
    def call(f, *args):
        try:
            f(*args)
            return 0
        except FMICallException as exc:
            return int(exc.status)
    out = {}
    if case != "before_init":
        s.setupExperiment(startTime=0.0)
        s.enterInitializationMode()
        if case == "contact_stiffness":
            s.setReal([vr["contact.stiffness"]], [-1.0])
        elif case == "n_segments":
            s.setInteger([vr["pipe.n_segments"]], [1])
        elif case == "scene_conflict":
            s.setInteger([vr["pipe.n_segments"]], [5])
        elif case == "missing_outputs":
            s.setString([vr["scene"]], ["table1_axial_pulse"])
            s.setString([vr["model"]], ["auto"])
        out["exit"] = call(s.exitInitializationMode)
    if case == "nan_input":
        out["ok"] = call(s.doStep, 0.0, 1e-3)
        s.setReal([vr["actuator1_force_E"]], [float("nan")])
    elif case == "huge_force":
        s.setReal([vr["actuator1_force_C"]], [1e12])
    elif case == "unknown_vr":
        out["get"] = call(s.getReal, [99999])
    out["steps"] = []
    # FMI 2.0: a discarded step leaves the FMU's time unchanged, so t advances on OK only
    t = 1e-3 if case == "nan_input" else 0.0
    for _ in range(1, 400):
        status = call(s.doStep, t, 1e-3)
        out["steps"].append(status)
        if status == 0:
            t += 1e-3
        if len([x for x in out["steps"] if x != 0]) == 2 or len(out["steps"]) == 3 and (
                case == "unknown_vr"):
            break
    if case == "nan_input":  # a valid input again: the instance is usable
        s.setReal([vr["actuator1_force_E"]], [0.0])
        out["retry"] = call(s.doStep, t, 1e-3)
    out["messages"] = messages
    seen = [out.get("exit", 0), out.get("get", 0), *out["steps"], out.get("retry", 0)]
    if 3 not in seen:  # FMI 2.0: after fmi2Error only fmi2FreeInstance (or reset/set state)
        out["terminate"] = call(s.terminate)
    s.freeInstance()
    print(json.dumps(out), flush=True)
""")


@pytest.mark.parametrize(
    ("case", "fragments", "log_status"),
    [
        ("contact_stiffness", ["contact.stiffness = -1.0 is out of range"], ERROR),
        ("n_segments", ["FMU parameter pipe.n_segments = 1 is out of range: allowed [2, 2000]"],
         ERROR),
        ("scene_conflict", ["FMU parameters set (pipe.n_segments = 5) do not fit scene "
                            "'paper_open_loop'", "contact.bodies: 11 is out of range"], ERROR),
        ("missing_outputs", ["lacks the declared outputs body11_X", "axial_torsional"], ERROR),
        ("nan_input", ["actuator1_force_E = nan is not finite at t = 0.001"], ERROR),
        ("huge_force", ["diverged at t =", "quantity body"], DISCARD),
        ("before_init", ["before initialization"], ERROR),
        ("unknown_vr", ["getReal: unknown value reference 99999"], ERROR),
    ],
)
def test_misuse_gives_a_non_ok_status_and_a_message_never_a_crash(
        fmu_path: Path, unzipdir: str, tmp_path: Path, case: str, fragments: list[str],
        log_status: int) -> None:
    """Each misuse: the documented status and message, never Fatal, clean exit."""
    script = tmp_path / "misuse.py"
    script.write_text(MISUSE_SCRIPT)
    proc = subprocess.run([sys.executable, str(script), case, str(fmu_path), unzipdir],
                          cwd=tmp_path, env=SUBPROCESS_ENV, capture_output=True, text=True,
                          timeout=120)
    assert proc.returncode == 0, (proc.stderr[-3000:], proc.stdout[-3000:])
    out = json.loads(proc.stdout.strip().splitlines()[-1])
    text = "\n".join(m for _, m in out["messages"])
    for fragment in fragments:
        assert [s for s, m in out["messages"] if fragment in m and s == log_status], text
    steps = out["steps"]
    assert FATAL not in steps and all(m[0] != FATAL for m in out["messages"])
    if case in ("contact_stiffness", "n_segments"):  # a value set through FMI, out of range:
        assert ".toml" not in text  # named as the FMU variable, not as the scene file's
    if case in ("contact_stiffness", "n_segments", "scene_conflict", "missing_outputs"):
        assert out["exit"] == ERROR  # at initialization, naming the parameter (above)
        assert steps == [ERROR, ERROR]  # never a silent run
        assert "terminate" not in out
    else:
        assert out.get("exit", OK) == OK
    if case in ("before_init", "nan_input"):
        assert steps == [ERROR, ERROR]  # repeated, state unchanged
    if case == "nan_input":
        assert out["ok"] == OK and out["retry"] == OK
    if case == "huge_force":
        assert steps[-2:] == [DISCARD, DISCARD] and set(steps[:-2]) <= {OK}
        assert "diverged earlier" in text  # halted after the divergence
        assert out["terminate"] == OK  # allowed after fmi2Discard
    if case == "unknown_vr":
        assert out["get"] == ERROR  # that call fails itself
        assert steps == [OK, OK, OK] and "an earlier call failed" not in text
