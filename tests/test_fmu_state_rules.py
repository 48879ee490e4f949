"""FMU state and call order: the same rules in every FMU of the project (docs/reliability.md,
"FMU state and call order"), tested on each: the plant, the three Python controllers and the C
controller.

* ``fmi2SetFMUstate`` is all or nothing: a state that fails any check leaves the instance
  exactly as before (checked against a twin instance that never saw the state: the same
  outputs, bit for bit, over the next steps) and says why in one logged line (fmi2Error); the
  instance stays usable.
* A serialized state carries a SHA-256 and the identity of the FMU and build it came from
  (``drillcosim.fmu_src.state_format``, checked here with hashlib): a corrupted (seeded random
  campaign) or foreign state is refused.
* A state is checked as a parameter set would be before it is applied (a state edited to an
  out-of-range parameter and sealed again with a valid checksum is refused).
* A state of another lifecycle phase (before initialization, after terminate) is refused,
  never silently ignored; a state of the same phase restores everything, parameters included.
* Setting a fixed parameter after initialization is fmi2Error from that call and changes
  nothing (the inputs of the same call included); the instance steps on.

The cases are those of a hostile host's probe; each failed on the FMUs before this work.
"""

from __future__ import annotations

import json
import math
import struct
import zipfile
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from fmpy import extract, read_model_description
from fmpy.fmi1 import FMICallException
from fmpy.fmi2 import FMU2Slave

from drillcosim.fmu_src.state_format import PHASES, read_state, write_state
from support.fmi_logging import RecordingCallbacks

ERROR = 3
NAMES = ("DrillstringPlant", "StrainController", "TopDriveController", "StateSpaceController",
         "StrainControllerC")
DT = 1e-3
#: The C controller's payload (fmi2_cosimulation.c, "serialized state"): inputs[4], outputs[4],
#: the parameters as set and as applied (5 doubles, mode, enabled), the lag state (forces[4],
#: decay step, decay) and the time.
C_PAYLOAD = struct.Struct("<4d4d5d2i5d2i4d2dd")
C_LAG_AS_SET, C_LAG_APPLIED = 12, 19  # indexes of lag_time_constant in C_PAYLOAD


#: The recorder of the current test's messages (every instance logs to it).
LOG: list[RecordingCallbacks] = []


@pytest.fixture(autouse=True)
def _log() -> None:
    LOG[:] = [RecordingCallbacks()]
    yield
    LOG.clear()


def messages() -> list[tuple[int, str]]:
    return LOG[0].messages


