"""``drillcosim doctor [FMU]``: the FMU's own Python search, run without starting anything.

The report's candidate lines must be the very lines a C host logs when ``fmi2Instantiate`` runs
the search in the same environment (one search code: the wrapper's, called through its
``drillcosim_doctor`` export), the verdict and exit status must follow what the C host then
does (runs: 0; NULL: 1), and bad input is one line with exit status 2.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from support import c_host

pytestmark = [pytest.mark.needs_cc]


def host_env(tmp_path: Path, **extra: str) -> dict[str, str]:
    env = {k: v for k, v in os.environ.items()
           if not k.startswith(("PYTHON", "DRILLCOSIM", "VIRTUAL_ENV", "XDG_CONFIG"))}
    env.update(PATH="/usr/bin:/bin", HOME=str(tmp_path / "home"), **extra)
    return env


def doctor(fmu: Path | None, env: dict[str, str], cwd: Path) -> subprocess.CompletedProcess:
    cmd = [sys.executable, "-m", "drillcosim.cosim.cli", "doctor", *([str(fmu)] if fmu else [])]
    return subprocess.run(cmd, env=env, cwd=cwd, capture_output=True, text=True, timeout=300)


def candidate_lines(text: str) -> list[str]:
    """The search's lines (one per candidate), the unzip folder's name left out."""
    lines = [ln.strip() for ln in text.splitlines() if ln.strip()[:3] in ("1. ", "2. ", "3. ",
                                                                          "4. ")]
    return [ln.split(": none of", 1)[0] for ln in lines]


@pytest.mark.parametrize("python", ["this", "bare"])
def test_the_report_is_the_wrappers_search_and_the_verdict_what_a_c_host_does(
        python: str, host: Path, project_fmus: dict[str, Path], bare_python: Path,
        tmp_path: Path) -> None:
    chosen = sys.executable if python == "this" else str(bare_python)
    env = host_env(tmp_path, DRILLCOSIM_PYTHON=chosen)
    fmu = project_fmus["StrainController"]
    report = doctor(fmu, env, tmp_path)
    d = c_host.unzip(fmu, tmp_path / "unzip")
    run = c_host.run_host(host, d, "StrainController", 0.002, 1e-3, [], [], env, tmp_path)
    if python == "this":
        assert (report.returncode, run.returncode) == (0, 0), (report.stderr, run.stderr)
        assert "Verdict: a Python is found" in report.stdout
        assert f"1. $DRILLCOSIM_PYTHON = {chosen}: Python 3." in report.stdout
        assert "would be used" in report.stdout and "), used" in run.stderr
        lines = candidate_lines(report.stdout)
        assert lines == [ln.replace("), used", "), would be used")
                         for ln in candidate_lines(run.stderr)]
    else:
        assert (report.returncode, run.returncode) == (1, 3), (report.stderr, run.stderr)
        assert "Verdict: no usable Python" in report.stdout
        assert "lacks numpy (ModuleNotFoundError: No module named 'numpy')" in report.stdout
        assert "How to fix: install numpy into a CPython 3.10 to 3.13" in report.stdout
        assert candidate_lines(report.stdout) == candidate_lines(run.stderr)
    assert "CPython 3.10-3.13 with these modules importable: numpy" in report.stdout
    assert f"This Python ({sys.version.split()[0]}, {sys.executable}) can host it." \
        in report.stdout


def test_the_path_search_is_reported_candidate_by_candidate(
        project_fmus: dict[str, Path], bare_python: Path, tmp_path: Path) -> None:
    env = host_env(tmp_path)
    env["PATH"] = f"{bare_python.parent}:{Path(sys.executable).parent}:/usr/bin:/bin"
    proc = doctor(project_fmus["StrainController"], env, tmp_path)
    assert proc.returncode == 0, proc.stderr
    lines = candidate_lines(proc.stdout)
    assert lines[0] == "1. $DRILLCOSIM_PYTHON: not set"
    assert lines[1] == "2. config file"
    assert lines[2].startswith(f"3. on PATH: {bare_python.parent}/python3: Python 3.")
    assert "lacks numpy" in lines[2]
    assert lines[-1].startswith(f"3. on PATH: {Path(sys.executable).parent}/python3")
    assert lines[-1].endswith("would be used")


def test_bad_input_is_one_line_and_exit_2(project_fmus: dict[str, Path],
                                          c_controller_fmu: Path, tmp_path: Path) -> None:
    env = host_env(tmp_path)
    missing = doctor(tmp_path / "nope.fmu", env, tmp_path)
    assert missing.returncode == 2 and "no such FMU file" in missing.stderr
    foreign = doctor(c_controller_fmu, env, tmp_path)  # a C FMU: not our wrapper
    assert foreign.returncode == 2 and "no drillcosim_doctor" in foreign.stderr
    (tmp_path / "text.fmu").write_text("not a zip")
    text = doctor(tmp_path / "text.fmu", env, tmp_path)
    assert text.returncode == 2 and "not a zip file" in text.stderr
    for proc in (missing, foreign, text):
        assert len(proc.stderr.strip().splitlines()) == 1 and "Traceback" not in proc.stderr
