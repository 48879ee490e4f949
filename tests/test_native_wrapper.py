"""The native C FMI wrapper (``fmu_src/wrapper``): statuses, safety, equality with pythonfmu.

Both project FMUs are built once per session with ``wrapper="native"`` (the default)
and once with the ``wrapper="pythonfmu"`` fallback. Runs that compare the two wrappers, misuse and the
heap check run in subprocesses (a crash shows as a failed exit code, and the two
wrappers never share a process).

Statuses under the native wrapper (see the adapters' module docstrings):
out-of-range parameter -> fmi2Error from fmi2ExitInitializationMode naming it;
non-finite input -> fmi2Error from fmi2DoStep; divergence -> fmi2Discard; doStep
before initialization, unknown value reference, NULL component -> fmi2Error; a
Python exception -> fmi2Error and the instance stays usable.
"""

from __future__ import annotations

import ctypes
import dataclasses
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

from drillcosim.fmu_src.build import REGISTRY, FmuSpec, build_one
from drillcosim.fmu_src.wrapper import compile_wrapper

pytestmark = [pytest.mark.needs_cc]

ROOT = Path(__file__).resolve().parents[1]
OK, WARNING, DISCARD, ERROR, FATAL = 0, 1, 2, 3, 4
SPECS = {s.name: s for s in REGISTRY}
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


@pytest.fixture(scope="session")
def pyfmu_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("pythonfmu_fmus")
    for spec in REGISTRY:
        build_one(spec, out, wrapper="pythonfmu")
    return out


#: A slave that raises on request; its script is written by the fixture (a unique temp path).
RAISER = FmuSpec(name="Raiser", script=str(Path(__import__("tempfile").mkdtemp(
    prefix="dcs_raiser_")) / "raiser_slave.py"))


@pytest.fixture(scope="session")
def raiser_fmu(tmp_path_factory: pytest.TempPathFactory) -> Path:
    src = Path(RAISER.script)
    src.parent.mkdir(parents=True, exist_ok=True)
    src.write_text(RAISING_SLAVE)
    return build_one(RAISER, tmp_path_factory.mktemp("raiser"), wrapper="native")


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
    assert {"fmi2Instantiate", "fmi2DoStep", "fmi2GetReal", "fmi2SerializeFMUstate",
            "fmi2GetRealStatus", "fmi2GetTypesPlatform"} <= names
    assert all(n.startswith("fmi2") or n.startswith("_") for n in names), names


def test_native_fmus_layout_and_validation(native_dir: Path, pyfmu_dir: Path) -> None:
    for name in SPECS:
        fmu = native_dir / f"{name}.fmu"
        assert validate_fmu(str(fmu)) == []
        with zipfile.ZipFile(fmu) as zn, zipfile.ZipFile(pyfmu_dir / f"{name}.fmu") as zp:
            assert zn.read("resources/slaveclass.txt").decode().strip() == name
            assert zn.read(f"binaries/linux64/{name}.so") != zp.read(
                f"binaries/linux64/{name}.so")
            assert zn.read("modelDescription.xml").split(b"guid=")[0] == zp.read(
                "modelDescription.xml").split(b"guid=")[0]


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


# --------------------------------------------------------------- same results as pythonfmu
SIMULATE = textwrap.dedent("""
    import json, os, sys
    import numpy as np
    from fmpy import simulate_fmu
    fmu, n, fast_exit = sys.argv[1], int(sys.argv[2]), sys.argv[3] == "fast-exit"
    dt = 1e-3
    t = np.arange(n + 1) * dt
    md_inputs = {"StrainController": ["strain1_C", "strain1_E", "strain2_C", "strain2_E"],
                 "DrillstringPlant": ["actuator1_force_C", "actuator1_force_E",
                                      "actuator2_force_C", "actuator2_force_E"]}
    name = fmu.rsplit("/", 1)[1][:-4]
    amp = 1e-5 if name == "StrainController" else 300.0
    sig = np.zeros(n + 1, dtype=[("time", float)] + [(x, float) for x in md_inputs[name]])
    sig["time"] = t
    for i, x in enumerate(md_inputs[name]):
        sig[x] = amp * np.sin(2 * np.pi * 5 * t + i)
    start = {"lag_time_constant": 2e-3, "gain": 7e8} if name == "StrainController" else {}
    res = simulate_fmu(fmu, stop_time=n * dt, step_size=dt, output_interval=dt, input=sig,
                       start_values=start)
    print(json.dumps({k: res[k].tolist() for k in res.dtype.names}), flush=True)
    if fast_exit:
        # pythonfmu 0.7.0 destroys its PyState from the library destructor after Python
        # has finalized: at exit this sometimes aborts with "corrupted double-linked
        # list" (seen here under load, and in test_plant_fmu). The native run exits
        # normally: the native wrapper has no destructor and never finalizes Python.
        os._exit(0)
""")