class Unit:
    """One FMU under test: extracted once, instances made and started the same way."""

    def __init__(self, fmu: Path, folder: Path) -> None:
        self.fmu = fmu
        self.md = read_model_description(str(fmu))
        self.unzipdir = extract(str(fmu), unzipdir=str(folder))
        self.name = self.md.coSimulation.modelIdentifier
        self.var = {v.name: v for v in self.md.modelVariables}
        self.inputs = [v.valueReference for v in self.md.modelVariables
                       if v.causality == "input"]
        self.outputs = [v.valueReference for v in self.md.modelVariables
                        if v.causality == "output"]
        self.made: list[FMU2Slave] = []
        #: input scale: forces [N] (plant), strains (strain controllers), rad/s and N m
        self.scale = (1e3 if self.name == "DrillstringPlant"
                      else 1e-6 if "strain1_C" in self.var else 1.0)

    def new(self) -> FMU2Slave:
        """A new instance, logging to :data:`LOG` (fmpy's logger proxy is one per process)."""
        inst = FMU2Slave(guid=self.md.guid, unzipDirectory=self.unzipdir,
                         modelIdentifier=self.name, instanceName=f"{self.name}{len(self.made)}")
        inst.instantiate(callbacks=LOG[0].callbacks, loggingOn=True)
        self.made.append(inst)
        return inst

    def set(self, inst: FMU2Slave, values: dict) -> None:
        for name, value in values.items():
            var = self.var[name]
            setter = {"Real": inst.setReal, "Integer": inst.setInteger,
                      "Boolean": inst.setBoolean, "String": inst.setString}[var.type]
            setter([var.valueReference], [value])

    def get(self, inst: FMU2Slave, name: str):
        var = self.var[name]
        getter = {"Real": inst.getReal, "Integer": inst.getInteger,
                  "Boolean": inst.getBoolean, "String": inst.getString}[var.type]
        return getter([var.valueReference])[0]

    def start(self, values: dict | None = None) -> FMU2Slave:
        """A new instance, initialized (the plant with a fixed internal step: cheap)."""
        inst = self.new()
        inst.setupExperiment(startTime=0.0)
        inst.enterInitializationMode()
        defaults = {"max_internal_step": 2.5e-4} if self.name == "DrillstringPlant" else {}
        self.set(inst, {**defaults, **(values or {})})
        inst.exitInitializationMode()
        return inst

    def step(self, inst: FMU2Slave, k: int) -> list[float]:
        """Step k (sine inputs, 1 ms); the outputs after it."""
        inst.setReal(self.inputs, [self.scale * math.sin(0.3 * k + i)
                                       for i in range(len(self.inputs))])
        inst.doStep(k * DT, DT)
        return inst.getReal(self.outputs)

    def run(self, inst: FMU2Slave, ks: range) -> np.ndarray:
        return np.array([self.step(inst, k) for k in ks])

    def blob(self, inst: FMU2Slave) -> bytes:
        state = inst.getFMUstate()
        try:
            return bytes(inst.serializeFMUstate(state))
        finally:
            inst.freeFMUstate(state)

    def build_id(self) -> str:
        with zipfile.ZipFile(self.fmu) as zf:
            return json.loads(zf.read("resources/dcs_build.json"))["build"]

    def free(self) -> None:
        for inst in self.made:
            inst.freeInstance()
        self.made.clear()


@pytest.fixture(scope="module")
def units(project_fmus, c_controller_fmu, tmp_path_factory) -> dict[str, Unit]:
    paths = {**project_fmus, "StrainControllerC": c_controller_fmu}
    made = {n: Unit(paths[n], tmp_path_factory.mktemp(n)) for n in NAMES}
    yield made
    for unit in made.values():
        unit.free()


def refused(unit: Unit, call, *args, fragment: str = "") -> str:
    """Run a call that must be refused: fmi2Error and ONE logged line; that line."""
    before = len(messages())
    with pytest.raises(FMICallException) as info:
        call(*args)
    assert info.value.status == ERROR, unit.name
    new = [m for s, m in messages()[before:] if s >= ERROR]
    assert len(new) == 1 and "\n" not in new[0], (unit.name, new)
    assert fragment in new[0], (unit.name, new[0])
    return new[0]


def restore(unit: Unit, inst: FMU2Slave, blob: bytes, fragment: str = "") -> str:
    """Deserialize + set ``blob``, which must be refused by one of the two calls."""
    before = len(messages())
    try:
        state = inst.deSerializeFMUstate(blob)
    except FMICallException as exc:
        assert exc.status == ERROR, unit.name
    else:
        refused(unit, inst.setFMUstate, state)
        inst.freeFMUstate(state)
    new = [m for s, m in messages()[before:] if s >= ERROR]
    assert len(new) == 1 and "\n" not in new[0], (unit.name, new)
    assert fragment in new[0], (unit.name, new[0])
    return new[0]


def twins(unit: Unit, steps: int = 5, values: dict | None = None):
    """Two instances run alike for ``steps`` steps."""
    a, b = unit.start(values), unit.start(values)
    unit.run(a, range(steps))
    unit.run(b, range(steps))
    return a, b


def assert_same_future(unit: Unit, a, b, start: int = 5, steps: int = 20) -> None:
    """a and b give the same outputs, bit for bit, over the next steps (and they move)."""
    ya, yb = unit.run(a, range(start, start + steps)), unit.run(b, range(start, start + steps))
    assert np.array_equal(ya, yb), unit.name
    assert np.any(ya != ya[0]), unit.name


