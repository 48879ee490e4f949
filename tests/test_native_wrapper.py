"""Our C FMI wrapper (``fmu_src/wrapper``): statuses, calling sequence, buffers, Python discovery.

Statuses (see the adapters' module docstrings): out-of-range parameter -> fmi2Error from
fmi2ExitInitializationMode naming it; non-finite input -> fmi2Error from fmi2DoStep; divergence
-> fmi2Discard; a call in a state that does not allow it, unknown value reference, NULL
component -> fmi2Error; a Python exception -> fmi2Error and the instance stays usable.
Runs that exercise misuse, the heap check and hosts without Python run in subprocesses (a
crash shows as a failed exit code).
"""

from __future__ import annotations

import ctypes
import json
import os
import shutil
import subprocess
import sys
import textwrap
import zipfile
from pathlib import Path

import numpy as np
import pytest
from fmpy import extract, read_model_description
from fmpy.validation import validate_fmu

from drillcosim.fmu_src.build import REGISTRY, FmuRecipe, build_one, shipped_modules
from drillcosim.fmu_src.platforms import select
from drillcosim.fmu_src.wrapper import compile_wrapper
from support import c_host
from support.required import import_module, missing

pytestmark = [pytest.mark.needs_cc]

ROOT = Path(__file__).resolve().parents[1]
OK, WARNING, DISCARD, ERROR, FATAL = 0, 1, 2, 3, 4
RECIPES = {r.name: r for r in REGISTRY}
ENV = dict(os.environ, OPENBLAS_NUM_THREADS="1")

RAISING_SLAVE = textwrap.dedent('''
    """Test slave: do_step raises for x < 0, exit_initialization_mode for x > 100."""
    from _dcs_pythonfmu_0_7_0 import Fmi2Causality, Fmi2Slave, Real
    from _dcs_pythonfmu_0_7_0.enums import Fmi2Status


    class Raiser(Fmi2Slave):
        author = "test"

        def __init__(self, **kwargs):
            super().__init__(**kwargs)
            self.x = 0.0
            self.y = 0.0
            self.register_variable(Real("x", causality=Fmi2Causality.input))
            self.register_variable(Real("y", causality=Fmi2Causality.output))

        def exit_initialization_mode(self):
            if self.x > 100.0:
                raise RuntimeError(f"x = {self.x} is too large")
            if self.x > 50.0:
                self.log("x > 50 is refused", status=Fmi2Status.error)
                return Fmi2Status.error
            return None

        def do_step(self, t, h):
            if self.x < 0.0:
                raise ValueError(f"x = {self.x} is negative")
            self.y += self.x * h
            return True
''')


@pytest.fixture(scope="session")
def native_dir(project_fmus: dict[str, Path]) -> Path:
    return project_fmus["DrillstringPlant"].parent


#: A slave that raises on request; its script is written by the fixture (a unique temp path).
RAISER = FmuRecipe(name="Raiser", script=str(Path(__import__("tempfile").mkdtemp(
    prefix="dcs_raiser_")) / "raiser_slave.py"))


@pytest.fixture(scope="session")
def raiser_fmu(tmp_path_factory: pytest.TempPathFactory) -> Path:
    src = Path(RAISER.script)
    src.parent.mkdir(parents=True, exist_ok=True)
    src.write_text(RAISING_SLAVE)
    return build_one(RAISER, tmp_path_factory.mktemp("raiser"))


def run_script(code: str, *args: str, env: dict | None = None, timeout: int = 600) -> dict:
    """Run ``code`` in a fresh Python; return the JSON of its last stdout line."""
    proc = subprocess.run([sys.executable, "-c", code, *args], cwd=ROOT, env=env or ENV,
                          capture_output=True, text=True, timeout=timeout)
    assert proc.returncode == 0, (args, proc.returncode, proc.stderr[-4000:],
                                  proc.stdout[-2000:])
    return json.loads(proc.stdout.strip().splitlines()[-1])


# Helpers shared by the subprocess scripts: an fmpy instance with a recording logger.
PRELUDE = textwrap.dedent("""
    import ctypes, json, math, os, sys
    import fmpy
    from fmpy import extract, read_model_description
    from fmpy.fmi1 import FMICallException
    from fmpy.fmi2 import (FMU2Slave, fmi2CallbackAllocateMemoryTYPE,
                           fmi2CallbackFreeMemoryTYPE, fmi2CallbackFunctions,
                           fmi2CallbackLoggerTYPE)
    from fmpy.logging import addLoggerProxy
    messages = []
    def _log(env, inst, status, category, message):
        messages.append([int(status), category.decode(), message.decode()])
    cb = fmi2CallbackFunctions()
    cb.logger = fmi2CallbackLoggerTYPE(_log)
    cb.allocateMemory = fmi2CallbackAllocateMemoryTYPE(fmpy.calloc)
    cb.freeMemory = fmi2CallbackFreeMemoryTYPE(fmpy.free)
    addLoggerProxy(ctypes.byref(cb))
    def call(f, *args):
        try:
            f(*args)
            return 0
        except FMICallException as exc:
            return int(exc.status)
    def open_fmu(path, name="inst", unzipdir=None):
        md = read_model_description(path)
        d = unzipdir or extract(path)
        s = FMU2Slave(guid=md.guid, unzipDirectory=d,
                      modelIdentifier=md.coSimulation.modelIdentifier, instanceName=name)
        s.instantiate(callbacks=cb, loggingOn=True)
        return s, {v.name: v.valueReference for v in md.modelVariables}, d
""")


