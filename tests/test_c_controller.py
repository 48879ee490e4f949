"""StrainControllerC.fmu, the strain controller in C99: the same interface and law as the Python
StrainController.fmu, bit for bit.

* its modelDescription declares what the Python FMU declares (names, value references,
  descriptions, causality, variability, initial, types, units, start values, unit
  definitions, log categories, default experiment, model structure), and config.h agrees;
* the FMU against the Python law (controller.StrainController) on random strains, step sizes
  and parameters (every mode, limits, lag, switch-on time, tunable changes): equal bit for bit;
* a closed loop through our master with the plant FMU equals the run with the Python
  controller FMU exactly (third-party engines running it: test_interop_libcosim.py,
  test_interop_ecos.py);
* FMI behaviour: errors named in one log message with fmi2Error, the FMI 2.0 state machine,
  FMU state get/set/serialise, no Python in the binary;
* handles a host should not pass (an instance used or freed after its free, a state freed
  twice or used after its free, a made-up pointer): fmi2Error or ignored, not a crash
  (``support/bad_handles.py``; test_sanitizers.py runs them under AddressSanitizer), with the
  shipped binary and one compiled from the FMU's own ``sources/`` alone.
"""

from __future__ import annotations

import dataclasses
import json
import math
import os
import re
import subprocess
import sys
import zipfile
from collections.abc import Iterator
from pathlib import Path
from xml.etree import ElementTree as ET

import numpy as np
import pytest
from fmpy import extract, read_model_description
from fmpy.fmi1 import FMICallException
from fmpy.validation import validate_fmu

from drillcosim.controller import MODES, ControllerParams, StrainController
from drillcosim.cosim.master.master import Master
from drillcosim.cosim.scenario.build import build_system
from drillcosim.cosim.scenario.config import load_config
from drillcosim.fmu_src.build_c import EXTRA_CFLAGS, SOURCE_DIR
from drillcosim.fmu_src.wrapper import compile_shared
from support import bad_handles
from support.fmi_logging import RecordingInstance

INPUTS = ["strain1_C", "strain1_E", "strain2_C", "strain2_E"]
OUTPUTS = ["actuator1_force_C", "actuator1_force_E", "actuator2_force_C", "actuator2_force_E"]
ERROR = 3


def _md_root(fmu: Path) -> ET.Element:
    with zipfile.ZipFile(fmu) as zf:
        return ET.fromstring(zf.read("modelDescription.xml"))


# ------------------------------------------------------------------ interface
def test_validate_fmu_finds_no_problems(c_controller_fmu: Path) -> None:
    assert validate_fmu(str(c_controller_fmu)) == []


def test_model_description_agrees_with_the_python_fmu(c_controller_fmu, project_fmus) -> None:
    c_root, py_root = _md_root(c_controller_fmu), _md_root(project_fmus["StrainController"])
    c_vars, py_vars = (list(r.find("ModelVariables")) for r in (c_root, py_root))
    assert len(c_vars) == len(py_vars) == 15
    for c, p in zip(c_vars, py_vars):
        assert c.attrib == p.attrib, p.get("name")  # name, VR, description, causality, ...
        (ct,), (pt,) = list(c), list(p)
        assert ct.tag == pt.tag, p.get("name")
        assert ct.get("unit") == pt.get("unit"), p.get("name")
        if ct.tag == "Real":
            assert float(ct.get("start")) == float(pt.get("start")), p.get("name")
        else:
            assert ct.get("start") == pt.get("start"), p.get("name")

    def canon(el: ET.Element | None):
        return None if el is None else ET.tostring(el, encoding="unicode").split()

    for tag in ("UnitDefinitions", "LogCategories", "ModelStructure"):
        assert canon(c_root.find(tag)) == canon(py_root.find(tag)), tag
    assert {k: float(v) for k, v in c_root.find("DefaultExperiment").attrib.items()} == \
        {k: float(v) for k, v in py_root.find("DefaultExperiment").attrib.items()}
    c_cs, py_cs = c_root.find("CoSimulation"), py_root.find("CoSimulation")
    for flag in ("canHandleVariableCommunicationStepSize", "canInterpolateInputs",
                 "canGetAndSetFMUstate", "canSerializeFMUstate"):
        assert c_cs.get(flag) == py_cs.get(flag), flag
    assert c_cs.get("needsExecutionTool") == "false"  # no Python needed