def edit_payload(unit: Unit, blob: bytes, edit) -> bytes:
    """``blob`` with its payload edited by ``edit`` and sealed again (a valid checksum)."""
    state = read_state(blob)
    if unit.name == "StrainControllerC":
        values = list(C_PAYLOAD.unpack(state.payload))
        edit(values)
        payload = C_PAYLOAD.pack(*values)
    else:
        doc = json.loads(state.payload)
        edit(doc)
        payload = json.dumps(doc).encode()
    return write_state(replace(state, payload=payload))


# ------------------------------------------------------------------------- the format
@pytest.mark.parametrize("name", NAMES)
def test_serialized_state_carries_identity_phase_and_checksum(units, name) -> None:
    unit = units[name]
    a = unit.start()
    unit.run(a, range(3))
    blob = unit.blob(a)
    state = read_state(blob)  # checks the SHA-256 with hashlib: a second implementation
    assert (state.model_identifier, state.build, PHASES[state.phase]) == (
        unit.name, unit.build_id(), "StepComplete")
    b = unit.start()
    b.setFMUstate(b.deSerializeFMUstate(blob))
    assert_same_future(unit, a, b, start=3)
    unit.free()


@pytest.fixture(scope="module")
def state_format_c(tmp_path_factory):
    """``fmu_src/wrapper/dcs_state_format.c`` alone, compiled into a library (ctypes)."""
    import ctypes

    from drillcosim.fmu_src.wrapper import HERE, compile_shared

    out = tmp_path_factory.mktemp("state_format") / "libdcs_state_format.so"
    lib = ctypes.CDLL(str(compile_shared("the state format", [HERE / "dcs_state_format.c"],
                                         out, flags=("-fvisibility=default", f"-I{HERE}"))))
    lib.dcs_state_seal.restype = ctypes.c_size_t
    lib.dcs_state_size_for.restype = ctypes.c_size_t
    return lib


@pytest.mark.needs_cc
def test_c_sha256_equals_hashlib(state_format_c) -> None:
    """Every length across the padding boundaries (0..300) and 40 long random inputs."""
    import ctypes
    import hashlib

    rng = np.random.default_rng(7)
    sizes = [*range(301), *rng.integers(301, 200_000, size=40).tolist()]
    for n in sizes:
        data = rng.integers(0, 256, size=n, dtype=np.uint8).tobytes()
        out = ctypes.create_string_buffer(32)
        state_format_c.dcs_sha256(data, ctypes.c_size_t(n), out)
        assert out.raw == hashlib.sha256(data).digest(), n
    out = ctypes.create_string_buffer(32)  # FIPS 180-4's example "abc"
    state_format_c.dcs_sha256(b"abc", ctypes.c_size_t(3), out)
    assert out.raw.hex() == ("ba7816bf8f01cfea414140de5dae2223b00361a396177a9cb410ff61f20015ad")


@pytest.mark.needs_cc
def test_c_seal_and_open_agree_with_the_python_reference(state_format_c) -> None:
    """The C writer gives the bytes of ``state_format.write_state``; the C reader accepts them
    and refuses (one line naming why) each kind of damage the Python reader refuses."""
    import ctypes

    from drillcosim.fmu_src.state_format import FmuState

    lib = state_format_c
    payload = bytes(range(256)) * 3
    size = lib.dcs_state_size_for(ctypes.c_size_t(5), ctypes.c_size_t(12),
                                  ctypes.c_size_t(len(payload)))
    buf = ctypes.create_string_buffer(size)
    assert lib.dcs_state_seal(buf, 4, b"Model", b"0123456789ab", payload,
                              ctypes.c_size_t(len(payload))) == size
    blob = buf.raw
    assert blob == write_state(FmuState(4, "Model", "0123456789ab", payload))

    def opened(data: bytes, model: bytes = b"Model", build: bytes = b"0123456789ab") -> str:
        why = ctypes.create_string_buffer(400)
        view = ctypes.create_string_buffer(128)  # DcsStateView, opaque here
        rc = lib.dcs_state_open(data, ctypes.c_size_t(len(data)), model, build, view, why,
                                ctypes.c_size_t(400))
        return "" if rc == 0 else why.value.decode()

    assert opened(blob) == ""
    flipped = bytearray(blob)
    flipped[100] ^= 4
    cases = {
        "too short": blob[:40], "does not start with DCSSTATE": b"X" + blob[1:],
        "format version 2": write_state(FmuState(4, "Model", "0123456789ab", payload, 2)),
        "lengths": blob + b"\0", "SHA-256": bytes(flipped),
        "unknown phase 3": write_state(FmuState(3, "Model", "0123456789ab", payload)),
    }
    for fragment, data in cases.items():
        assert fragment in opened(data), fragment
        with pytest.raises(ValueError, match=fragment.split()[0]):
            read_state(data)
    assert "a state of FMU Model, not of Other" in opened(blob, model=b"Other")
    assert "a state of build 0123456789ab of Model" in opened(blob, build=b"ffffffffffff")