# ----------------------------------------------------------------------- the library
#: Every FMI 2.0 function a co-simulation FMU exports (fmi2Functions.h, common + CS part).
FMI2_CS_FUNCTIONS = {
    "fmi2GetTypesPlatform", "fmi2GetVersion", "fmi2SetDebugLogging", "fmi2Instantiate",
    "fmi2FreeInstance", "fmi2SetupExperiment", "fmi2EnterInitializationMode",
    "fmi2ExitInitializationMode", "fmi2Terminate", "fmi2Reset", "fmi2GetReal",
    "fmi2GetInteger", "fmi2GetBoolean", "fmi2GetString", "fmi2SetReal", "fmi2SetInteger",
    "fmi2SetBoolean", "fmi2SetString", "fmi2GetFMUstate", "fmi2SetFMUstate",
    "fmi2FreeFMUstate", "fmi2SerializedFMUstateSize", "fmi2SerializeFMUstate",
    "fmi2DeSerializeFMUstate", "fmi2GetDirectionalDerivative", "fmi2SetRealInputDerivatives",
    "fmi2GetRealOutputDerivatives", "fmi2DoStep", "fmi2CancelStep", "fmi2GetStatus",
    "fmi2GetRealStatus", "fmi2GetIntegerStatus", "fmi2GetBooleanStatus", "fmi2GetStringStatus",
}


def test_compiles_without_warnings_and_needs_no_libpython(tmp_path: Path) -> None:
    lib = compile_wrapper(tmp_path / "w.so")  # -Wall -Wextra -Werror; stderr must be empty
    undefined = subprocess.run(["nm", "-D", "--undefined-only", str(lib)], capture_output=True,
                               text=True, check=True).stdout
    assert not [ln for ln in undefined.splitlines() if " Py" in ln or " _Py" in ln], undefined
    needed = subprocess.run(["readelf", "-d", str(lib)], capture_output=True, text=True,
                            check=True).stdout
    assert "libpython" not in needed
    exported = subprocess.run(["nm", "-D", "--defined-only", str(lib)], capture_output=True,
                              text=True, check=True).stdout
    names = {ln.split()[-1] for ln in exported.splitlines() if " T " in ln}
    # exactly the FMI 2.0 co-simulation API and the doctor's report (`drillcosim doctor`)
    assert names == FMI2_CS_FUNCTIONS | {"drillcosim_doctor"}
    # of the building machine only the building interpreter is recorded (the last candidate)
    strings = subprocess.run(["strings", str(lib)], capture_output=True, text=True,
                             check=True).stdout.splitlines()
    paths = [s for s in strings if s.startswith("/") and s != "/dev/null"]
    assert paths == [sys.executable], paths


def _c_code(text: str) -> str:
    """C text without comments, string/char literals, and with continued lines joined."""
    import re

    text = re.sub(r"/\*.*?\*/", " ", text, flags=re.S)
    text = re.sub(r"//[^\n]*", " ", text)
    # string and char literals in one left-to-right pass: a '"' char literal opens no string
    text = re.sub(r"""("(\\.|[^"\\])*")|('(\\.|[^'\\])*')""",
                  lambda m: '""' if m.group(1) else "''", text)
    return text.replace("\\\n", " ")


def test_the_c_sources_have_one_exit_per_function_and_use_the_official_headers() -> None:
    """Fails on a second ``return`` in a function, a macro with a ``return``, or FMI types
    declared by us instead of taken from the official headers."""
    import re

    from drillcosim.fmu_src.wrapper import HERE, SOURCES

    for src in SOURCES:
        code = _c_code(src.read_text())
        for line in code.splitlines():
            if line.lstrip().startswith("#define"):
                assert not re.search(r"\breturn\b", line), f"{src.name}: {line}"
        depth, returns, start = 0, 0, 0
        for m in re.finditer(r"[{}]|\breturn\b", code):
            if m.group() == "{":
                if depth == 0:
                    returns, start = 0, m.start()
                depth += 1
            elif m.group() == "}":
                depth -= 1
            elif depth > 0:
                returns += 1
                head = code[:start].rstrip().splitlines()[-1]
                assert returns <= 1, f"{src.name}: a second return in {head!r}"
        assert depth == 0, src.name
        assert not re.search(r"typedef[^;]*\bfmi2(Status|Component|Real|CallbackFunctions)\b",
                             code), src.name
    assert "#include \"fmi2/fmi2Functions.h\"" in (HERE / "dcs_wrapper.h").read_text()
    license_text = (HERE / "fmi2" / "LICENSE.txt").read_text()
    assert "tag v2.0.5" in license_text and "Redistribution and use in source" in license_text


def test_native_fmus_layout_and_validation(native_dir: Path) -> None:
    for name, recipe in RECIPES.items():
        fmu = native_dir / f"{name}.fmu"
        assert validate_fmu(str(fmu)) == []
        with zipfile.ZipFile(fmu) as zf:
            assert zf.read("resources/slaveclass.txt").decode().strip() == name
            assert tuple(zf.read("resources/python_requires.txt").decode().split()) == (
                recipe.requires)
            # ours for each platform with a compiler here; no pythonfmu binary left
            assert [n for n in zf.namelist() if n.startswith("binaries/")] == [
                p.library_name(name) for p in select().platforms]


