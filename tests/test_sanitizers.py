"""The C code under AddressSanitizer and UndefinedBehaviorSanitizer: no report.

Our wrapper (``fmu_src/wrapper``) and the C controller (``fmu_src/c_controller``) are compiled
with ``clang -fsanitize=address,undefined -fno-sanitize-recover=all -fno-omit-frame-pointer``
(every finding aborts the process) and put into copies of the session's FMUs, then:

* the fuzz campaign (``support/fuzz_fmi.py``, short) on the Python strain controller, the C
  controller and the plant, in Python processes with the sanitizer runtime preloaded
  (``LD_PRELOAD``; Python itself is not instrumented, so leak detection is off: its own
  allocations at exit are not ours);
* a closed loop of the sanitized plant and controller (``support/version_run.py``: each alone,
  then coupled) in such a process;
* the plain C host (``support/fmi2_host.c``) compiled with the sanitizers itself (a clean
  sanitized host, nothing preloaded), where the wrapper finds and starts a Python: the
  controller and the plant;
* handles a host should not pass (a freed FMU state set and freed again, a freed instance
  stepped and freed again): fmi2Error or ignored, and no read of the freed memory (the wrapper
  looks handles up in its registries; reading a magic number through them was a
  heap-use-after-free); for the C controller each case of ``support/bad_handles.py`` (an
  instance used or freed after its free, a state freed twice or used after its free, a made-up
  pointer) in its own process, since its binary shares the wrapper's registry (before, these
  were a heap-use-after-free, a double free or a SEGV under ASan).

Each run must exit normally (a finding is an abort) and print no sanitizer report. Needs clang
and its sanitizer runtime (``.ci/run`` installs Debian's clang when missing): skipped with the
reason otherwise.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest
from fmpy import read_model_description

from drillcosim.fmu_src.build import REGISTRY
from drillcosim.fmu_src.build_c import MODEL_IDENTIFIER, compile_library
from drillcosim.fmu_src.wrapper import HERE as WRAPPER_DIR
from drillcosim.fmu_src.wrapper import compile_shared, compile_wrapper, install_native_wrapper
from support import bad_handles, c_host
from support.required import missing

pytestmark = [pytest.mark.needs_cc, pytest.mark.slow]

HERE = Path(__file__).resolve().parent
SANITIZE = ("-fsanitize=address,undefined", "-fno-sanitize-recover=all",
            "-fno-omit-frame-pointer", "-g", "-O1")
REPORT_MARKERS = ("ERROR: AddressSanitizer", "runtime error:", "ERROR: LeakSanitizer",
                  "UndefinedBehaviorSanitizer")
RECIPES = {r.name: r for r in REGISTRY}
#: Fuzz examples per FMU under the sanitizers (the full campaign is test_reliability_fuzz).
EXAMPLES = {"StrainController": 150, MODEL_IDENTIFIER: 300, "DrillstringPlant": 10}


@pytest.fixture(scope="module")
def asan_runtime() -> Path:
    """The shared ASan (+UBSan) runtime of clang; skips without clang or the runtime."""
    if shutil.which("clang") is None:
        missing("clang-asan", "clang is not on PATH")
    path = Path(subprocess.run(["clang", "-print-file-name=libclang_rt.asan-x86_64.so"],
                               capture_output=True, text=True).stdout.strip())
    if not path.is_absolute() or not path.is_file():
        missing("clang-asan", "clang's AddressSanitizer runtime libclang_rt.asan-x86_64.so is missing")
    return path


def _replace_member(fmu: Path, member: str, data: bytes) -> None:
    tmp = fmu.with_suffix(".tmp")
    with zipfile.ZipFile(fmu) as src, zipfile.ZipFile(tmp, "w", zipfile.ZIP_DEFLATED) as dst:
        for info in src.infolist():
            dst.writestr(info, data if info.filename == member else src.read(info.filename))
    os.replace(tmp, fmu)


@pytest.fixture(scope="module")
def sanitized(asan_runtime: Path, project_fmus: dict[str, Path], c_controller_fmu: Path,
              tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """Copies of the FMUs with sanitized binaries: ``{model identifier: .fmu}``."""
    out = tmp_path_factory.mktemp("sanitized")
    wrapper = compile_wrapper(out / "wrapper.so", cc="clang", flags=SANITIZE)
    fmus = {}
    for name in ("StrainController", "DrillstringPlant"):
        fmus[name] = out / f"{name}.fmu"
        shutil.copy2(project_fmus[name], fmus[name])
        install_native_wrapper(fmus[name], name, wrapper, RECIPES[name].requires)
    lib = compile_library(out / f"{MODEL_IDENTIFIER}.so", cc="clang", flags=SANITIZE)
    fmus[MODEL_IDENTIFIER] = out / f"{MODEL_IDENTIFIER}.fmu"
    shutil.copy2(c_controller_fmu, fmus[MODEL_IDENTIFIER])
    _replace_member(fmus[MODEL_IDENTIFIER], f"binaries/linux64/{MODEL_IDENTIFIER}.so",
                    lib.read_bytes())
    return fmus


def sanitizer_env(**extra: str) -> dict[str, str]:
    """Options: a finding aborts; no leak check (Python's own allocations at exit); no
    symbolizer (llvm-symbolizer started from a process with the runtime preloaded inherits
    LD_PRELOAD and hangs: reports show module+offset, for addr2line)."""
    symbolize = "0" if "LD_PRELOAD" in extra else "1"
    env = dict(os.environ, OPENBLAS_NUM_THREADS="1",
               ASAN_OPTIONS=f"detect_leaks=0:abort_on_error=1:symbolize={symbolize}",
               UBSAN_OPTIONS=f"print_stacktrace=1:halt_on_error=1:symbolize={symbolize}")
    env["PYTHONPATH"] = os.pathsep.join([str(HERE), env.get("PYTHONPATH", "")])
    env.update(extra)
    return env


def assert_clean(proc: subprocess.CompletedProcess, what: str) -> None:
    text = proc.stdout + proc.stderr
    found = [m for m in REPORT_MARKERS if m in text]
    assert proc.returncode == 0 and not found, (
        f"{what}: exit {proc.returncode}, sanitizer report {found}\n{proc.stderr[-6000:]}")


PLANTED = r"""
#include <stdlib.h>
#define EXPORT __attribute__((visibility("default")))
EXPORT int planted(int k) { int *a = (int *)malloc(4 * sizeof *a); int v; free(a); v = a[k]; return v; }
EXPORT int shifted(int k) { return 1 << k; }
"""
PLANTED_CALL = """
import ctypes, sys
lib = ctypes.CDLL(sys.argv[1])
print(getattr(lib, sys.argv[2])(int(sys.argv[3])))
"""


def test_the_sanitized_libraries_are_instrumented(sanitized: dict[str, Path]) -> None:
    """The check below is real: the binaries call the sanitizer runtime."""
    for name, fmu in sanitized.items():
        with zipfile.ZipFile(fmu) as zf:
            data = zf.read(f"binaries/linux64/{name}.so")
        assert b"__asan_report" in data and b"__ubsan_handle" in data, name


@pytest.mark.parametrize(("function", "arg", "marker"), [
    ("planted", 1, "ERROR: AddressSanitizer: heap-use-after-free"),
    ("shifted", 40, "runtime error: shift exponent 40"),
])
def test_a_planted_bug_is_reported_by_this_harness(function: str, arg: int, marker: str,
                                                   asan_runtime: Path, tmp_path: Path) -> None:
    """Negative control: a read after free and an undefined shift in a library built with the
    same flags and loaded the same way (preloaded runtime, these options) abort with a report."""
    src = tmp_path / "planted.c"
    src.write_text(PLANTED)
    lib = compile_shared("the planted bug", [src], tmp_path / "planted.so", cc="clang",
                         flags=SANITIZE)
    proc = subprocess.run([sys.executable, "-c", PLANTED_CALL, str(lib), function, str(arg)],
                          env=sanitizer_env(LD_PRELOAD=str(asan_runtime)), capture_output=True,
                          text=True, timeout=120)
    assert proc.returncode != 0 and marker in proc.stderr, proc.stderr[-3000:]


@pytest.mark.parametrize("name", list(EXAMPLES))
def test_fuzz_campaign_under_the_sanitizers(name: str, sanitized: dict[str, Path],
                                            asan_runtime: Path, tmp_path: Path) -> None:
    proc = subprocess.run([sys.executable, str(HERE / "support" / "fuzz_fmi.py"),
                           str(sanitized[name]), "--examples", str(EXAMPLES[name])],
                          cwd=tmp_path, env=sanitizer_env(LD_PRELOAD=str(asan_runtime)),
                          capture_output=True, text=True, timeout=900)
    assert_clean(proc, f"fuzzing {name}")
    assert '"fatal": 0' in proc.stdout and '"healthy_equal": true' in proc.stdout, proc.stdout


def test_closed_loop_under_the_sanitizers(sanitized: dict[str, Path], asan_runtime: Path,
                                          tmp_path: Path) -> None:
    proc = subprocess.run([sys.executable, str(HERE / "support" / "version_run.py"),
                           str(sanitized["DrillstringPlant"]), str(sanitized["StrainController"])],
                          cwd=tmp_path, env=sanitizer_env(LD_PRELOAD=str(asan_runtime)),
                          capture_output=True, text=True, timeout=900)
    assert_clean(proc, "the closed loop")
    assert '"closed_loop": [[' in proc.stdout


def test_a_sanitized_c_host_runs_the_sanitized_fmus(sanitized: dict[str, Path],
                                                    asan_runtime: Path, tmp_path: Path) -> None:
    """No Python in the host: the wrapper finds one and starts it in the sanitized process."""
    host = tmp_path / "fmi2_host_asan"
    subprocess.run(["clang", "-std=c99", "-Wall", "-Wextra", "-Werror", *SANITIZE,
                    f"-I{WRAPPER_DIR / 'fmi2'}", "-o", str(host), str(c_host.SOURCE), "-ldl"],
                   check=True, capture_output=True, text=True)
    env = sanitizer_env(DRILLCOSIM_PYTHON=sys.executable)
    env.pop("LD_PRELOAD", None)
    for name, (inp, value, out) in {"StrainController": ("strain1_C", 1e-6, "actuator1_force_C"),
                                    "DrillstringPlant": ("actuator1_force_C", 1e3, "hook_load")
                                    }.items():
        vr = {v.name: v.valueReference
              for v in read_model_description(str(sanitized[name])).modelVariables}
        d = c_host.unzip(sanitized[name], tmp_path / name)
        proc = c_host.run_host(host, d, name, 0.004, 1e-3, [f"r:{vr[inp]}={value!r}"],
                               [vr[out]], env, tmp_path)
        assert_clean(proc, f"the C host with {name}")
        rows = c_host.rows(proc.stdout)
        assert "used" in proc.stderr and len(rows) == 5 and rows[-1][1] != 0.0, proc.stdout


FREED_HANDLES = """
import ctypes, json, sys
from ctypes import byref, c_char_p, c_double, c_int, c_void_p
lib = ctypes.CDLL(sys.argv[1])
LOG = ctypes.CFUNCTYPE(None, c_void_p, c_char_p, c_int, c_char_p, c_char_p)
log = LOG(lambda *args: None)
class Callbacks(ctypes.Structure):
    _fields_ = [("logger", LOG), ("alloc", c_void_p), ("free", c_void_p), ("step", c_void_p),
                ("env", c_void_p)]
callbacks = Callbacks(log)
lib.fmi2Instantiate.restype = c_void_p
lib.fmi2SetupExperiment.argtypes = [c_void_p, c_int, c_double, c_double, c_int, c_double]
lib.fmi2DoStep.argtypes = [c_void_p, c_double, c_double, c_int]
for name in ("fmi2EnterInitializationMode", "fmi2ExitInitializationMode", "fmi2FreeInstance"):
    getattr(lib, name).argtypes = [c_void_p]
lib.fmi2GetFMUstate.argtypes = lib.fmi2FreeFMUstate.argtypes = [c_void_p, c_void_p]
lib.fmi2SetFMUstate.argtypes = [c_void_p, c_void_p]
c = lib.fmi2Instantiate(b"freed", 1, b"", sys.argv[2].encode(), byref(callbacks), 0, 0)
assert c is not None
out = {"setup": lib.fmi2SetupExperiment(c, 0, 0.0, 0.0, 0, 0.0),
       "enter": lib.fmi2EnterInitializationMode(c), "exit": lib.fmi2ExitInitializationMode(c)}
state = c_void_p()
out["get_state"] = lib.fmi2GetFMUstate(c, byref(state))
freed = state.value
out["free_state"] = lib.fmi2FreeFMUstate(c, byref(state))
out["set_freed_state"] = lib.fmi2SetFMUstate(c, freed)
again = c_void_p(freed)
out["free_freed_state"] = lib.fmi2FreeFMUstate(c, byref(again))
lib.fmi2FreeInstance(c)
out["step_freed_instance"] = lib.fmi2DoStep(c, 0.0, 1e-3, 1)
lib.fmi2FreeInstance(c)  # a second free: ignored
print(json.dumps(out))
"""


def test_freed_handles_are_refused_without_reading_them(sanitized: dict[str, Path],
                                                        asan_runtime: Path,
                                                        tmp_path: Path) -> None:
    d = c_host.unzip(sanitized["StrainController"], tmp_path / "unzip")
    proc = subprocess.run([sys.executable, "-c", FREED_HANDLES,
                           str(d / "binaries" / "linux64" / "StrainController.so"),
                           (d / "resources").as_uri()],
                          env=sanitizer_env(LD_PRELOAD=str(asan_runtime)), capture_output=True,
                          text=True, timeout=300)
    assert_clean(proc, "freed handles")
    out = json.loads(proc.stdout.strip().splitlines()[-1])
    assert out == {"setup": 0, "enter": 0, "exit": 0, "get_state": 0, "free_state": 0,
                   "set_freed_state": 3, "free_freed_state": 3, "step_freed_instance": 3}


@pytest.mark.parametrize("case", bad_handles.CASES)
def test_c_controller_bad_handles_are_refused_without_reading_them(
        case: str, sanitized: dict[str, Path], asan_runtime: Path, tmp_path: Path) -> None:
    d = c_host.unzip(sanitized[MODEL_IDENTIFIER], tmp_path / "unzip")
    guid = read_model_description(str(sanitized[MODEL_IDENTIFIER])).guid
    proc = subprocess.run([sys.executable, bad_handles.__file__,
                           str(d / "binaries" / "linux64" / f"{MODEL_IDENTIFIER}.so"), guid, case],
                          env=sanitizer_env(LD_PRELOAD=str(asan_runtime)), capture_output=True,
                          text=True, timeout=120)
    assert_clean(proc, case)
    assert json.loads(proc.stdout.strip().splitlines()[-1]) == bad_handles.EXPECTED[case]
