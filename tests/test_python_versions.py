"""One FMU binary for CPython 3.10-3.13: the FMUs built by this interpreter run in Python hosts
and in a C host with a Python of every other supported version on this machine.

For each version 3.10 to 3.13 other than this interpreter's (found as ``~/.pyenv/versions/3.X.*``
or ``python3.X`` on PATH; each is a row of ``.ci/required-tools``: absent, a failure under CI,
else a skip naming it):

* a fresh venv with only fmpy, numpy, scipy and numba (cached under the user cache, keyed by the
  interpreter, its version and the requirements: a second run reuses it; ``pip --no-compile``
  from the configured indexes keeps a fresh one at ~15 s) runs ``support/version_run.py``: the
  plant FMU, the strain controller FMU and a closed loop of both through fmpy. Every signal
  equals the run of this interpreter (the one that built the FMUs) to 1e-12 of its peak;
* the numba cache of the plant's kernels is kept per Python version beside the one of this
  interpreter (numba names its index files ``*.py3X.nbi``), in the same stable folder;
* the plain C host (``support/fmi2_host.c``, no Python in the process) runs both FMUs with that
  venv's Python named by ``$DRILLCOSIM_PYTHON`` (the documented search order's first
  candidate), equal to the C host with this interpreter to 1e-12 of each signal's peak.

And for every supported version's headers present: the wrapper compiles against them (limited
API 3.10, warnings are errors) and its hand-declared ``DcsBuffer`` has ``Py_buffer``'s layout.
"""

from __future__ import annotations

import glob
import hashlib
import json
import os
import shutil
import subprocess
import sys
import textwrap
from concurrent.futures import Future, ThreadPoolExecutor
from pathlib import Path

import numpy as np
import pytest

from drillcosim.fmu_src.build import REGISTRY, shipped_modules, user_cache
from drillcosim.fmu_src.wrapper import HERE as WRAPPER_DIR
from drillcosim.fmu_src.wrapper import compile_shared, compile_wrapper, python_range
from support import c_host
from support.required import missing

HERE = Path(__file__).resolve().parent
RUN = HERE / "support" / "version_run.py"
REQUIREMENTS = ("fmpy", "numpy", "scipy", "numba")
LOW, HIGH = python_range()
MINORS = tuple(range(LOW, HIGH + 1))
#: the supported versions other than this interpreter's (which made the reference run)
OTHERS = tuple(m for m in MINORS if m != sys.version_info.minor)
CANONICAL_PLANT = dict(next(r for r in REGISTRY if r.name == "DrillstringPlant").vendored)["plant"]
RTOL = 1e-12  #: of each signal's peak


def find_python(minor: int) -> str | None:
    """``sys.executable`` of a CPython 3.<minor> on this machine (pyenv's, else on PATH)."""
    found = sorted(glob.glob(os.path.expanduser(f"~/.pyenv/versions/3.{minor}.*/bin/python3.{minor}")))
    found = [*reversed(found), shutil.which(f"python3.{minor}")]
    for exe in filter(None, found):
        proc = subprocess.run([exe, "-c", "import sys; print(sys.version_info[1], sys.executable)"],
                              capture_output=True, text=True, timeout=60)
        words = proc.stdout.split(maxsplit=1)
        if proc.returncode == 0 and len(words) == 2 and words[0] == str(minor):
            return words[1].strip()
    return None


def python_or_missing(minor: int) -> str:
    """CPython 3.<minor>: a required tool (a failure under CI when absent, else a skip)."""
    exe = find_python(minor)
    if exe is None:
        missing(f"python3.{minor}", f"looked for ~/.pyenv/versions/3.{minor}.* and python3.{minor} on PATH")
    return exe


def clean_env(**extra: str) -> dict[str, str]:
    """This environment without PYTHON*/VIRTUAL_ENV/DRILLCOSIM_PYTHON (caches kept)."""
    env = {k: v for k, v in os.environ.items()
           if not k.startswith(("PYTHON", "VIRTUAL_ENV")) and k != "DRILLCOSIM_PYTHON"}
    env.update(OPENBLAS_NUM_THREADS="1", **extra)
    return env


def venv_for(exe: str) -> Path:
    """A venv of ``exe`` with :data:`REQUIREMENTS` only, made once per interpreter, version and
    requirements (``<user cache>/test_venvs/``); a half-made one is made anew."""
    version = subprocess.run([exe, "-c", "import sys; print(sys.version)"], capture_output=True,
                             text=True, check=True).stdout.strip()
    key = hashlib.sha256(f"{os.path.realpath(exe)}\0{version}\0{' '.join(REQUIREMENTS)}"
                         .encode()).hexdigest()[:16]
    root = user_cache() / "test_venvs" / f"py{version.split()[0]}-{key}"
    done = root / "COMPLETE"
    if not done.is_file():
        shutil.rmtree(root, ignore_errors=True)
        root.parent.mkdir(parents=True, exist_ok=True)
        subprocess.run([exe, "-m", "venv", str(root)], check=True, capture_output=True,
                       env=clean_env(), timeout=300)
        pip = subprocess.run([str(root / "bin" / "python"), "-m", "pip", "install", "-q",
                              "--no-compile", "--disable-pip-version-check", *REQUIREMENTS],
                             capture_output=True, text=True, env=clean_env(), timeout=900)
        assert pip.returncode == 0, f"pip install into a {version} venv failed:\n{pip.stderr}"
        done.write_text(version + "\n")
    return root / "bin" / "python"