def test_null_component_and_platform_calls(native_dir: Path, tmp_path: Path) -> None:
    d = extract(str(native_dir / "StrainController.fmu"), unzipdir=str(tmp_path / "u"))
    lib = ctypes.CDLL(str(Path(d) / "binaries" / "linux64" / "StrainController.so"))
    lib.fmi2GetTypesPlatform.restype = ctypes.c_char_p
    lib.fmi2GetVersion.restype = ctypes.c_char_p
    assert lib.fmi2GetTypesPlatform() == b"default" and lib.fmi2GetVersion() == b"2.0"
    lib.fmi2DoStep.argtypes = [ctypes.c_void_p, ctypes.c_double, ctypes.c_double, ctypes.c_int]
    assert lib.fmi2DoStep(None, 0.0, 1e-3, 1) == ERROR
    assert lib.fmi2EnterInitializationMode(None) == ERROR
    assert lib.fmi2GetReal(None, None, ctypes.c_size_t(0), None) == ERROR
    assert lib.fmi2Terminate(None) == ERROR
    lib.fmi2FreeInstance(None)  # tolerated


# ------------------------------------------------------------- the fast Real boundary
BUFFER_SCRIPT = PRELUDE + textwrap.dedent("""
    import numpy as np
    fmu = sys.argv[1]
    plant = "DrillstringPlant" in fmu
    s, vr, d = open_fmu(fmu, "buf")
    with open(os.path.join(d, "resources", "slavemodule.txt")) as f:
        mod = sys.modules[f.read().strip()]
    cls = getattr(mod, "DrillstringPlant" if plant else "StrainController")
    calls = {"get_real": 0, "set_real": 0, "do_step": 0}
    for name in calls:  # count the Python calls the wrapper makes
        def wrap(f, name=name):
            def counted(self, *a):
                calls[name] += 1
                return f(self, *a)
            return counted
        setattr(cls, name, wrap(getattr(cls, name)))
    ins = [vr[n] for n in cls.REAL_INPUTS]
    outs = [vr[n] for n in cls.REAL_OUTPUTS]
    param = vr["gravity" if plant else "gain"]
    s.setupExperiment(startTime=0.0)
    s.enterInitializationMode()
    init_outputs = s.getReal(outs)            # initial unknowns: computed by Python
    init_calls = dict(calls)
    s.exitInitializationMode()
    inst = [o for o in __import__("gc").get_objects() if isinstance(o, cls)][0]
    fast, mixed, inputs = [], [], []
    amp = 300.0 if plant else 1e-5
    for k in range(50):
        u = [amp * math.sin(0.1 * k + i) for i in range(len(ins))]
        s.setReal(ins, u)                     # inputs only: the C buffer
        inputs.append([u, inst.inputs.tolist()])
        s.doStep(k * 1e-3, 1e-3)
        fast.append(s.getReal(outs + ins))    # outputs and inputs: the C buffers
        mixed.append(s.getReal(outs + [param]))  # with a parameter: Python's get_real
    print(json.dumps({"calls": calls, "init_calls": init_calls, "fast": fast, "mixed": mixed,
                      "inputs": inputs, "python_outputs": inst.outputs.tolist(),
                      "init_outputs": init_outputs, "errors": [m for m in messages if m[0]]}))
""")


@pytest.mark.parametrize("name", ["StrainController", "DrillstringPlant"])
def test_real_inputs_and_outputs_cross_without_python_calls(name: str, native_dir: Path) -> None:
    """Step mode: getReal/setReal of the buffered variables never call Python; one call a step,
    none where the FMU's compiled step runs (the plant; a controller alone in a process without
    numba loaded steps in Python: ``controller/acceleration.py``).

    Fails if the wrapper routes them through the slave's get_real/set_real, or if the C
    buffers and the slave's arrays disagree (a wrong slot, a stale view).
    """
    out = run_script(BUFFER_SCRIPT, str(native_dir / f"{name}.fmu"))
    assert out["errors"] == []
    assert out["init_calls"]["get_real"] == 1  # initialization mode goes through Python
    calls = out["calls"]
    steps = 0 if name == "DrillstringPlant" else 50  # the plant's compiled step: no do_step
    assert calls == {"get_real": 1 + 50, "set_real": 0, "do_step": steps}  # +50: the mixed gets
    for (u, seen), fast, mixed in zip(out["inputs"], out["fast"], out["mixed"]):
        assert u == seen  # setReal wrote the slave's own input array
        n_out = len(mixed) - 1
        assert fast[:n_out] == mixed[:n_out]  # the C buffer equals Python's get_real
        assert fast[n_out:] == u
    assert out["fast"][-1][:len(out["python_outputs"])] == out["python_outputs"]
    assert np.ptp(np.array(out["fast"])[:, 0]) > 0


