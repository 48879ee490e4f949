"""The list of required tools (``.ci/required-tools``) is the one place the suite and CI read.

* every row's check passes on this machine (a failure under CI, a skip naming the row
  elsewhere): the list itself is checked, not only the tests that use a row;
* every row is used: some test calls ``missing("<row>")``, so the list holds nothing stale;
* the helper is strict: under ``CI=true`` a missing tool or test package fails the test, without
  it the test skips with one line; a name that is not a row is an error, not a skip.
"""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import pytest

from support.required import ROOT, read_tools
from support.required import check as run_check
from support.required import missing as tool_missing

TOOLS = read_tools()


@pytest.mark.parametrize("name", sorted(TOOLS))
def test_required_tool_is_present(name: str) -> None:
    proc = run_check(TOOLS[name])
    if proc.returncode != 0:
        tool_missing(name, f"its check `{TOOLS[name].check}` exited {proc.returncode}")


def test_every_row_is_used_by_a_test() -> None:
    """Each row is named by a test's ``missing(...)`` call (``missing(f"python3.{minor}")``
    names every ``python3.N`` row)."""
    used: set[str] = set()
    for path in (ROOT / "tests").rglob("*.py"):
        if path.name == Path(__file__).name:
            continue
        text = path.read_text()
        used |= set(re.findall(r"""missing\(\s*["']([\w.\-]+)["']""", text))
        if re.search(r"""missing\(\s*f["']python3\.\{""", text):
            used |= {n for n in TOOLS if re.fullmatch(r"python3\.\d+", n)}
    assert sorted(set(TOOLS) - used) == [], "rows of .ci/required-tools no test names"


def test_ci_script_reads_the_list() -> None:
    """.ci/run installs the list through .ci/install-tools (and holds no second list)."""
    script = (ROOT / ".ci" / "run").read_text()
    assert "bash .ci/install-tools" in script
    assert "apt-get install" not in script, "a package installed by .ci/run outside the list"


def test_install_tools_installs_or_fails_naming_the_tool(tmp_path: Path) -> None:
    """A row whose check fails is installed by its install command (then checked again); a row
    that nothing installs ("-") or whose install does not help makes the script exit 1 naming
    it, after trying every row."""
    flag = tmp_path / "installed"
    rows = (f"present :: true :: false\n"
            f"installable :: test -f {flag} :: touch {flag}\n"
            f"# a comment\n\n"
            f"absent :: false :: -\n"
            f"broken :: false :: true\n")
    (tmp_path / "tools").write_text(rows)
    proc = subprocess.run(["bash", str(ROOT / ".ci" / "install-tools"), str(tmp_path / "tools")],
                          capture_output=True, text=True, timeout=60)
    assert proc.returncode == 1
    assert flag.is_file()
    assert proc.stdout.splitlines() == [
        "ci: installing installable",
        "ci: required tool absent is missing and could not be installed (check: false)",
        "ci: installing broken",
        "ci: required tool broken is missing and could not be installed (check: false)",
        "ci: missing: absent broken"]
    (tmp_path / "tools").write_text(rows.split("# a comment")[0])
    again = subprocess.run(["bash", str(ROOT / ".ci" / "install-tools"), str(tmp_path / "tools")],
                           capture_output=True, text=True, timeout=60)
    assert (again.returncode, again.stdout) == (0, "")


HELPER = """
import pytest
from support.required import missing, import_module

def test_tool():
    missing("gcc", "looked on PATH")

def test_package():
    import_module("no_such_package_dcs")

def test_not_a_row():
    missing("not-a-row")
"""


@pytest.mark.parametrize("ci", ["true", ""])
def test_missing_fails_under_ci_and_skips_elsewhere(tmp_path: Path, ci: str) -> None:
    (tmp_path / "test_helper.py").write_text(HELPER)
    env = {"CI": ci, "PYTHONPATH": str(ROOT / "tests"), "PATH": "/usr/bin:/bin"}
    proc = subprocess.run([sys.executable, "-m", "pytest", "-q", "-rs", "-p", "no:cacheprovider",
                           "-p", "no:randomly", str(tmp_path / "test_helper.py")],
                          capture_output=True, text=True, cwd=tmp_path, env=env, timeout=120)
    out = proc.stdout
    assert "ValueError: 'not-a-row' is not a row of .ci/required-tools" in out, out
    if ci:
        assert "3 failed" in out, out
        assert "CI: required tool gcc is missing: looked on PATH" in out, out
        assert "CI: Python package no_such_package_dcs is missing" in out, out
    else:
        assert "1 failed, 2 skipped" in out, out
        assert "required tool gcc is missing: looked on PATH (.ci/run installs" in out, out
