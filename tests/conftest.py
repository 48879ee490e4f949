"""Shared fixtures of the test suite.

* ``project_fmus`` (session): the plant and controller FMUs, built once into a session folder
  by the project's build (each in its own subprocess) and validated; every FMU test uses them.
* ``fmus`` (session): the tiny master-test FMUs of ``tests/support/master_fmus`` (cached across
  sessions under a full key, validated before use, see :mod:`support.master_fmus.build`).
* ``c_controller_fmu`` (session): ``StrainControllerC.fmu`` (the controller in C99), built and
  validated once.
* ``closed_loop_py`` / ``closed_loop_c`` (session): the loop the third-party engines are
  compared on (:mod:`support.closed_loop`) with the Python / the C controller: its SSP file and
  our master's result.
* Two autouse guards: fmpy's logger proxy is restored after every test, and every test leaves
  ``sys.path`` and the host's module namespace as it found them (see
  :func:`_host_namespace_unchanged`).

Markers (``pytest -m "not slow"`` is the fast subset): ``slow`` (long simulations, builds,
campaigns), ``interop`` (third-party FMI engines: libcosim, Ecos, a C host), ``needs_cc`` (runs
a C compiler itself).
"""

from __future__ import annotations

import ctypes
import os
import sys
import sysconfig
from pathlib import Path

import pytest
from fmpy import platform
from fmpy.fmi1 import printLogMessage
from fmpy.fmi2 import fmi2CallbackFunctions, fmi2CallbackLoggerTYPE
from fmpy.logging import addLoggerProxy
from fmpy.validation import validate_fmu

from drillcosim.fmu_src.build import REGISTRY, build_one
from drillcosim.fmu_src.build_c import build_c_controller
from support.closed_loop import ClosedLoop, closed_loop
from support.master_fmus.build import build_all as build_test_fmus

# fmpy's native logger proxy (logging.so) keeps ONE global target for every FMU in the process:
# the last addLoggerProxy() call wins. Tests that install a recording logger re-point it at their
# own ctypes callback; once that callback is garbage-collected, the next FMU that logs jumps into
# freed memory (a segfault or heap corruption in a later, unrelated test). After every test the
# target goes back to fmpy's printing logger, through a callback kept alive for the whole session.
_DEFAULT = fmi2CallbackFunctions()
_DEFAULT.logger = fmi2CallbackLoggerTYPE(printLogMessage)
_KEEP = _DEFAULT.logger

_ENV_ROOTS = tuple(str(Path(p).resolve()) for p in {
    sysconfig.get_paths()["purelib"], sysconfig.get_paths()["platlib"],
    sysconfig.get_paths()["stdlib"], sysconfig.get_paths()["platstdlib"]})


@pytest.fixture(autouse=True)
def _restore_fmpy_logger_proxy():
    yield
    cb = fmi2CallbackFunctions()
    cb.logger = _KEEP
    addLoggerProxy(ctypes.byref(cb))


def _fmu_folder(path: str | None) -> Path | None:
    """The extracted FMU a module file lies in (a parent holding modelDescription.xml)."""
    if not path:
        return None
    for parent in Path(path).resolve().parents:
        if (parent / "modelDescription.xml").is_file():
            return parent
    return None


def foreign_modules(before: set[str]) -> list[str]:
    """Modules added since ``before`` that an FMU brought under a name that is not unique.

    An FMU loaded in this process may add modules only under ``_dcs_`` names (versioned,
    unique): a generic name (``pythonfmu``, an adapter script's name) from an FMU's unzip
    folder would shadow the host's own module of that name for the rest of the process, and
    dangle once the folder is deleted. ``pythonfmu`` itself must be the environment's.
    """
    found = []
    for name in set(sys.modules) - before:
        module = sys.modules.get(name)
        if name.split(".")[0].startswith("_dcs_"):
            continue
        if _fmu_folder(getattr(module, "__file__", None)) is not None:
            found.append(f"{name} from {module.__file__}")
    pfmu = sys.modules.get("pythonfmu")
    if pfmu is not None and not str(Path(pfmu.__file__).resolve()).startswith(_ENV_ROOTS):
        found.append(f"pythonfmu from {pfmu.__file__} (not the environment's)")
    return sorted(found)