# ------------------------------------------------------------ corrupted and foreign states
@pytest.mark.parametrize("name", NAMES)
def test_randomly_corrupted_states_are_all_refused(units, name) -> None:
    """Seeded campaign: 200 corruptions of a running state (bytes overwritten, a bit flipped,
    cut, extended); none may be accepted, and the instance is unchanged after all of them."""
    unit = units[name]
    a, b = twins(unit)
    blob = unit.blob(a)
    rng = np.random.default_rng(32)
    accepted, tried = 0, 0
    while tried < 200:
        bad = bytearray(blob)
        kind = tried % 4
        if kind == 0:
            for i in rng.integers(0, len(bad), size=int(rng.integers(1, 9))):
                bad[int(i)] = int(rng.integers(0, 256))
        elif kind == 1:
            i = int(rng.integers(0, len(bad)))
            bad[i] ^= 1 << int(rng.integers(0, 8))
        elif kind == 2:
            del bad[int(rng.integers(0, len(bad))):]
        else:
            bad += bytes(rng.integers(0, 256, size=int(rng.integers(1, 64)), dtype=np.uint8))
        if bytes(bad) == blob:
            continue
        tried += 1
        try:
            state = a.deSerializeFMUstate(bytes(bad))
        except FMICallException as exc:
            assert exc.status == ERROR
            continue
        try:
            a.setFMUstate(state)
            accepted += 1
        except FMICallException as exc:
            assert exc.status == ERROR
        a.freeFMUstate(state)
    assert accepted == 0, f"{unit.name}: {accepted} of {tried} corrupted states accepted"
    assert_same_future(unit, a, b)
    unit.free()


@pytest.mark.parametrize(("name", "other"), [("StrainController", "StrainControllerC"),
                                             ("StrainControllerC", "StrainController"),
                                             ("TopDriveController", "StrainController"),
                                             ("DrillstringPlant", "StateSpaceController")])
def test_a_state_of_another_fmu_is_refused(units, name, other) -> None:
    unit, foreign = units[name], units[other]
    f = foreign.start()
    foreign.run(f, range(3))
    a, b = twins(unit)
    restore(unit, a, foreign.blob(f), fragment=f"a state of FMU {other}")
    assert_same_future(unit, a, b)
    unit.free()
    foreign.free()


@pytest.mark.parametrize("name", NAMES)
def test_a_state_of_another_build_is_refused(units, name) -> None:
    unit = units[name]
    a, b = twins(unit)
    state = read_state(unit.blob(a))
    other = write_state(replace(state, build="0123456789ab"))
    line = restore(unit, a, other, fragment="a state of build 0123456789ab")
    assert unit.build_id() in line
    assert_same_future(unit, a, b)
    unit.free()


# --------------------------------------------------- checked as a parameter set would be
def _set_c_lag(values: list) -> None:
    values[C_LAG_AS_SET] = values[C_LAG_APPLIED] = -1e-3


def _python_param(name: str, value):
    def edit(doc: dict) -> None:
        assert name in doc["variables"]
        doc["variables"][name] = value
    return edit