# ----------------------------------------------------------------- statuses (subprocess)
STATUS_SCRIPT = PRELUDE + textwrap.dedent("""
    case, fmu = sys.argv[1:3]
    plant = "DrillstringPlant" in fmu
    s, vr, d = open_fmu(fmu, case)
    out = {}
    if case == "before_init":
        out["step"] = call(s.doStep, 0.0, 1e-3)
        s.setupExperiment(startTime=0.0)
        s.enterInitializationMode()
        s.exitInitializationMode()
        out["after"] = call(s.doStep, 0.0, 1e-3)
    else:
        s.setupExperiment(startTime=0.0)
        s.enterInitializationMode()
        if case == "bad_param":
            if plant:
                s.setReal([vr["contact.stiffness"]], [-1.0])
            else:
                s.setReal([vr["gain"]], [-5.0])
        out["exit"] = call(s.exitInitializationMode)
        if case == "bad_param":
            out["step"] = call(s.doStep, 0.0, 1e-3)
        elif case == "nan_input":
            inp = "actuator1_force_E" if plant else "strain1_E"
            out["ok"] = call(s.doStep, 0.0, 1e-3)
            s.setReal([vr[inp]], [float("nan")])
            out["step"] = call(s.doStep, 1e-3, 1e-3)
            s.setReal([vr[inp]], [0.0])
            out["retry"] = call(s.doStep, 1e-3, 1e-3)
        elif case == "diverge":
            s.setReal([vr["actuator1_force_C"]], [1e12])
            t, steps = 0.0, []
            for _ in range(400):
                st = call(s.doStep, t, 1e-3)
                steps.append(st)
                if st:
                    break
                t += 1e-3
            out["steps"] = steps
            out["again"] = call(s.doStep, t, 1e-3)
        elif case == "unknown_vr":
            try:
                s.getReal([99999])
                out["get"] = 0
            except FMICallException as exc:
                out["get"] = int(exc.status)
            out["set"] = call(s.setReal, [99999], [1.0])
            out["step"] = call(s.doStep, 0.0, 1e-3)  # no deferred discard any more
        elif case == "set_output":
            out_name = "body11_X" if plant else "actuator1_force_C"
            out["set"] = call(s.setReal, [vr[out_name]], [1.0])
            out["step"] = call(s.doStep, 0.0, 1e-3)
        elif case == "states_after_terminate":
            out["step"] = call(s.doStep, 0.0, 1e-3)
            s.terminate()
            out["after_terminate"] = call(s.doStep, 1e-3, 1e-3)
    out["messages"] = messages
    s.freeInstance()
    print(json.dumps(out), flush=True)
""")


def status_case(fmu: Path, case: str) -> dict:
    return run_script(STATUS_SCRIPT, case, str(fmu), timeout=300)


def texts(out: dict, status: int | None = None) -> str:
    return "\n".join(m for s, _c, m in out["messages"] if status is None or s == status)


@pytest.mark.parametrize("name", ["StrainController", "DrillstringPlant"])
def test_out_of_range_parameter_is_fmi2error_at_initialization(name, native_dir) -> None:
    out = status_case(native_dir / f"{name}.fmu", "bad_param")
    assert out["exit"] == ERROR
    param = "contact.stiffness" if name == "DrillstringPlant" else "gain"
    assert param in texts(out, ERROR), texts(out)
    assert any(c == "logStatusError" for _s, c, _m in out["messages"])
    assert out["step"] == ERROR  # never a silent run


@pytest.mark.parametrize("name", ["StrainController", "DrillstringPlant"])
def test_non_finite_input_is_fmi2error_and_instance_recovers(name, native_dir) -> None:
    out = status_case(native_dir / f"{name}.fmu", "nan_input")
    assert (out["exit"], out["ok"], out["step"], out["retry"]) == (OK, OK, ERROR, OK)
    assert "nan" in texts(out, ERROR) and "finite" in texts(out, ERROR)


def test_divergence_is_fmi2discard(native_dir: Path) -> None:
    out = status_case(native_dir / "DrillstringPlant.fmu", "diverge")
    assert out["steps"][-1] == DISCARD and set(out["steps"][:-1]) <= {OK}
    assert out["again"] == DISCARD  # halted until a saved state is restored
    assert "diverged" in texts(out, DISCARD)


@pytest.mark.parametrize("name", ["StrainController", "DrillstringPlant"])
def test_misuse_is_fmi2error_never_a_crash(name, native_dir) -> None:
    fmu = native_dir / f"{name}.fmu"
    out = status_case(fmu, "before_init")
    assert (out["step"], out["after"]) == (ERROR, OK)
    assert "before initialization" in texts(out, ERROR)
    out = status_case(fmu, "unknown_vr")
    assert (out["get"], out["set"], out["step"]) == (ERROR, ERROR, OK)
    assert "unknown value reference 99999" in texts(out, ERROR)
    out = status_case(fmu, "set_output")
    assert (out["set"], out["step"]) == (ERROR, OK)
    out = status_case(fmu, "states_after_terminate")
    assert (out["step"], out["after_terminate"]) == (OK, ERROR)