@pytest.mark.parametrize("name", ["StrainController", "DrillstringPlant"])
def test_simulate_fmu_bit_identical_to_pythonfmu(name: str, native_dir: Path,
                                                 pyfmu_dir: Path) -> None:
    n = 300 if name == "DrillstringPlant" else 2000
    nat = run_script(SIMULATE, str(native_dir / f"{name}.fmu"), str(n), "normal-exit")
    ref = run_script(SIMULATE, str(pyfmu_dir / f"{name}.fmu"), str(n), "fast-exit")
    assert nat.keys() == ref.keys() and len(nat["time"]) == n + 1
    moving = 0
    for key in ref:
        np.testing.assert_array_equal(np.array(nat[key]), np.array(ref[key]), err_msg=key)
        moving += np.ptp(ref[key]) > 0
    assert moving > 3


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
    with zipfile.ZipFile(raiser_fmu) as src, zipfile.ZipFile(broken, "w") as dst:
        for info in src.infolist():
            data = src.read(info.filename)
            if info.filename == f"resources/{RAISER.slave_module}.py":
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
    pytest.importorskip("libcosimpy")
    from drillcosim.cosim.master.master import Master
    from drillcosim.cosim.master.ssp import export_ssp
    from drillcosim.cosim.scenario.scene_system import scene_system
    from drillcosim.plant.scene import load_scene
    from support.engines import LIBCOSIM_HOST as HOST

    sc = load_scene("paper_restricted_actuator", overrides={"controller": {"gain": 5e8}})
    sc = dataclasses.replace(sc, cosim={"step": 1e-3, "controller_sample_period": 2e-3})
    ss = scene_system(sc, native_dir)
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


C_HOST = r"""
#include <dlfcn.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
typedef void (*logger_t)(void *, const char *, int, const char *, const char *, ...);
typedef struct { logger_t logger; void *alloc; void *free; void *step; void *env; } cb_t;
static void logger(void *env, const char *name, int status, const char *cat,
                   const char *msg, ...) {
    va_list ap; (void)env;
    fprintf(stderr, "[%s %d %s] ", name, status, cat);
    va_start(ap, msg); vfprintf(stderr, msg, ap); va_end(ap); fputc('\n', stderr);
}
int main(int argc, char **argv) {
    void *h = dlopen(argv[1], RTLD_NOW | RTLD_LOCAL);
    if (!h) { fprintf(stderr, "%s\n", dlerror()); return 2; }
    void *(*inst)(const char *, int, const char *, const char *, const cb_t *, int, int) =
        (void *(*)(const char *, int, const char *, const char *, const cb_t *, int, int))
        dlsym(h, "fmi2Instantiate");
    int (*setup)(void *, int, double, double, int, double) =
        (int (*)(void *, int, double, double, int, double))dlsym(h, "fmi2SetupExperiment");
    int (*enter)(void *) = (int (*)(void *))dlsym(h, "fmi2EnterInitializationMode");
    int (*exitm)(void *) = (int (*)(void *))dlsym(h, "fmi2ExitInitializationMode");
    int (*step)(void *, double, double, int) =
        (int (*)(void *, double, double, int))dlsym(h, "fmi2DoStep");
    int (*setr)(void *, const unsigned *, size_t, const double *) =
        (int (*)(void *, const unsigned *, size_t, const double *))dlsym(h, "fmi2SetReal");
    int (*getr)(void *, const unsigned *, size_t, double *) =
        (int (*)(void *, const unsigned *, size_t, double *))dlsym(h, "fmi2GetReal");
    void (*freei)(void *) = (void (*)(void *))dlsym(h, "fmi2FreeInstance");
    cb_t cb = {logger, NULL, NULL, NULL, NULL};
    void *c = inst("chost", 1, "", argv[2], &cb, 0, 1);
    if (!c) return 3;
    unsigned in0 = (unsigned)atoi(argv[3]), out0 = (unsigned)atoi(argv[4]);
    int st = setup(c, 0, 0.0, 0.0, 0, 0.0) | enter(c) | exitm(c);
    printf("BAD %d\n", step(c, 0.0, -1.0, 1));
    for (int k = 0; k < 20; k++) {
        double u = 1e-6 * (k + 1), y;
        st |= setr(c, &in0, 1, &u) | step(c, k * 1e-3, 1e-3, 1) | getr(c, &out0, 1, &y);
        printf("%.17g\n", y);
    }
    freei(c);
    printf("STATUS %d\n", st);
    return 0;
}
"""


def test_c_host_without_python_loads_libpython_itself(native_dir: Path, tmp_path: Path) -> None:
    """A plain C program (no Python in the process) runs the native controller FMU."""
    if shutil.which("gcc") is None:
        pytest.skip("no gcc")
    src = tmp_path / "host.c"
    src.write_text(C_HOST)
    exe = tmp_path / "host"
    subprocess.run(["gcc", "-std=c99", "-Wall", "-o", str(exe), str(src), "-ldl"], check=True)
    fmu = native_dir / "StrainController.fmu"
    d = Path(extract(str(fmu), unzipdir=str(tmp_path / "unzip")))
    md = read_model_description(str(fmu))
    vr = {v.name: v.valueReference for v in md.modelVariables}
    env = {k: v for k, v in ENV.items() if not k.startswith(("PYTHON", "VIRTUAL_ENV"))}
    proc = subprocess.run([str(exe), str(d / "binaries/linux64/StrainController.so"),
                           (d / "resources").as_uri(), str(vr["strain1_C"]),
                           str(vr["actuator1_force_C"])], env=env, capture_output=True,
                          text=True, timeout=120)
    assert proc.returncode == 0, (proc.stdout, proc.stderr)
    lines = proc.stdout.split()
    assert lines[:2] == ["BAD", str(ERROR)] and lines[-2:] == ["STATUS", "0"]
    got = [float(x) for x in lines[2:-2]]
    gain = float(next(v.start for v in md.modelVariables if v.name == "gain"))
    assert got == [gain * (1e-6 * (k + 1)) for k in range(20)]  # held over the step, no lag
    assert "[chost 3 logStatusError]" in proc.stderr and "dt = -1.0" in proc.stderr, proc.stderr