#: name -> (edit, parameter edited, fragment of the message, parameters of the run)
BAD_PARAMETERS = {
    "StrainControllerC": (_set_c_lag, "lag_time_constant", "lag_time_constant = -0.001",
                          {"lag_time_constant": 0.01}),
    "StrainController": (_python_param("lag_time_constant", -1e-3), "lag_time_constant",
                         "lag_time_constant = -0.001", {"lag_time_constant": 0.01}),
    "TopDriveController": (_python_param("p_gain", -1.0), "p_gain", "p_gain", {}),
    "StateSpaceController": (_python_param("lower_limit_actuator1_force_C", math.inf),
                             "lower_limit_actuator1_force_C",
                             "lower_limit > upper_limit (or NaN) for actuator1_force_C", {}),
    "DrillstringPlant": (_python_param("pipe.n_segments", 1), "pipe.n_segments",
                         "pipe.n_segments = 1 is out of range", {}),
}


@pytest.mark.parametrize("name", NAMES)
def test_a_state_with_a_parameter_out_of_range_is_refused(units, name) -> None:
    """The state edited to a bad parameter and sealed again (valid checksum): refused by the
    checks its parameters would get at initialization; nothing of it applied."""
    unit = units[name]
    edit, param, fragment, values = BAD_PARAMETERS[name]
    a, b = twins(unit, values=values)
    old = unit.get(a, param)
    restore(unit, a, edit_payload(unit, unit.blob(a), edit), fragment=fragment)
    assert unit.get(a, param) == old
    assert_same_future(unit, a, b)
    unit.free()


def test_plant_state_with_another_segment_count_is_refused(units) -> None:
    """The probe: ``pipe.n_segments`` edited to 31 (a valid value, a model of another size)
    with the 30-segment state vector: refused, nothing applied (it used to set n_segments and
    run on with a hook load of 18.7 kN instead of 53.8 kN)."""
    unit = units["DrillstringPlant"]
    a, b = twins(unit)
    hook = unit.get(a, "hook_load")
    line = restore(unit, a, edit_payload(unit, unit.blob(a), _python_param("pipe.n_segments",
                                                                           31)))
    assert "state" in line
    assert unit.get(a, "pipe.n_segments") == 30 and unit.get(a, "hook_load") == hook
    assert_same_future(unit, a, b, steps=100)
    unit.free()


def _break_internal(unit: Unit):
    """An edit that passes every parameter check but fails the last one (the internal state),
    after changing the inputs: the refusal must undo the inputs written before it."""
    def edit(doc):
        for name in doc["variables"]:
            if unit.var[name].causality == "input":
                doc["variables"][name] = 123.0
        internal = doc["internal"]
        if "sim" in internal:
            internal["sim"][1] = internal["sim"][1][:-1]  # one state value short
        else:
            internal["law"] = [math.nan] * len(internal["law"])
    return edit


@pytest.mark.parametrize("name", [n for n in NAMES if n != "StrainControllerC"])
def test_a_state_failing_its_last_check_changes_nothing(units, name) -> None:
    unit = units[name]
    a, b = twins(unit)
    ins = a.getReal(unit.inputs)
    restore(unit, a, edit_payload(unit, unit.blob(a), _break_internal(unit)))
    assert a.getReal(unit.inputs) == ins
    assert_same_future(unit, a, b)
    unit.free()


def test_c_controller_state_with_non_finite_lag_state_is_refused(units) -> None:
    unit = units["StrainControllerC"]
    a, b = twins(unit, values={"lag_time_constant": 0.01})

    def edit(values):
        values[0:4] = [123.0] * 4  # inputs
        values[24] = math.nan      # the lag state of channel 1

    restore(unit, a, edit_payload(unit, unit.blob(a), edit), fragment="lag state")
    assert_same_future(unit, a, b)
    unit.free()


# ------------------------------------------------------------------------- the phases
@pytest.mark.parametrize("name", NAMES)
def test_a_state_taken_before_initialization_is_refused_while_running(units, name) -> None:
    unit = units[name]
    early = unit.new()
    state = early.getFMUstate()
    a, b = twins(unit)
    blob = early.serializeFMUstate(state)
    refused(unit, a.setFMUstate, state, fragment="Instantiated")
    restore(unit, a, bytes(blob), fragment="Instantiated")
    assert_same_future(unit, a, b)
    early.freeFMUstate(state)
    unit.free()