def run_fmus(python: str | Path, fmus: dict[str, Path], cwd: Path) -> dict:
    proc = subprocess.run([str(python), str(RUN), str(fmus["DrillstringPlant"]),
                           str(fmus["StrainController"])], cwd=cwd, env=clean_env(),
                          capture_output=True, text=True, timeout=900)
    assert proc.returncode == 0, proc.stderr[-4000:]
    return json.loads(proc.stdout.strip().splitlines()[-1])


def assert_close(got: np.ndarray, ref: np.ndarray, what: str) -> None:
    """Every column equal to ``ref``'s to RTOL of its peak (exactly if it is all zeros)."""
    assert got.shape == ref.shape, what
    peak = np.max(np.abs(ref), axis=0)
    err = np.max(np.abs(got - ref), axis=0)
    bad = np.flatnonzero(err > RTOL * peak)
    assert bad.size == 0, f"{what}: columns {bad.tolist()} differ by {err[bad]} (peaks {peak[bad]})"


@pytest.fixture(scope="module")
def reference(project_fmus: dict[str, Path], tmp_path_factory: pytest.TempPathFactory) -> dict:
    """The run of this interpreter (the one that built the FMUs)."""
    return run_fmus(sys.executable, project_fmus, tmp_path_factory.mktemp("reference"))


#: (FMU, stop [s], step [s], settings in initialization mode, outputs) of the C host runs.
def c_host_cases(fmus: dict[str, Path]) -> dict[str, tuple]:
    from fmpy import read_model_description

    cases = {}
    for name, stop, step, sets in (
            ("StrainController", 0.02, 1e-3, {"strain1_C": 1e-6, "strain2_E": -2e-6,
                                              "lag_time_constant": 0.005}),
            ("DrillstringPlant", 0.01, 2.5e-4, {"max_internal_step": 2.5e-4,
                                               "actuator1_force_C": 1e3})):
        md = read_model_description(str(fmus[name]))
        vr = {v.name: v.valueReference for v in md.modelVariables}
        outs = [v.valueReference for v in md.modelVariables if v.causality == "output"]
        cases[name] = (fmus[name], stop, step, [f"r:{vr[k]}={v!r}" for k, v in sets.items()],
                       outs)
    return cases


def run_c_host(host: Path, python: str | Path, case: tuple, where: Path) -> tuple[np.ndarray, str]:
    fmu, stop, step, sets, outs = case
    d = c_host.unzip(fmu, where / "unzip")
    home = where / "home"
    home.mkdir(exist_ok=True)
    env = {k: v for k, v in clean_env().items() if not k.startswith("XDG_CONFIG")}
    env.update(PATH="/usr/bin:/bin", HOME=str(home), DRILLCOSIM_PYTHON=str(python))
    proc = c_host.run_host(host, d, fmu.stem, stop, step, sets, outs, env, where)
    assert proc.returncode == 0, proc.stderr[-4000:]
    return np.array(c_host.rows(proc.stdout)), proc.stderr


@pytest.fixture(scope="module")
def c_reference(host: Path, project_fmus: dict[str, Path],
                tmp_path_factory: pytest.TempPathFactory) -> dict[str, np.ndarray]:
    return {name: run_c_host(host, sys.executable, case, tmp_path_factory.mktemp(name))[0]
            for name, case in c_host_cases(project_fmus).items()}


def numba_index_files(shipped_plant: str) -> list[Path]:
    """numba's index files of the plant's kernels (under the stable copy, or NUMBA_CACHE_DIR)."""
    roots = [user_cache()]
    if os.environ.get("DRILLCOSIM_CACHE"):
        roots.append(Path(os.environ["DRILLCOSIM_CACHE"]))
    if os.environ.get("NUMBA_CACHE_DIR"):
        roots.append(Path(os.environ["NUMBA_CACHE_DIR"]))
    return [p for root in roots if root.is_dir() for p in root.rglob("*.nbi")
            if shipped_plant in str(p)]


def run_version(python: Path, fmus: dict[str, Path], host: Path, where: Path) -> dict:
    """Everything one version runs: the fmpy script, then both FMUs in the C host."""
    where.mkdir(parents=True)
    out = {"fmpy": run_fmus(python, fmus, where), "c": {}}
    for name, case in c_host_cases(fmus).items():
        out["c"][name] = run_c_host(host, python, case, where / f"c_{name}")
    return out