def test_config_h_agrees_with_the_model_description(c_controller_fmu) -> None:
    config = (SOURCE_DIR / "config.h").read_text()
    vrs = {m.group(1): int(m.group(2)) for m in re.finditer(r"vr_(\w+) = (\d+)", config)}
    md = read_model_description(str(c_controller_fmu))
    assert vrs == {v.name: v.valueReference for v in md.modelVariables}
    token = re.search(r'#define INSTANTIATION_TOKEN "([^"]+)"', config).group(1)
    assert token == md.guid
    starts = {m.group(1).lower(): float(m.group(2))
              for m in re.finditer(r"#define START_(\w+) (\S+)", config)}
    md_starts = {v.name: float(v.start) if v.type == "Real" else
                 float(v.start in ("true", "1") if v.type == "Boolean" else v.start)
                 for v in md.modelVariables if v.causality == "parameter"}
    assert starts == md_starts


def test_binary_needs_no_python(c_controller_fmu) -> None:
    with zipfile.ZipFile(c_controller_fmu) as zf:
        names = zf.namelist()
        binary = zf.read("binaries/linux64/StrainControllerC.so")
    assert b"libpython" not in binary and b"Py_Initialize" not in binary
    assert [n for n in names if n.startswith("resources/")] == ["resources/dcs_build.json"]
    assert {"sources/model.c", "sources/fmi2_cosimulation.c", "sources/dcs_registry.c",
            "sources/dcs_registry.h", "sources/dcs_state_format.c", "sources/dcs_state_format.h",
            "sources/dcs_build.h", "sources/fmi2Functions.h"} <= set(names)


@pytest.fixture(scope="module")
def built_from_sources(c_controller_fmu, tmp_path_factory) -> Path:
    """The binary compiled anew from the FMU's ``sources/`` alone: the files its
    ``<SourceFiles>`` lists, ``-I sources`` and nothing of this checkout (as an importer on
    another platform would, e.g. fmpy's compile_platform_binary)."""
    d = tmp_path_factory.mktemp("cctl_sources")
    with zipfile.ZipFile(c_controller_fmu) as zf:
        zf.extractall(d, members=[n for n in zf.namelist() if n.startswith("sources/")])
    listed = [f.get("name") for f in _md_root(c_controller_fmu).iter("File")]
    return compile_shared("StrainControllerC from its sources/", [d / "sources" / n for n in listed],
                          d / "StrainControllerC.so", flags=(*EXTRA_CFLAGS, f"-I{d / 'sources'}"),
                          libs=("-lm", "-lpthread"))