@pytest.fixture(autouse=True)
def _host_namespace_unchanged(request):
    """sys.path exactly as before; no non-unique module name brought in by an FMU."""
    path_before = list(sys.path)
    modules_before = set(sys.modules)
    yield
    problems = []
    if sys.path != path_before:
        added = [p for p in sys.path if p not in path_before]
        removed = [p for p in path_before if p not in sys.path]
        sys.path[:] = path_before
        problems.append(f"sys.path changed (added {added}, removed {removed})")
    foreign = foreign_modules(modules_before)
    for entry in foreign:
        sys.modules.pop(entry.split(" ")[0], None)
    if foreign:
        problems.append(f"modules from an FMU under non-unique names: {foreign}")
    if problems:
        pytest.fail(f"{request.node.nodeid} left the host process changed: "
                    f"{'; '.join(problems)}", pytrace=False)


def _validated(path: Path) -> Path:
    ident = path.stem
    import zipfile

    with zipfile.ZipFile(path) as zf:
        if f"binaries/{platform}/{ident}.so" not in zf.namelist():
            raise RuntimeError(f"{path}: no binaries/{platform}/{ident}.so")
    problems = validate_fmu(str(path))
    if problems:
        raise RuntimeError(f"{path}: fmpy validation: {problems}")
    return path


@pytest.fixture(scope="session")
def project_fmus(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """``{name: path}`` of the plant and controller FMUs, built once per session, validated."""
    out = tmp_path_factory.mktemp("project_fmus")
    return {spec.name: _validated(build_one(spec, out)) for spec in REGISTRY}


@pytest.fixture(scope="session")
def fmus() -> dict[str, Path]:
    """``{script name: path}`` of the tiny master-test FMUs (validated)."""
    return build_test_fmus()


@pytest.fixture(scope="session")
def host(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The plain C FMI host of the tests (``support/fmi2_host.c``), compiled once."""
    import shutil

    from support import c_host
    from support.required import missing

    if shutil.which("gcc") is None:
        missing("gcc", "not on PATH")
    return c_host.compile_host(tmp_path_factory.mktemp("c_host"))


@pytest.fixture(scope="session")
def bare_python(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A Python 3 of this version without numpy (a venv of this interpreter, no packages)."""
    import venv

    where = tmp_path_factory.mktemp("bare") / "venv"
    venv.EnvBuilder(with_pip=False, symlinks=True).create(where)
    return where / "bin" / "python3"


@pytest.fixture(scope="session")
def c_controller_fmu(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """``StrainControllerC.fmu`` (the C99 controller), built once per session, validated."""
    return _validated(build_c_controller(tmp_path_factory.mktemp("c_controller")))


@pytest.fixture(scope="session")
def closed_loop_py(project_fmus, tmp_path_factory: pytest.TempPathFactory) -> ClosedLoop:
    """The engine-comparison loop with the Python controller FMU (SSP + our master's result)."""
    return closed_loop(project_fmus["DrillstringPlant"], project_fmus["StrainController"],
                       tmp_path_factory.mktemp("closed_loop_py"))


@pytest.fixture(scope="session")
def closed_loop_c(project_fmus, c_controller_fmu, tmp_path_factory) -> ClosedLoop:
    """The engine-comparison loop with the C controller FMU (SSP + our master's result)."""
    return closed_loop(project_fmus["DrillstringPlant"], c_controller_fmu,
                       tmp_path_factory.mktemp("closed_loop_c"), name="closed_loop_c")


@pytest.fixture(scope="session")
def windows_caches(tmp_path_factory: pytest.TempPathFactory) -> dict[str, str]:
    """The caches of every Windows process of this test run (numba's, the stable package copies
    and their native images), as environment variables: empty at the start of a run, shared by
    the wine tests of all pytest-xdist workers (one folder beside the workers' own), so the
    plant's kernels are compiled under wine once per run, not once per test file."""
    from support.windows_bench import windows_path

    base = tmp_path_factory.getbasetemp()
    if os.environ.get("PYTEST_XDIST_WORKER"):
        base = base.parent  # the run's folder, above popen-gw0, popen-gw1, ...
    folder = base / "windows_caches"
    folder.mkdir(exist_ok=True)
    return {"DRILLCOSIM_CACHE": windows_path(folder / "drillcosim"),
            "NUMBA_CACHE_DIR": windows_path(folder / "numba"), "OPENBLAS_NUM_THREADS": "1"}