# ---------------------------------------------------- exceptions and heap (subprocess)
RAISER_SCRIPT = PRELUDE + textwrap.dedent("""
    fmu, loops = sys.argv[1], int(sys.argv[2])
    md = read_model_description(fmu)
    d = extract(fmu)
    out = {"bad_step": [], "good_step": [], "exit_raise": [], "exit_status": [], "get": []}
    for k in range(loops):
        s, vr, _ = open_fmu(fmu, f"r{k}", d)
        s.setupExperiment(startTime=0.0)
        s.enterInitializationMode()
        s.exitInitializationMode()
        s.setReal([vr["x"]], [-1.0])
        out["bad_step"].append(call(s.doStep, 0.0, 0.1))   # ValueError -> fmi2Error
        s.setReal([vr["x"]], [2.0])
        out["good_step"].append(call(s.doStep, 0.0, 0.1))  # same instance still works
        try:
            s.getReal([12345])                               # KeyError -> fmi2Error
            out["get"].append(0)
        except FMICallException as exc:
            out["get"].append(int(exc.status))
        out["y"] = s.getReal([vr["y"]])[0]
        s.terminate()
        s.freeInstance()
        t, vr2, _ = open_fmu(fmu, f"q{k}", d)                # a new instance works
        t.setupExperiment(startTime=0.0)
        t.enterInitializationMode()
        t.setReal([vr2["x"]], [1000.0])
        out["exit_raise"].append(call(t.exitInitializationMode))
        t.setReal([vr2["x"]], [60.0])
        out["exit_status"].append(call(t.exitInitializationMode))  # returns Fmi2Status.error
        t.setReal([vr2["x"]], [1.0])
        out["exit_ok"] = call(t.exitInitializationMode)
        out["step_ok"] = call(t.doStep, 0.0, 0.5)
        out["y2"] = t.getReal([vr2["y"]])[0]
        t.freeInstance()
    out["messages"] = messages[:12]
    out["n_messages"] = len(messages)
    print(json.dumps(out), flush=True)
""")


def test_exceptions_are_fmi2error_and_instances_stay_usable_no_heap_corruption(
        raiser_fmu: Path) -> None:
    loops = 50
    out = run_script(RAISER_SCRIPT, str(raiser_fmu), str(loops),
                     env=dict(ENV, MALLOC_CHECK_="3", MALLOC_PERTURB_="165"), timeout=300)
    assert out["bad_step"] == [ERROR] * loops
    assert out["good_step"] == [OK] * loops and out["y"] == pytest.approx(0.2)
    assert out["get"] == [ERROR] * loops
    assert out["exit_raise"] == [ERROR] * loops and out["exit_status"] == [ERROR] * loops
    assert (out["exit_ok"], out["step_ok"], out["y2"]) == (OK, OK, 0.5)
    msgs = out["messages"]
    assert any(s == ERROR and c == "logStatusError" and "ValueError: x = -1.0 is negative" in m
               and "Traceback" in m for s, c, m in msgs), msgs
    assert any("KeyError: 12345" in m for _s, _c, m in msgs), msgs
    assert any("RuntimeError: x = 1000.0 is too large" in m for _s, _c, m in msgs), msgs
    assert any("x > 50 is refused" in m for _s, _c, m in msgs), msgs


def test_instantiate_failure_returns_null_and_logs(raiser_fmu: Path, tmp_path: Path) -> None:
    broken = tmp_path / "Raiser.fmu"
    slave_file = f"resources/{shipped_modules(raiser_fmu)[RAISER.slave_module]}.py"
    with zipfile.ZipFile(raiser_fmu) as src, zipfile.ZipFile(broken, "w") as dst:
        for info in src.infolist():
            data = src.read(info.filename)
            if info.filename == slave_file:
                data = data.replace(b"self.x = 0.0", b"self.x = 1 / 0")
            dst.writestr(info, data)
    code = PRELUDE + textwrap.dedent("""
        from fmpy.fmi2 import FMU2Slave
        fmu = sys.argv[1]
        try:
            open_fmu(fmu, "broken")
            res = "instantiated"
        except Exception as exc:
            res = type(exc).__name__
        print(json.dumps({"res": res, "messages": messages}))
    """)
    out = run_script(code, str(broken), env=dict(ENV, MALLOC_CHECK_="3"))
    assert out["res"] != "instantiated"
    assert any("ZeroDivisionError" in m for _s, _c, m in out["messages"]), out


# --------------------------------------------------------------------------- FMU state
STATE_SCRIPT = PRELUDE + textwrap.dedent("""
    import numpy as np
    fmu = sys.argv[1]
    s, vr, _ = open_fmu(fmu, "st")
    plant = "DrillstringPlant" in fmu
    inp = vr["actuator1_force_C"] if plant else vr["strain1_C"]
    outs = [vr[n] for n in (["strain1_C", "body11_X", "total_energy"] if plant
                            else ["actuator1_force_C"])]
    s.setupExperiment(startTime=0.0)
    s.enterInitializationMode()
    if not plant:
        s.setReal([vr["lag_time_constant"]], [5e-3])
    s.exitInitializationMode()
    def run(k0, n):
        rows = []
        for k in range(k0, k0 + n):
            s.setReal([inp], [(300.0 if plant else 1e-5) * math.sin(0.05 * k)])
            s.doStep(k * 1e-3, 1e-3)
            rows.append(s.getReal(outs))
        return rows
    run(0, 40)
    state = s.getFMUstate()
    blob = s.serializeFMUstate(state)
    a = run(40, 40)
    s.setFMUstate(state)
    b = run(40, 40)
    s.freeFMUstate(state)
    state2 = s.deSerializeFMUstate(blob)
    s.setFMUstate(state2)
    c = run(40, 40)
    s.freeFMUstate(state2)
    print(json.dumps({"a": a, "b": b, "c": c, "errors": [m for m in messages if m[0]]}))
""")