@pytest.mark.parametrize("name", NAMES)
def test_a_running_state_is_refused_after_terminate(units, name) -> None:
    unit = units[name]
    a = unit.start()
    unit.run(a, range(3))
    running = a.getFMUstate()
    a.terminate()
    refused(unit, a.setFMUstate, running, fragment="StepComplete")
    refused(unit, a.doStep, 3 * DT, DT)  # still terminated: no silent run
    assert len(a.getReal(unit.outputs)) == len(unit.outputs)  # usable
    a.freeFMUstate(running)
    unit.free()


@pytest.mark.parametrize("name", NAMES)
def test_a_state_of_the_same_phase_restores_the_parameters(units, name) -> None:
    unit = units[name]
    param, value = {"DrillstringPlant": ("pipe.length", 70.0),
                    "StrainController": ("gain", 2.5e9), "StrainControllerC": ("gain", 2.5e9),
                    "TopDriveController": ("p_gain", 123.0),
                    "StateSpaceController": ("upper_limit_actuator1_force_C", 77.0)}[name]
    src, dst = unit.new(), unit.new()
    unit.set(src, {param: value})
    state = src.getFMUstate()
    dst.setFMUstate(dst.deSerializeFMUstate(src.serializeFMUstate(state)))
    dst.setupExperiment(startTime=0.0)
    dst.enterInitializationMode()  # FMI 2.0: no get before it
    assert unit.get(dst, param) == value
    src.freeFMUstate(state)
    unit.free()


# ------------------------------------------------------ fixed parameters after initialization
FIXED = {"DrillstringPlant": ("pipe.length", 70.0), "StrainController": ("lag_time_constant", 0.5),
         "StrainControllerC": ("lag_time_constant", 0.5), "TopDriveController": ("enabled", False)}


@pytest.mark.parametrize("name", sorted(FIXED))
def test_setting_a_fixed_parameter_after_initialization_changes_nothing(units, name) -> None:
    """fmi2Error from that call; neither the parameter nor an input of the same call changes;
    the instance steps on as its twin."""
    unit = units[name]
    param, value = FIXED[name]
    a, b = twins(unit)
    old, ins = unit.get(a, param), a.getReal(unit.inputs)
    var = unit.var[param]
    if var.type == "Real":  # an input and the fixed parameter in one call
        call, vrs, vals = a.setReal, [unit.inputs[0], var.valueReference], [9.0, value]
    else:
        call, vrs, vals = a.setBoolean, [var.valueReference], [value]
    refused(unit, call, vrs, vals, fragment=param)
    assert unit.get(a, param) == old and a.getReal(unit.inputs) == ins
    assert_same_future(unit, a, b)
    unit.free()


# ------------------------------------------------------- fmi2Error leaves the instance usable
RETRY = {"DrillstringPlant": ("pipe.n_segments", 1, 30),
         "StrainController": ("lag_time_constant", -1.0, 0.01),
         "StrainControllerC": ("lag_time_constant", -1.0, 0.01),
         "TopDriveController": ("p_gain", -1.0, 100.0),
         "StateSpaceController": ("lower_limit_actuator1_force_C", math.inf, -1e3)}


@pytest.mark.parametrize("name", NAMES)
def test_a_failed_initialization_can_be_corrected_and_retried(units, name) -> None:
    """fmi2Error from fmi2ExitInitializationMode leaves the instance in initialization mode,
    its (fixed) parameters settable: the corrected retry runs as an instance set right."""
    unit = units[name]
    param, bad, good = RETRY[name]
    a = unit.new()
    a.setupExperiment(startTime=0.0)
    a.enterInitializationMode()
    unit.set(a, {"max_internal_step": 2.5e-4} if name == "DrillstringPlant" else {})
    unit.set(a, {param: bad})
    refused(unit, a.exitInitializationMode, fragment=param.split("_actuator")[0])
    refused(unit, a.doStep, 0.0, DT)  # never a silent run
    unit.set(a, {param: good})
    a.exitInitializationMode()
    b = unit.start({param: good})
    assert_same_future(unit, a, b, start=0)
    unit.free()
