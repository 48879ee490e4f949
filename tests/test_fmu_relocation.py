"""The FMUs on "another machine": built by an interpreter that is gone, run by a plain C host.

An FMU must not need the building machine. Here the FMUs are built by a throw-away
venv (the building interpreter, the last discovery candidate), that venv is renamed away, and a
different venv with the packages sits elsewhere on ``PATH`` (offline: its site-packages holds a
``.pth`` line pointing at this environment's site-packages). A plain C host (no Python in its
process, no ``DRILLCOSIM_*`` variable, a ``PYTHONHOME``/``PYTHONPATH`` leaking in) runs both FMUs;
their outputs equal fmpy's (a Python host) to the last digit. With no suitable Python at all
the instantiation fails with ONE message naming each candidate and what it lacked, and the
host process survives and exits normally.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import sysconfig
import venv
from pathlib import Path

import numpy as np
import pytest
from fmpy import read_model_description, simulate_fmu

from support import c_host
from support.required import missing

pytestmark = [pytest.mark.slow, pytest.mark.needs_cc]

SITE = Path(sysconfig.get_paths()["purelib"])


def _venv(where: Path, pth_lines: list[str]) -> Path:
    """A venv of this interpreter without pip; ``pth_lines`` go into a .pth of its site."""
    venv.EnvBuilder(with_pip=False, symlinks=True).create(where)
    site = where / "lib" / f"python{sys.version_info.major}.{sys.version_info.minor}"
    site = site / "site-packages"
    if pth_lines:
        (site / "_dcs_test_env.pth").write_text("\n".join(pth_lines) + "\n")
    return where / "bin" / "python3"


def _host_env(tmp: Path, path: str, **extra: str) -> dict[str, str]:
    env = {k: v for k, v in os.environ.items()
           if not k.startswith(("PYTHON", "DRILLCOSIM", "VIRTUAL_ENV", "XDG_CONFIG"))}
    env.update(PATH=path, HOME=str(tmp / "home"), OPENBLAS_NUM_THREADS="1", **extra)
    return env


@pytest.fixture(scope="module")
def relocated(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    if shutil.which("gcc") is None:
        missing("gcc", "not on PATH")
    base = tmp_path_factory.mktemp("relocation")
    # the building interpreter: sees this environment's packages, drillcosim included (the
    # checkout's editable finder is the one .pth import line that must run there)
    editable = [line for p in SITE.glob("__editable__*drillcosim*.pth")
                for line in p.read_text().splitlines() if line.strip()]
    build_python = _venv(base / "build-venv", [str(SITE), *editable])
    fmus = base / "fmus"
    proc = subprocess.run([str(build_python), "-m", "drillcosim.fmu_src.build", "--out",
                           str(fmus)], cwd=base, capture_output=True, text=True, timeout=600,
                          env=_host_env(base, os.environ["PATH"]))
    assert proc.returncode == 0, proc.stderr[-3000:]
    for name in ("DrillstringPlant", "StrainController"):  # it recorded the building venv
        lib = (c_host.unzip(fmus / f"{name}.fmu", base / "peek" / name)
               / "binaries" / "linux64" / f"{name}.so").read_bytes()
        assert str(build_python).encode() in lib
    (base / "build-venv").rename(base / "build-venv.hidden")  # gone from where it was
    user_python = _venv(base / "elsewhere" / "user-venv", [str(SITE)])  # no drillcosim
    bare_python = _venv(base / "bare-venv", [])  # no packages at all
    return {"base": base, "fmus": fmus, "user_bin": user_python.parent,
            "bare_bin": bare_python.parent, "build_python": build_python,
            "host": c_host.compile_host(base)}


CASES = {
    "DrillstringPlant": ({"actuator1_force_C": 300.0, "actuator2_force_E": -150.0}, 0.2),
    "StrainController": ({"strain1_C": 1e-6, "strain2_E": -2e-6, "lag_time_constant": 2e-3},
                         0.02),
}


@pytest.mark.parametrize("name", list(CASES))
def test_relocated_fmus_run_in_a_c_host_like_in_fmpy(relocated: dict[str, Path],
                                                     name: str) -> None:
    start, stop = CASES[name]
    fmu = relocated["fmus"] / f"{name}.fmu"
    md = read_model_description(str(fmu))
    vr = {v.name: v.valueReference for v in md.modelVariables}
    outputs = [v.name for v in md.modelVariables if v.causality == "output"]
    base = relocated["base"]
    d = c_host.unzip(fmu, base / f"run-{name}")
    env = _host_env(base, f"{relocated['user_bin']}:/usr/bin:/bin",
                    PYTHONHOME="/nonexistent/leaked", PYTHONPATH="/nonexistent/leaked")
    proc = c_host.run_host(relocated["host"], d, name, stop, 1e-3,
                           [f"r:{vr[k]}={v!r}" for k, v in start.items()],
                           [vr[o] for o in outputs], env, base)
    assert proc.returncode == 0, proc.stderr[-4000:]
    assert f"{relocated['user_bin']}/python3: Python 3." in proc.stderr  # found on PATH
    assert "used" in proc.stderr
    assert f"the building interpreter {relocated['build_python']}" not in proc.stderr  # not needed
    got = np.array(c_host.rows(proc.stdout))
    ref = simulate_fmu(str(fmu), stop_time=stop, step_size=1e-3, output_interval=1e-3,
                       start_values=start, output=outputs)
    assert got.shape == (len(ref), len(outputs) + 1)
    np.testing.assert_array_equal(got[:, 0], ref["time"])
    for j, out in enumerate(outputs):  # "%.17g" round-trips: equal to the last bit
        np.testing.assert_array_equal(got[:, j + 1], ref[out], err_msg=out)
    assert np.ptp(got[:, 1:], axis=0).max() > 0


@pytest.mark.parametrize("name", list(CASES))
def test_no_suitable_python_is_one_message_and_the_host_survives(
        relocated: dict[str, Path], name: str) -> None:
    fmu = relocated["fmus"] / f"{name}.fmu"
    base = relocated["base"]
    d = c_host.unzip(fmu, base / f"fail-{name}")
    env = _host_env(base, str(relocated["bare_bin"]))
    proc = c_host.run_host(relocated["host"], d, name, 0.01, 1e-3, [], [], env, base)
    assert proc.returncode == 3, (proc.returncode, proc.stderr)  # NULL, then a normal exit
    assert c_host.log_lines(proc.stderr) == c_host.log_lines(proc.stderr, c_host.ERROR)
    assert len(c_host.log_lines(proc.stderr)) == 1, proc.stderr  # ONE message
    text = proc.stderr
    needs = "numpy scipy numba" if name == "DrillstringPlant" else "numpy"
    assert f"runs its model in CPython 3.10 to 3.13 with {needs}" in text
    assert "1. $DRILLCOSIM_PYTHON: not set" in text
    assert "2. config file: none of" in text
    assert f"3. on PATH: {relocated['bare_bin']}/python3: Python 3." in text
    for module in needs.split():
        assert f"{module} (ModuleNotFoundError: No module named '{module}')" in text
    assert f"4. the building interpreter {relocated['build_python']}: not found" in text
    assert "How to fix:" in text
