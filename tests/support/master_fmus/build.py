"""The tiny master-test FMUs: built in a subprocess, cached under a full key, validated on use.

Each script ``tests/support/master_fmus/<name>.py`` is built by the project's own build
(:func:`drillcosim.fmu_src.build.build_one`: a fresh Python subprocess, our C wrapper,
pythonfmu vendored under a unique name), never inside the calling (test) process, whose
``sys.modules`` may hold anything. The cache file name carries a hash of everything that makes
the FMU: the pythonfmu version and every file of its recipe (script, wrapper sources, build).
A cached FMU is validated before it is handed out (:func:`problems`: the binary of this
platform, the slave module and the vendored pythonfmu are present; fmpy's validation is clean)
and rebuilt when it is not; an FMU that is still broken after a rebuild raises.
"""

from __future__ import annotations

import hashlib
import os
import shutil
import tempfile
import zipfile
from pathlib import Path

import pythonfmu
from fmpy import platform, read_model_description
from fmpy.validation import validate_fmu

from drillcosim.fmu_src import build as project_build

HERE = Path(__file__).resolve().parent
SCRIPTS = {"mt_integrator": "MtIntegrator", "mt_gain": "MtGain", "mt_source": "MtSource",
           "mt_mass": "MtMass", "mt_compiled": "MtCompiled"}


def cache_dir() -> Path:
    """Folder of the built test FMUs: ``$DRILLCOSIM_TEST_FMU_DIR`` or ``<user cache>/test_fmus``."""
    root = os.environ.get("DRILLCOSIM_TEST_FMU_DIR")
    path = Path(root) if root else project_build.user_cache() / "test_fmus"
    path.mkdir(parents=True, exist_ok=True)
    return path


def cache_key(script: Path) -> str:
    """Hash of what makes the FMU: the pythonfmu version and every file of its recipe."""
    digest = hashlib.sha256()
    digest.update(f"pythonfmu {pythonfmu.__version__}\0".encode())
    for src in _recipe(script).sources():
        digest.update(src.name.encode() + b"\0" + src.read_bytes())
    return digest.hexdigest()[:16]


def _recipe(script: Path) -> project_build.FmuRecipe:
    return project_build.FmuRecipe(name=SCRIPTS[script.stem], script=str(script))


def problems(fmu: Path) -> list[str]:
    """Why ``fmu`` cannot be used here (empty if it can)."""
    try:
        with zipfile.ZipFile(fmu) as zf:
            names = set(zf.namelist())
        md = read_model_description(str(fmu))
    except Exception as exc:  # noqa: BLE001 - any unreadable file is a problem
        return [f"unreadable: {exc!r}"]
    ident = md.coSimulation.modelIdentifier
    found = []
    members = [f"binaries/{platform}/{ident}.so", "resources/slavemodule.txt"]
    try:  # the vendored pythonfmu, under the name of this build
        pfmu = project_build.shipped_modules(fmu)[project_build.PYTHONFMU_VENDORED]
        members.append(f"resources/{pfmu}/fmi2slave.py")
    except (KeyError, ValueError):
        found.append(f"{project_build.BUILD_INFO} missing or unreadable")
    for member in members:
        if member not in names:
            found.append(f"{member} missing")
    found += [f"fmpy validation: {p}" for p in validate_fmu(str(fmu))]
    return found


def build_fmu(name: str, dest: Path | None = None) -> Path:
    """Path of a valid FMU of ``<name>.py``, built (in a subprocess) unless cached and valid."""
    script = HERE / f"{name}.py"
    dest = dest or cache_dir()
    dest.mkdir(parents=True, exist_ok=True)
    target = dest / f"{name}-{cache_key(script)}.fmu"
    if target.exists() and not problems(target):
        return target
    tmp = Path(tempfile.mkdtemp(dir=dest, prefix=f".{name}-"))
    try:
        built = project_build.build_one(_recipe(script), tmp)
        found = problems(built)
        if found:
            raise RuntimeError(f"test FMU {name} is broken right after its build: "
                               f"{'; '.join(found)}")
        os.replace(built, target)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return target


def build_all(dest: Path | None = None) -> dict[str, Path]:
    """Build (or reuse) every test FMU; return ``{script name: fmu path}``."""
    return {name: build_fmu(name, dest) for name in SCRIPTS}
