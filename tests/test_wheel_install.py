"""The installed package is self-sufficient: a wheel in a fresh venv, used from an empty folder.

The wheel is built from this checkout (offline, ``--no-build-isolation``) and installed with
``--no-deps`` into a new venv outside the checkout; the venv reaches the dependencies of the
current environment through a path entry (not its ``.pth`` files, so the checkout's editable
finder is not loaded). Everything then runs in an empty folder: ``drillcosim scenes``,
``drillcosim build`` and ``drillcosim run paper_open_loop --stop-time 0.5``.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import sysconfig
import zipfile
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
pytestmark = [pytest.mark.slow, pytest.mark.needs_cc]


@pytest.fixture(scope="module")
def installed(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    base = tmp_path_factory.mktemp("wheel")
    dist = base / "dist"
    # a copy of the sources without build products: setuptools reuses an in-tree build/ folder,
    # which a checkout that ran `make` has (stale files would land in the wheel)
    src = base / "src"
    shutil.copytree(ROOT, src, ignore=shutil.ignore_patterns(
        ".git", ".venv", "build", "out", "*.egg-info", "__pycache__", ".pytest_cache"))
    proc = subprocess.run([sys.executable, "-m", "pip", "wheel", "--no-deps",
                           "--no-build-isolation", "-w", str(dist), str(src)],
                          capture_output=True, text=True, cwd=base)
    assert proc.returncode == 0, proc.stderr[-3000:]
    # pyproject is clean: setuptools warns of nothing (a license table, data folders that are
    # no declared package: ~220 lines of `pip install` before)
    assert "Warning" not in proc.stdout + proc.stderr, (proc.stdout + proc.stderr)[-3000:]
    wheel = next(dist.glob("drillcosim-*.whl"))
    venv = base / "venv"
    subprocess.run([sys.executable, "-m", "venv", "--without-pip", str(venv)], check=True)
    py = venv / "bin" / "python"
    site = Path(subprocess.run([str(py), "-c", "import sysconfig; print(sysconfig.get_paths()"
                                "['purelib'])"], capture_output=True, text=True,
                               check=True).stdout.strip())
    # the current environment's packages, as a plain path entry after the venv's own
    (site / "zz_host_env.pth").write_text(sysconfig.get_paths()["purelib"] + "\n")
    proc = subprocess.run([sys.executable, "-m", "pip", "install", "--no-deps", "--no-index",
                           "--target", str(site), str(wheel)], capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr[-3000:]
    # pip --target does not write console scripts: the entry point is called as pip would
    drillcosim = venv / "bin" / "drillcosim"
    drillcosim.write_text(f"#!{py}\nimport sys\nfrom drillcosim.cosim.cli import main\n"
                          f"sys.exit(main())\n")
    drillcosim.chmod(0o755)
    work = base / "empty"
    work.mkdir()
    return {"wheel": wheel, "py": py, "site": site, "cli": drillcosim, "work": work,
            "cache": base / "cache"}


def _run(inst: dict[str, Path], *args: str, timeout: float = 600) -> subprocess.CompletedProcess:
    env = {k: v for k, v in os.environ.items() if not k.startswith(("PYTHON", "DRILLCOSIM"))}
    env["XDG_CACHE_HOME"] = str(inst["cache"])
    return subprocess.run([str(inst["cli"]), *args], cwd=inst["work"], env=env,
                          capture_output=True, text=True, timeout=timeout)


def test_wheel_has_one_import_namespace_and_the_package_data(installed) -> None:
    with zipfile.ZipFile(installed["wheel"]) as zf:
        names = zf.namelist()
    tops = {n.split("/")[0] for n in names if not n.split("/")[0].endswith(".dist-info")}
    assert tops == {"drillcosim"}
    for needed in ("drillcosim/scenes/paper_open_loop.toml",
                   "drillcosim/fmu_src/wrapper/fmi2_functions.c",
                   "drillcosim/fmu_src/wrapper/fmi2/fmi2Functions.h",
                   "drillcosim/fmu_src/wrapper/fmi2/LICENSE.txt",
                   "drillcosim/fmu_src/c_controller/model.c",
                   "drillcosim/fmu_src/c_controller/modelDescription.xml",
                   "drillcosim/plant/kernels.py", "drillcosim/cosim/master/execution.py"):
        assert needed in names
    meta = next(n for n in names if n.endswith(".dist-info/METADATA"))
    with zipfile.ZipFile(installed["wheel"]) as zf:
        metadata = zf.read(meta).decode()
        assert "License-Expression: MIT" in metadata.splitlines()
        assert zf.read(meta.replace("METADATA", "licenses/LICENSE")).startswith(b"MIT License")
    installed_tops = {p.name for p in installed["site"].iterdir()  # bin/: pip --target's scripts
                      if not p.name.endswith((".dist-info", ".pth")) and p.name != "bin"}
    assert installed_tops == {"drillcosim"}


def test_installed_cli_works_from_an_empty_folder(installed) -> None:
    where = subprocess.run([str(installed["py"]), "-c", "import drillcosim; "
                            "print(drillcosim.__file__)"], capture_output=True, text=True,
                           cwd=installed["work"], check=True).stdout.strip()
    assert Path(where).is_relative_to(installed["site"]), where  # not the checkout

    version = next(ln.split(": ", 1)[1] for ln in zipfile.ZipFile(installed["wheel"]).read(
        next(n for n in zipfile.ZipFile(installed["wheel"]).namelist()
             if n.endswith(".dist-info/METADATA"))).decode().splitlines()
        if ln.startswith("Version: "))
    shown = _run(installed, "--version")
    assert (shown.returncode, shown.stdout) == (0, f"drillcosim {version}\n"), shown.stderr
    api = subprocess.run([str(installed["py"]), "-c", "import drillcosim; "
                          "print(drillcosim.__version__)"], capture_output=True, text=True,
                         cwd=installed["work"], check=True)
    assert api.stdout == f"{version}\n"

    scenes = _run(installed, "scenes")
    assert scenes.returncode == 0, scenes.stderr
    assert "paper_open_loop" in scenes.stdout and "table1_axial_pulse" in scenes.stdout

    build = _run(installed, "build")
    assert build.returncode == 0, build.stderr
    fmus = sorted((installed["cache"] / "drillcosim" / "fmus").rglob("*.fmu"))
    assert [p.name for p in fmus] == ["DrillstringPlant.fmu", "StateSpaceController.fmu",
                                      "StrainController.fmu", "StrainControllerC.fmu",
                                      "TopDriveController.fmu"]

    run = _run(installed, "run", "paper_open_loop", "--stop-time", "0.5", "--no-progress")
    assert run.returncode == 0, run.stderr
    out = installed["work"] / "out" / "paper_open_loop"
    rows = (out / "results.csv").read_text().splitlines()
    assert rows[0].startswith("time,plant.")
    assert float(rows[-1].split(",")[0]) == pytest.approx(0.5)
    assert (out / "summary.json").is_file()

    bench = _run(installed, "bench", "--quick")
    assert bench.returncode == 2 and "checkout" in bench.stderr
    assert "Traceback" not in bench.stderr and len(bench.stderr.strip().splitlines()) == 1