@pytest.mark.needs_cc
@pytest.mark.parametrize("binary", ["shipped", "built from sources/"])
@pytest.mark.parametrize("case", bad_handles.CASES)
def test_bad_handles_are_refused_not_followed(case: str, binary: str, c_controller_fmu: Path,
                                              request, tmp_path: Path) -> None:
    """gcc's build (-O2, no sanitizer): today's binary answered these with fmi2OK after reading
    freed memory, or crashed (glibc's double-free abort, a segfault on the made-up pointer)."""
    if binary == "shipped":
        with zipfile.ZipFile(c_controller_fmu) as zf:
            lib = tmp_path / "StrainControllerC.so"
            lib.write_bytes(zf.read("binaries/linux64/StrainControllerC.so"))
    else:
        lib = request.getfixturevalue("built_from_sources")
    guid = _md_root(c_controller_fmu).get("guid")
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(Path(__file__).parent),
                                                       os.environ.get("PYTHONPATH", "")]))
    proc = subprocess.run([sys.executable, bad_handles.__file__, str(lib), guid, case],
                          env=env, capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, f"exit {proc.returncode}\n{proc.stderr[-3000:]}"
    assert json.loads(proc.stdout) == bad_handles.EXPECTED[case]


# ----------------------------------------------------------------- instances
class Instance(RecordingInstance):
    """A recording FMU2Slave of the C controller."""

    def __init__(self, md, unzipdir: str) -> None:
        super().__init__(md, unzipdir, "cctl")
        self.vr = {v.name: v.valueReference for v in md.modelVariables}

    def initialize(self, params: dict[str, float | int | bool] | None = None) -> None:
        self.fmu.setupExperiment(startTime=0.0)
        self.fmu.enterInitializationMode()
        for name, value in (params or {}).items():
            self.set(name, value)
        self.fmu.exitInitializationMode()

    def set(self, name: str, value) -> None:
        if name == "mode":
            self.fmu.setInteger([self.vr[name]], [int(value)])
        elif name == "enabled":
            self.fmu.setBoolean([self.vr[name]], [bool(value)])
        else:
            self.fmu.setReal([self.vr[name]], [float(value)])

    def step(self, t: float, dt: float, strains) -> np.ndarray:
        self.fmu.setReal([self.vr[n] for n in INPUTS], [float(x) for x in strains])
        self.fmu.doStep(t, dt)
        return np.array(self.fmu.getReal([self.vr[n] for n in OUTPUTS]))


@pytest.fixture(scope="module")
def unzipped(c_controller_fmu, tmp_path_factory) -> tuple:
    md = read_model_description(str(c_controller_fmu))
    return md, extract(str(c_controller_fmu), str(tmp_path_factory.mktemp("cctl")))


@pytest.fixture
def make(unzipped) -> Iterator:
    made: list[Instance] = []

    def factory() -> Instance:
        made.append(Instance(*unzipped))
        return made[-1]

    yield factory
    for inst in made:
        inst.fmu.freeInstance()


def _bits(a: np.ndarray) -> np.ndarray:
    return np.asarray(a, dtype=np.float64).view(np.int64)


CASES = [
    {},                                                             # paper: 1e9, unrestricted
    {"gain": 3.7e8, "symmetric_force_limit": 750.0},                # symmetric saturation
    {"gain": 2e9, "mode": 1, "force_limit": 1200.0},                # push only, limited
    {"gain": 1e9, "mode": 1, "force_limit": math.inf},              # push only, no limit
    {"gain": 5e8, "lag_time_constant": 0.004, "switch_on_time": 0.05},
    {"gain": 1e9, "lag_time_constant": 0.02, "mode": 1, "force_limit": 900.0,
     "switch_on_time": 0.0123},
    {"gain": 0.0},
    {"enabled": False, "lag_time_constant": 0.01},
]


@pytest.mark.parametrize("case", CASES, ids=[str(i) for i in range(len(CASES))])
def test_fmu_equals_the_python_law_bit_for_bit(make, case: dict) -> None:
    """Random strains (with exact zeros of both signs) and step sizes (0 included), a tunable
    change half way: every force equal to the Python law's in every bit."""
    rng = np.random.default_rng(len(case) * 7919 + 1)
    inst = make()
    inst.initialize(case)
    full = {**case, "mode": MODES[case.get("mode", 0)]}
    law = StrainController(ControllerParams(**full))
    t = 0.0
    n = 400
    strains = rng.normal(scale=3e-6, size=(n, 4))
    strains[rng.random((n, 4)) < 0.05] = 0.0
    strains[rng.random((n, 4)) < 0.05] = -0.0
    steps = rng.choice([1e-3, 2.5e-4, 1e-4, 0.0, 3.3e-4], size=n)
    moved = False
    for k in range(n):
        if k == n // 2:  # a tunable change keeps the lag state (both sides)
            inst.set("gain", 6.5e8)
            law.params = dataclasses.replace(law.params, gain=6.5e8)
        got = inst.step(t, steps[k], strains[k])
        want = law.step(t, steps[k], strains[k])
        assert np.array_equal(_bits(got), _bits(want)), (k, got, want)
        moved |= bool(np.any(want != 0))
        t += steps[k]
    assert moved or case.get("gain") == 0.0 or case.get("enabled") is False


def test_switch_on_counts_a_time_a_few_ulp_early_as_on(make) -> None:
    """t = 0.1 + ... + 0.1 (8 terms) = 0.7999999999999999 < switch_on_time = 0.8: on (both)."""
    inst = make()
    inst.initialize({"switch_on_time": 0.8})
    law = StrainController(ControllerParams(switch_on_time=0.8))
    t, out = 0.0, []
    for _ in range(10):
        got, want = inst.step(t, 0.1, [1e-6] * 4), law.step(t, 0.1, [1e-6] * 4)
        assert np.array_equal(_bits(got), _bits(want))
        out.append((t, got[0]))
        t += 0.1
    assert out[8][0] < 0.8 and out[8][1] == 1000.0 and out[7][1] == 0.0


def test_closed_loop_equals_the_python_controller_exactly(project_fmus, c_controller_fmu) -> None:
    """Plant FMU + controller FMU through our master: the C controller changes no bit."""
    runs = {
        "paper_closed_loop": ("paper_closed_loop", {}, 0.4),
        # multirate controller, lag, switch-on, push-only with a limit that is reached
        "restricted_lag": ("paper_restricted_actuator", {
            "controller.lag_time_constant": 0.002, "controller.switch_on_time": 0.05,
            "controller.force_limit": 0.25, "cosim.step": 2.5e-4,
            "cosim.controller_sample_period": 5e-4, "cosim.algorithm": "jacobi",
            "cosim.order": ["plant", "controller"]}, 0.4),
    }
    for name, (scene, over, stop) in runs.items():
        data = {}
        for ctrl in (project_fmus["StrainController"], c_controller_fmu):
            config = load_config(scene, over, plant_fmu=project_fmus["DrillstringPlant"],
                                 controller_fmu=ctrl)
            ss = build_system(config, "fmu")
            data[ctrl.stem] = Master(ss.system).simulate(stop, ss.outputs).data
        py, c = data["StrainController"], data["StrainControllerC"]
        assert py.dtype.names == c.dtype.names and len(py) == len(c) > 100
        for field in py.dtype.names:
            assert np.array_equal(py[field], c[field]), (name, field)
        forces = [f for f in py.dtype.names if f.startswith("controller.")]
        assert len(forces) == 4 and max(np.max(np.abs(py[f])) for f in forces) > 0.2, name
    pushed = np.concatenate([data["StrainController"][f] for f in forces])
    assert np.min(pushed) >= 0 and np.max(pushed) == pytest.approx(0.25, rel=1e-12)  # limit hit


# ----------------------------------------------------------------- FMI behaviour
@pytest.mark.parametrize(("name", "value", "fragment"), [
    ("gain", -1.0, "gain = -1 is out of range; allowed: 0 <= gain < inf"),
    ("gain", float("nan"), "gain = nan is not allowed"),
    ("switch_on_time", float("inf"), "switch_on_time = inf is out of range"),
    ("lag_time_constant", -0.1, "lag_time_constant = -0.10000000000000001"),
    ("mode", 2, "mode = 2 is not allowed"),
])
def test_parameter_out_of_range_fails_initialization_naming_it(make, name, value,
                                                               fragment) -> None:
    inst = make()
    with pytest.raises(FMICallException) as info:
        inst.initialize({name: value})
    assert info.value.status == ERROR
    assert [m for s, m in inst.messages if s == ERROR and fragment in m], inst.messages
    with pytest.raises(FMICallException):  # never a silent run
        inst.fmu.doStep(0.0, 1e-3)
    inst.fmu.reset()  # FMI 2.0: after fmi2Error, reset (or free, or set a state)
    inst.initialize({name: 1.0 if name != "mode" else 1})
    assert inst.step(0.0, 1e-3, [1e-6] * 4).tolist() != [math.nan] * 4


def test_non_finite_input_is_an_error_naming_the_channel(make) -> None:
    inst = make()
    inst.initialize({"lag_time_constant": 0.01})
    inst.step(0.0, 1e-3, [1e-6] * 4)
    state = inst.fmu.getFMUstate()
    with pytest.raises(FMICallException) as info:
        inst.step(1e-3, 1e-3, [1e-6, math.nan, 0.0, 0.0])
    assert info.value.status == ERROR
    assert [m for s, m in inst.messages if s == ERROR and "site1_E" in m and "t = 0.001" in m]
    inst.fmu.setFMUstate(state)  # FMI 2.0: a stored state makes the instance usable again
    ref = make()
    ref.initialize({"lag_time_constant": 0.01})
    ref.step(0.0, 1e-3, [1e-6] * 4)
    assert np.array_equal(inst.step(1e-3, 1e-3, [2e-6] * 4), ref.step(1e-3, 1e-3, [2e-6] * 4))
    inst.fmu.freeFMUstate(state)


@pytest.mark.parametrize(("call", "args", "fragment"), [
    ("getReal", ([999],), "no Real variable has value reference 999"),
    ("setReal", ([4], [1.0]), "value reference 4 is an output"),
    ("getInteger", ([8],), "no Integer variable has value reference 8"),
    ("setInteger", ([12], [1]), "fixed parameter"),
    ("setReal", ([13], [0.5]), "fixed parameter"),
])
def test_bad_calls_are_errors_of_that_call(make, call, args, fragment) -> None:
    inst = make()
    inst.initialize()
    with pytest.raises(FMICallException) as info:
        getattr(inst.fmu, call)(*args)
    assert info.value.status == ERROR
    assert [m for s, m in inst.messages if s == ERROR and fragment in m], inst.messages


def test_calling_sequence_is_checked(make) -> None:
    inst = make()
    with pytest.raises(FMICallException) as info:
        inst.fmu.doStep(0.0, 1e-3)
    assert info.value.status == ERROR
    assert [m for s, m in inst.messages if "fmi2DoStep: not allowed in state Instantiated" in m]


def test_fmu_state_and_serialisation_reproduce_a_run(make) -> None:
    rng = np.random.default_rng(11)
    strains = rng.normal(scale=2e-6, size=(200, 4))
    a = make()
    a.initialize({"lag_time_constant": 0.03, "gain": 3e9, "switch_on_time": 0.02})
    for k in range(100):
        a.step(k * 1e-3, 1e-3, strains[k])
    blob = a.fmu.serializeFMUstate(a.fmu.getFMUstate())
    first = np.array([a.step(k * 1e-3, 1e-3, strains[k]) for k in range(100, 200)])
    b = make()
    b.initialize({"gain": 1.0})
    b.fmu.setFMUstate(b.fmu.deSerializeFMUstate(blob))
    second = np.array([b.step(k * 1e-3, 1e-3, strains[k]) for k in range(100, 200)])
    assert np.array_equal(first, second) and np.any(first != 0)
    assert b.fmu.getReal([b.vr["gain"]]) == [3e9]
    with pytest.raises(FMICallException):
        b.fmu.deSerializeFMUstate(bytes(len(blob)))  # not a state of this FMU
