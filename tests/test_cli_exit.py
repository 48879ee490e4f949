"""The console script's quick exit (:func:`drillcosim.cosim.cli.console_main`): it skips only
Python's finalization. What a command printed arrives whole through a pipe, the exit handlers
registered in the process still run, the exit code is the command's, and an internal error
still leaves with its traceback."""

from __future__ import annotations

import subprocess
import sys

import pytest

SCRIPT = """
import atexit, sys
atexit.register(lambda: print("exit handler ran", flush=True))
sys.argv = ["drillcosim", *sys.argv[1:]]
from drillcosim.cosim import cli
if sys.argv[1] == "boom":
    cli.main = lambda argv=None: 1 / 0   # an internal error inside the command
    sys.argv[1] = "scenes"
sys.exit(cli.console_main())
"""


def run(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-c", SCRIPT, *args], capture_output=True, text=True,
                          timeout=300)


def test_output_whole_handlers_run_and_code_kept() -> None:
    proc = run("scenes")
    assert proc.returncode == 0, proc.stderr
    lines = proc.stdout.splitlines()
    assert "paper_closed_loop" in proc.stdout and len(lines) > 5
    assert lines[-1] == "exit handler ran"  # after everything the command printed


@pytest.mark.parametrize("args", [("run", "no_such_scene"), ("boom",)])
def test_errors_keep_their_exit(args: tuple[str, ...]) -> None:
    proc = run(*args)
    assert proc.stdout.splitlines()[-1:] == ["exit handler ran"]
    if args[0] == "boom":  # internal error: traceback, Python's usual exit code 1
        assert proc.returncode == 1 and "ZeroDivisionError" in proc.stderr
    else:  # bad input: one line, exit 2
        assert proc.returncode == 2 and proc.stderr.count("\n") == 1, proc.stderr
        assert "no_such_scene" in proc.stderr and "Traceback" not in proc.stderr
