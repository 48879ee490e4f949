"""Self-contained FMUs (``drillcosim build --standalone``): their own Python, no Python needed.

* In a plain C host (``support/fmi2_cosim_host.c``) in an environment with no Python (PATH an
  empty folder; no PYTHONHOME, PYTHONPATH, LD_LIBRARY_PATH), the standalone plant + controller
  closed loop equals, bit for bit, the same host running the regular FMUs on this machine's
  Python; and that host (Jacobi, zero-order hold) equals our master to 1e-9 of each signal's
  peak, as Ecos and libcosim do. That the runtime started at all means the wrapper's SHA-256
  (C, ``dcs_sha256.c``) agreed with Python's hashlib on every one of its files.
* Bad runtimes: a file missing, a file damaged (same size), the MANIFEST damaged, and a second
  self-contained FMU whose runtime differs from the one running: each ONE message with
  fmi2Error and a NULL from fmi2Instantiate (exit 3 of the host), never a crash or a hang.
* In a Python host the FMU runs in the host's interpreter (its own runtime is not loaded: one
  process runs one Python), equal to the regular FMU.
* ``drillcosim doctor`` says it is self-contained and that its own runtime would be used.
"""

from __future__ import annotations

import json
import subprocess
import sys
import zipfile
from pathlib import Path

import numpy as np
import pytest

from drillcosim.fmu_src.standalone.manifest import MANIFEST, read_manifest, write_manifest
from support import c_host, cosim_host
from support.closed_loop import closed_loop
from support.engines import compare
from support.standalone import bare_env, linked_copy, standalone_copy

pytestmark = [pytest.mark.needs_cc, pytest.mark.interop, pytest.mark.slow]

STOP = 0.05  #: [s] of the closed loop (500 steps of 0.1 ms)
RUNTIME = Path("resources/dcs_runtime/linux64")


@pytest.fixture(scope="session")
def standalone(project_fmus, tmp_path_factory) -> dict[str, Path]:
    """The self-contained plant and controller, and both kinds unzipped once."""
    root = tmp_path_factory.mktemp("standalone")
    out = {}
    for name in ("DrillstringPlant", "StrainController"):
        fmu = standalone_copy(project_fmus[name])
        out[name] = fmu
        out[f"{name}/sa"] = c_host.unzip(fmu, root / f"{name}-sa")
        out[f"{name}/regular"] = c_host.unzip(project_fmus[name], root / f"{name}-regular")
    return out


@pytest.fixture(scope="session")
def cosim(tmp_path_factory) -> Path:
    return cosim_host.compile_host(tmp_path_factory.mktemp("cosim_host"))


@pytest.fixture(scope="session")
def short_loop(project_fmus, tmp_path_factory):
    return closed_loop(project_fmus["DrillstringPlant"], project_fmus["StrainController"],
                       tmp_path_factory.mktemp("short_loop"), stop=STOP)


def run_pair(cosim: Path, loop, plant: Path, controller: Path, env: dict[str, str],
             where: Path) -> subprocess.CompletedProcess:
    spec = cosim_host.write_spec(loop, {"plant": str(plant), "controller": str(controller)},
                                 where / f"{plant.name}-{controller.name}.spec")
    return cosim_host.run([str(cosim), str(spec)], env, where)


def errors(stderr: str) -> list[str]:
    return [ln for ln in stderr.splitlines() if ln.startswith("[") and " 3 " in ln[:60]]


def test_the_standalone_pair_runs_with_no_python_anywhere_equal_to_the_regular_one(
        cosim, short_loop, standalone, tmp_path) -> None:
    env_sa = bare_env(tmp_path / "home")
    sa = run_pair(cosim, short_loop, standalone["DrillstringPlant/sa"],
                  standalone["StrainController/sa"], env_sa, tmp_path)
    assert sa.returncode == 0, sa.stderr[-3000:]
    assert "the FMU's own Python runtime (Python " in sa.stderr and "started" in sa.stderr
    assert "joins the one running" in sa.stderr  # the controller's runtime joined the plant's
    env_regular = bare_env(tmp_path / "home", DRILLCOSIM_PYTHON=sys.executable)
    regular = run_pair(cosim, short_loop, standalone["DrillstringPlant/regular"],
                       standalone["StrainController/regular"], env_regular, tmp_path)
    assert regular.returncode == 0, regular.stderr[-3000:]
    assert "$DRILLCOSIM_PYTHON" in regular.stderr and "own Python runtime" not in regular.stderr
    rows_sa, rows_regular = cosim_host.rows(sa.stdout), cosim_host.rows(regular.stdout)
    assert rows_sa.shape == (short_loop.n_steps + 1, len(short_loop.outputs) + 1)
    np.testing.assert_array_equal(rows_sa, rows_regular)
    # the host itself: Jacobi with a hold, as our master (and libcosim, Ecos) step
    result = compare(short_loop.data, {o: rows_regular[:, j + 1]
                                       for j, o in enumerate(short_loop.outputs)}, rtol=1e-9)
    assert result.n_moving() >= 20