@pytest.mark.parametrize("name", ["StrainController", "DrillstringPlant"])
def test_fmu_state_get_set_serialize_bit_identical(name: str, native_dir: Path) -> None:
    out = run_script(STATE_SCRIPT, str(native_dir / f"{name}.fmu"))
    assert out["errors"] == []
    assert out["a"] == out["b"] == out["c"]
    assert np.ptp(np.array(out["a"])) > 0


# ------------------------------------------------------------------------ third parties
@pytest.mark.interop
def test_libcosim_runs_native_fmus_like_our_master(native_dir: Path, tmp_path: Path) -> None:
    import_module("libcosimpy")
    from drillcosim.cosim.master.master import Master
    from drillcosim.cosim.master.ssp import export_ssp
    from drillcosim.cosim.scenario.build import build_system
    from drillcosim.cosim.scenario.config import load_config
    from support.engines import LIBCOSIM_HOST as HOST

    config = load_config("paper_restricted_actuator", {
        "controller.gain": 5e8, "cosim.step": 1e-3, "cosim.controller_sample_period": 2e-3,
        "cosim.algorithm": "jacobi", "cosim.order": ["plant", "controller"]})
    ss = build_system(config, "fmu", fmu_dir=native_dir)
    n = 200
    ours = Master(ss.system).simulate(n * 1e-3, ss.outputs).data
    exp = export_ssp(ss.system, tmp_path / "sys.ssp")
    with zipfile.ZipFile(exp.path) as zf:  # the archive holds the native-wrapped FMUs
        inner = zipfile.ZipFile(zf.open("resources/StrainController.fmu"))
        assert "resources/slaveclass.txt" in inner.namelist()
    host = tmp_path / "host.py"
    host.write_text(HOST)
    proc = subprocess.run([sys.executable, str(host), str(exp.path), "1000000", str(n),
                           json.dumps(list(ss.outputs))], cwd=tmp_path, env=ENV,
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr[-3000:]
    res = json.loads([ln for ln in proc.stdout.splitlines() if ln.startswith("RESULT ")][-1]
                     .removeprefix("RESULT "))
    assert res["ok"]
    lib = np.array(res["rows"])
    for j, name in enumerate(ss.outputs):
        mine = ours[name][1:]
        scale = float(np.max(np.abs(mine)))
        np.testing.assert_allclose(lib[:, j], mine, rtol=0, atol=1e-9 * scale + 1e-300,
                                   err_msg=name)
    forces = [j for j, nm in enumerate(ss.outputs) if "force_C" in nm]
    assert np.max(np.abs(lib[:, forces])) > 0


# --------------------------------------------------------------- hosts without Python
# (fixtures host and bare_python: conftest.py)


def plain_env(tmp_path: Path, path: str = "/usr/bin:/bin", **extra: str) -> dict[str, str]:
    """A host's environment: no PYTHON*/DRILLCOSIM_*/VIRTUAL_ENV, a HOME of its own."""
    env = {k: v for k, v in ENV.items()
           if not k.startswith(("PYTHON", "DRILLCOSIM", "VIRTUAL_ENV", "XDG_CONFIG"))}
    env.update(PATH=path, HOME=str(tmp_path / "home"), **extra)
    return env


def controller_run(host: Path, native_dir: Path, tmp_path: Path, env: dict[str, str],
                   conf: str | None = None) -> subprocess.CompletedProcess:
    """The controller FMU in the C host: strain1_C = 1e-6 held, 4 steps of 1 ms."""
    d = c_host.unzip(native_dir / "StrainController.fmu", tmp_path / "unzip")
    if conf is not None:
        (d / "drillcosim.conf").write_text(conf)
    md = read_model_description(str(native_dir / "StrainController.fmu"))
    vr = {v.name: v.valueReference for v in md.modelVariables}
    return c_host.run_host(host, d, "StrainController", 4e-3, 1e-3,
                           [f"r:{vr['strain1_C']}=1e-6"], [vr["actuator1_force_C"]], env,
                           tmp_path)


def test_c_host_without_python_runs_the_fmu(host: Path, native_dir: Path,
                                            tmp_path: Path) -> None:
    """A plain C program (no Python in the process, PYTHONHOME/PYTHONPATH leaking in)."""
    env = plain_env(tmp_path, PYTHONHOME="/nonexistent", PYTHONPATH="/nonexistent")
    proc = controller_run(host, native_dir, tmp_path, env)
    assert proc.returncode == 0, (proc.stdout, proc.stderr)
    assert proc.stdout.splitlines()[0] == f"BAD {ERROR}"  # a negative step: refused
    assert "dt = -1.0" in proc.stderr
    got = c_host.rows(proc.stdout)
    gain = 1e9  # the FMU's default; held over the step, no lag
    assert got == [[k * 1e-3, 0.0 if k == 0 else gain * 1e-6] for k in range(5)]


def test_the_host_keeps_its_locale_and_signal_handlers(host: Path, native_dir: Path,
                                                       tmp_path: Path) -> None:
    """Python's start sets LC_CTYPE from the environment (no PyPreConfig in the stable ABI):
    the wrapper restores the host's; Py_InitializeEx(0) installs no signal handler."""
    env = plain_env(tmp_path, LANG="C.UTF-8", LC_CTYPE="C.UTF-8")
    proc = controller_run(host, native_dir, tmp_path, env)
    assert proc.returncode == 0, proc.stderr
    assert "HOST locale=C sigint=unchanged" in proc.stderr.splitlines(), proc.stderr


def test_no_usable_python_is_one_message_listing_what_each_candidate_lacked(
        host: Path, native_dir: Path, bare_python: Path, tmp_path: Path) -> None:
    env = plain_env(tmp_path, DRILLCOSIM_PYTHON=str(bare_python))
    proc = controller_run(host, native_dir, tmp_path, env)
    assert proc.returncode == 3, (proc.stdout, proc.stderr)  # NULL; the host goes on and exits
    errors = c_host.log_lines(proc.stderr, ERROR)
    assert len(errors) == 1 and len(c_host.log_lines(proc.stderr)) == 1, proc.stderr
    text = proc.stderr
    assert "no usable Python found" in text and "CPython 3.10 to 3.13 with numpy" in text
    assert f"1. $DRILLCOSIM_PYTHON = {bare_python}: Python 3.{sys.version_info.minor}" in text
    assert "lacks numpy (ModuleNotFoundError: No module named 'numpy')" in text
    assert "an explicit choice: no other candidate is tried" in text
    assert "How to fix: install numpy into a CPython 3.10 to 3.13" in text
    assert "PYTHONHOME" in text and "drillcosim doctor" in text


@pytest.mark.parametrize("conf", ["python = {good}\n", "# site setup\npython = /nope/python3\n",
                                  "pithon = typo\n"])
def test_config_file_in_the_unzip_folder_is_an_explicit_choice(
        host: Path, native_dir: Path, tmp_path: Path, conf: str) -> None:
    env = plain_env(tmp_path)
    proc = controller_run(host, native_dir, tmp_path, env, conf.format(good=sys.executable))
    cfg = tmp_path / "unzip" / "drillcosim.conf"
    if "{good}" in conf:
        assert proc.returncode == 0, proc.stderr
        assert f"2. config file {cfg}: python = {sys.executable}: Python 3." in proc.stderr
        assert "used" in proc.stderr and "3. on PATH" not in proc.stderr  # PATH not searched
    else:
        assert proc.returncode == 3 and len(c_host.log_lines(proc.stderr, ERROR)) == 1
        assert f"config file {cfg}" in proc.stderr and "explicit choice" in proc.stderr
        assert ("not found" in proc.stderr) == ("nope" in conf)
        assert ("no line 'python = /path/to/python3'" in proc.stderr) == ("pithon" in conf)


def test_path_candidates_in_order_each_checked_in_a_child(
        host: Path, native_dir: Path, bare_python: Path, tmp_path: Path) -> None:
    first = bare_python.parent  # a venv without numpy (pyvenv.cfg beside bin/)
    second = Path(sys.executable).parent  # this test's venv: has numpy
    broken = tmp_path / "broken"
    broken.mkdir()
    (broken / "python3").write_text("#!/bin/sh\necho no python here >&2\nexit 7\n")
    (broken / "python3").chmod(0o755)
    env = plain_env(tmp_path, path=f"{first}:relative/bin:{broken}:{second}:/usr/bin:/bin")
    proc = controller_run(host, native_dir, tmp_path, env)
    assert proc.returncode == 0, proc.stderr
    report = proc.stderr
    lines = [ln.strip() for ln in report.splitlines() if ln.strip().startswith("3. on PATH")]
    assert lines[0].startswith(f"3. on PATH: {first}/python3: Python 3.")
    assert "lacks numpy" in lines[0]
    assert lines[1] == (f"3. on PATH: {broken}/python3: does not run as a Python 3 interpreter "
                        f"(exit status 7: no python here)")
    assert lines[2].startswith(f"3. on PATH: {second}/python3: Python 3.") and "used" in lines[2]
    assert len(lines) == 3  # the search stops at the first that fits; relative entries skipped


def unsupported_python_version() -> str | None:
    """A runnable Python 3 outside 3.10-3.13, if the machine has one (``python3.X`` on PATH, or
    a pyenv installation)."""
    import glob

    found = [shutil.which(f"python3.{minor}") for minor in (9, 14, 8, 15, 7)]
    found += sorted(glob.glob(os.path.expanduser("~/.pyenv/versions/3.*/bin/python3")))
    for exe in filter(None, found):
        proc = subprocess.run([exe, "-c", "import sys; print(sys.version_info[1])"],
                              capture_output=True, text=True)
        if proc.returncode == 0 and not 10 <= int(proc.stdout.strip() or 0) <= 13:
            return exe
    return None


VERSION_SCRIPT = textwrap.dedent("""
    import ctypes, sys
    lib = ctypes.CDLL(sys.argv[1])
    LOG = ctypes.CFUNCTYPE(None, ctypes.c_void_p, ctypes.c_char_p, ctypes.c_int, ctypes.c_char_p,
                           ctypes.c_char_p)
    msgs = []
    log = LOG(lambda env, name, st, cat, msg: msgs.append((st, msg.decode())))
    class CB(ctypes.Structure):
        _fields_ = [("logger", LOG), ("alloc", ctypes.c_void_p), ("free", ctypes.c_void_p),
                    ("step", ctypes.c_void_p), ("env", ctypes.c_void_p)]
    lib.fmi2Instantiate.restype = ctypes.c_void_p
    c = lib.fmi2Instantiate(b"other", 1, b"", sys.argv[2].encode(), ctypes.byref(CB(log)), 0, 0)
    print("NULL" if c is None else "INSTANCE")
    for st, m in msgs:
        print(st, m)
""")


def test_a_python_host_of_an_unsupported_version_gets_one_clear_message(
        native_dir: Path, tmp_path: Path) -> None:
    other = unsupported_python_version()
    if other is None:
        missing("python3-unsupported", "no Python 3 outside 3.10-3.13 on this machine")
    d = c_host.unzip(native_dir / "StrainController.fmu", tmp_path / "unzip")
    proc = subprocess.run([other, "-c", VERSION_SCRIPT,
                           str(d / "binaries/linux64/StrainController.so"),
                           (d / "resources").as_uri()], capture_output=True, text=True,
                          timeout=120, env=plain_env(tmp_path, path=os.environ["PATH"]))
    assert proc.returncode == 0, proc.stderr
    lines = proc.stdout.splitlines()
    assert lines[0] == "NULL" and len(lines) == 2, lines
    assert lines[1].startswith(f"{ERROR} other: fmi2Instantiate: this process runs Python 3.")
    assert "but the FMU's wrapper runs on CPython 3.10 to 3.13" in lines[1]


# ----------------------------------------------------------------- calling sequence
SEQUENCE_SCRIPT = PRELUDE + textwrap.dedent("""
    fmu = sys.argv[1]
    s, vr, _ = open_fmu(fmu, "seq")
    out = {}
    out["exit_before_enter"] = call(s.exitInitializationMode)
    out["terminate_before_init"] = call(s.terminate)
    s.setupExperiment(startTime=0.0)
    s.enterInitializationMode()
    out["setup_in_init"] = call(s.setupExperiment, None, 0.0)
    out["enter_twice"] = call(s.enterInitializationMode)
    s.exitInitializationMode()
    out["exit_twice"] = call(s.exitInitializationMode)
    out["step"] = call(s.doStep, 0.0, 1e-3)
    out["cancel"] = call(s.cancelStep)
    s.terminate()
    out["step_after_terminate"] = call(s.doStep, 1e-3, 1e-3)
    out["get_after_terminate"] = call(s.getReal, [vr["actuator1_force_C"]])
    s.reset()
    out["setup_after_reset"] = call(s.setupExperiment, None, 0.0)
    out["messages"] = [m for m in messages if m[0]]
    s.freeInstance()
    print(json.dumps(out))
""")


def test_calling_sequence_is_the_state_mask_table(native_dir: Path) -> None:
    out = run_script(SEQUENCE_SCRIPT, str(native_dir / "StrainController.fmu"))
    refused = ["exit_before_enter", "terminate_before_init", "setup_in_init", "enter_twice",
               "exit_twice", "cancel", "step_after_terminate"]
    assert {k: out[k] for k in refused} == dict.fromkeys(refused, ERROR)
    assert (out["step"], out["get_after_terminate"], out["setup_after_reset"]) == (OK, OK, OK)
    texts = [m for _s, _c, m in out["messages"]]
    assert "seq: fmi2ExitInitializationMode is not allowed in state Instantiated (before " \
           "initialization); allowed in: InitializationMode" in texts
    assert "seq: fmi2DoStep is not allowed in state Terminated; allowed in: StepComplete" \
           in texts
    assert "seq: fmi2CancelStep is not allowed in state StepComplete; not supported by this " \
           "FMU" in texts
    assert len(texts) == len(refused)  # one message per refused call


@pytest.mark.needs_cc
def test_the_wrapper_sources_are_named_and_a_stray_c_file_is_not_linked(tmp_path) -> None:
    """The list of wrapper sources is the folder's C files and headers (nothing forgotten), and a
    copy of the wrapper package with a stray C file in it (an installed copy: setuptools reuses a
    checkout's stale ``build/lib``, where a file deleted from the sources stays; seen as
    'multiple definition of fmi2GetStringStatus' after a `pip install .`) still compiles."""
    import importlib.util
    import shutil

    from drillcosim.fmu_src import wrapper

    here = wrapper.HERE
    assert sorted(wrapper.SOURCES) == sorted(here.glob("*.c"))
    assert sorted(wrapper.HEADERS) == sorted([*here.glob("*.h"), *here.glob("fmi2/*.h")])
    copy = tmp_path / "wrapper"
    shutil.copytree(here, copy, ignore=shutil.ignore_patterns("__pycache__"))
    (copy / "stray_old_wrapper.c").write_text(
        '#include "fmi2/fmi2Functions.h"\n'
        'const char* fmi2GetVersion(void) { return "stray"; }\n')
    spec = importlib.util.spec_from_file_location("_dcs_test_wrapper_copy", copy / "__init__.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)   # a separate module object: sys.modules is left alone
    assert module.HERE == copy.resolve()
    assert module.compile_wrapper(tmp_path / "w.so").stat().st_size > 0