@pytest.fixture(scope="module")
def version_runs(project_fmus: dict[str, Path], host: Path,
                 tmp_path_factory: pytest.TempPathFactory) -> dict[int, Future]:
    """Each other version's venv and runs, two versions at a time (the first use of a version
    compiles the plant's numba kernels for it: ~15 s of CPU each; a fresh venv ~10 s)."""
    where = tmp_path_factory.mktemp("versions")
    found = {m: find_python(m) for m in OTHERS}

    def work(minor: int, exe: str) -> dict:
        return run_version(venv_for(exe), project_fmus, host, where / f"3.{minor}")

    pool = ThreadPoolExecutor(max_workers=2)
    runs = {m: pool.submit(work, m, exe) for m, exe in found.items() if exe is not None}
    pool.shutdown(wait=False)
    return runs


@pytest.mark.slow
@pytest.mark.interop
@pytest.mark.needs_cc
@pytest.mark.parametrize("minor", OTHERS)
def test_the_fmus_run_in_python_and_c_hosts_of_each_version(
        minor: int, version_runs: dict[int, Future], project_fmus: dict[str, Path],
        reference: dict, c_reference: dict[str, np.ndarray]) -> None:
    exe = python_or_missing(minor)
    got = version_runs[minor].result(timeout=1800)
    python = venv_for(exe)  # made by the run: only its path here
    assert got["fmpy"]["python"].startswith(f"3.{minor}.")
    for run in ("plant", "controller", "closed_loop"):
        assert_close(np.array(got["fmpy"][run]), np.array(reference[run]), f"3.{minor} {run}")
    assert np.max(np.abs(np.array(reference["closed_loop"])[:, -4:])) > 1.0  # forces act
    # numba's cache of the plant kernels: one per Python version, side by side
    shipped = shipped_modules(project_fmus["DrillstringPlant"])[CANONICAL_PLANT]
    index = numba_index_files(shipped)
    mine = f".py3{sys.version_info.minor}.nbi"
    assert any(p.name.endswith(f".py3{minor}.nbi") for p in index), index
    assert any(p.name.endswith(mine) for p in index), index
    # the C host, this version's Python named by $DRILLCOSIM_PYTHON
    for name, (rows, log) in got["c"].items():
        assert f"1. $DRILLCOSIM_PYTHON = {python}: Python 3.{minor}." in log, log
        assert "used" in log
        assert_close(rows, c_reference[name], f"3.{minor} C host {name}")


BUFFER_CHECK = textwrap.dedent("""
    #include <Python.h>
    #include <stddef.h>
    #include "dcs_python_buffer.h"
    #define SAME(f) _Static_assert(offsetof(Py_buffer, f) == offsetof(DcsBuffer, f), #f);
    SAME(buf) SAME(obj) SAME(len) SAME(itemsize) SAME(readonly) SAME(ndim) SAME(format)
    SAME(shape) SAME(strides) SAME(suboffsets) SAME(internal)
    _Static_assert(sizeof(Py_buffer) == sizeof(DcsBuffer), "size");
    _Static_assert(PyBUF_WRITABLE == DCS_PYBUF_WRITABLE, "writable");
    _Static_assert(PyBUF_FORMAT == DCS_PYBUF_FORMAT, "format");
    _Static_assert(PyBUF_C_CONTIGUOUS == DCS_PYBUF_C_CONTIGUOUS, "c contiguous");
    int dcs_buffer_check(void) { return 0; }
""")


@pytest.mark.needs_cc
@pytest.mark.parametrize("minor", MINORS)
def test_the_wrapper_compiles_against_each_versions_headers(minor: int, tmp_path: Path) -> None:
    """Limited API 3.10 with every version's headers; the hand-declared buffer struct and flags
    (dcs_python.h) equal the full API's ``Py_buffer`` of that version."""
    exe = sys.executable if minor == sys.version_info.minor else find_python(minor)
    if exe is None:
        missing(f"python3.{minor}", f"looked for ~/.pyenv/versions/3.{minor}.* and python3.{minor} on PATH")
    include = subprocess.run([exe, "-c", "import sysconfig; print(sysconfig.get_paths()"
                              "['include'])"], capture_output=True, text=True,
                             check=True).stdout.strip()
    if not (Path(include) / "Python.h").is_file():
        missing(f"python3.{minor}", f"its headers are not in {include}")
    compile_wrapper(tmp_path / "w.so", include=include)  # warnings are errors
    header = (WRAPPER_DIR / "dcs_python.h").read_text()
    start = header.index("/* Py_buffer of the stable ABI")
    end = header.index("/* Functions of the limited API of 3.10")
    (tmp_path / "dcs_python_buffer.h").write_text(header[start:end])
    (tmp_path / "check.c").write_text(BUFFER_CHECK)
    compile_shared(f"the buffer layout check for 3.{minor}", [tmp_path / "check.c"],
                   tmp_path / "check.so", flags=(f"-I{include}", f"-I{tmp_path}"))