def _single(host: Path, unzipped: Path, tmp_path: Path) -> subprocess.CompletedProcess:
    return c_host.run_host(host, unzipped, "StrainController", 0.002, 1e-3, [], [4],
                           bare_env(tmp_path / "home"), tmp_path, timeout=300)


def _replace(path: Path, data: bytes) -> None:
    """Write data to path as a new file (path may be a hard link to the cached original)."""
    path.unlink()
    path.write_bytes(data)


@pytest.mark.parametrize("damage", ["missing", "damaged", "manifest"])
def test_a_bad_runtime_file_is_one_message_and_no_instance(damage, host, standalone,
                                                           tmp_path) -> None:
    unzipped = linked_copy(standalone["StrainController/sa"], tmp_path / "fmu")
    runtime = unzipped / RUNTIME
    _items, files = read_manifest(runtime / MANIFEST)
    victim = runtime / next(f for f in files if f.endswith(".so") and "numpy/_core" in f)
    if damage == "missing":
        victim.unlink()
        expected = f"{victim} is missing"
    elif damage == "damaged":
        data = bytearray(victim.read_bytes())
        data[len(data) // 2] ^= 0x40  # one bit, same size
        _replace(victim, bytes(data))
        expected = f"{victim} differs from the file it was built with (another SHA-256"
    else:
        text = (runtime / MANIFEST).read_bytes()
        _replace(runtime / MANIFEST, text.replace(b"platform linux64", b"platform linux65"))
        expected = "is damaged (its end line does not match its content)"
    run = _single(host, unzipped, tmp_path)
    assert run.returncode == 3, (run.returncode, run.stderr[-2000:])  # NULL, no crash
    lines = errors(run.stderr)
    assert len(lines) == 1 and expected in lines[0], run.stderr[-2000:]
    assert "\n" not in lines[0]


def test_a_second_standalone_fmu_with_another_runtime_is_refused_in_one_line(
        cosim, short_loop, standalone, tmp_path) -> None:
    """Plant first (its runtime starts), then a controller whose runtime carries another
    numpy (one source file changed, its MANIFEST rewritten: a valid, different runtime)."""
    controller = linked_copy(standalone["StrainController/sa"], tmp_path / "controller")
    runtime = controller / RUNTIME
    items, files = read_manifest(runtime / MANIFEST)
    version = next(f for f in files if f.endswith("numpy/version.py"))
    _replace(runtime / version, (runtime / version).read_bytes() + b"\n# another build\n")
    write_manifest(runtime, items)
    run = run_pair(cosim, short_loop, standalone["DrillstringPlant/sa"], controller,
                   bare_env(tmp_path / "home"), tmp_path)
    assert run.returncode == 3, run.stderr[-2000:]
    lines = errors(run.stderr)
    assert len(lines) == 1, run.stderr[-2000:]
    assert "cannot join it: its packages numpy differ from those running" in lines[0]
    assert "controller: fmi2Instantiate:" in lines[0]


PYTHON_HOST = """
import json, sys
from pathlib import Path
from fmpy import simulate_fmu
runs = {}
for kind, fmu in (("regular", sys.argv[1]), ("standalone", sys.argv[2])):
    runs[kind] = simulate_fmu(fmu, stop_time=0.01, step_size=1e-3, output=["strain1_C",
                              "bit_rotary_speed"], fmi_call_logger=None)
maps = Path("/proc/self/maps").read_text()
import numpy
print(json.dumps({"equal": bool((runs["regular"] == runs["standalone"]).all()),
                  "runtime_mapped": "dcs_runtime" in maps, "numpy": numpy.__file__,
                  "n": len(runs["standalone"])}))
"""


def test_in_a_python_host_the_standalone_fmu_runs_in_the_hosts_interpreter(
        project_fmus, standalone, tmp_path) -> None:
    run = subprocess.run([sys.executable, "-c", PYTHON_HOST,
                          str(project_fmus["DrillstringPlant"]),
                          str(standalone["DrillstringPlant"])],
                         capture_output=True, text=True, timeout=600, cwd=tmp_path)
    assert run.returncode == 0, run.stderr[-3000:]
    found = json.loads(run.stdout.strip().splitlines()[-1])
    assert found["n"] == 11 and found["equal"]
    assert not found["runtime_mapped"]  # no file of its runtime was loaded
    assert "dcs_runtime" not in found["numpy"]


def test_the_doctor_says_self_contained_and_that_its_own_runtime_is_used(standalone,
                                                                          tmp_path) -> None:
    env = bare_env(tmp_path / "home")
    env["PATH"] = str(Path(sys.executable).parent)  # the doctor itself runs in Python
    run = subprocess.run([sys.executable, "-m", "drillcosim.cosim.cli", "doctor",
                          str(standalone["StrainController"])], capture_output=True, text=True,
                         env=env, timeout=600, cwd=tmp_path)
    assert run.returncode == 0, run.stdout + run.stderr
    assert "Self-contained: yes" in run.stdout
    assert "  linux64: CPython 3." in run.stdout
    assert "0. its own runtime" in run.stdout and "would be used" in run.stdout
    with zipfile.ZipFile(standalone["StrainController"]) as zf:
        assert f"{RUNTIME.as_posix()}/{MANIFEST}" in zf.namelist()
