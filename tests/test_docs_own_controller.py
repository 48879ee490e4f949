"""docs/your_own_controller.md runs as written.

The page's blocks run in order in an empty folder: ```` ```lang file=NAME ```` writes NAME,
a ``run`` flag runs it with this interpreter, and each ``$`` line of a ``console`` block runs
(``pythonfmu``, ``drillcosim``: this environment's) and must exit with the code its comment
names (``# exit 2``; 0 without one). The page's own asserts are the checks: the user's PD FMU
equals the project's PD law bit for bit, the kd sweep separates the diverging and the stable
point; here, besides, the run's summary records the foreign FMU and the parameters it got.
"""

from __future__ import annotations

import json
import os
import re
import shlex
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PAGE = ROOT / "docs" / "your_own_controller.md"
BLOCK = re.compile(r"^```(\w+)([^\n]*)\n(.*?)^```", re.S | re.M)

pytestmark = pytest.mark.slow


def _blocks(text: str) -> list[tuple[str, dict[str, str], str]]:
    out = []
    for lang, info, body in BLOCK.findall(text):
        flags = dict(w.split("=", 1) if "=" in w else (w, "") for w in info.split())
        out.append((lang, flags, body))
    return out


def test_the_page_runs_as_written(tmp_path) -> None:
    env = dict(os.environ)
    env["PATH"] = os.pathsep.join([str(Path(sys.executable).parent), env.get("PATH", "")])
    ran = []
    for lang, flags, body in _blocks(PAGE.read_text()):
        if "file" in flags:
            (tmp_path / flags["file"]).write_text(body)
            if "run" in flags:
                proc = subprocess.run([sys.executable, flags["file"]], cwd=tmp_path, env=env,
                                      capture_output=True, text=True)
                assert proc.returncode == 0, proc.stdout + proc.stderr
                ran.append(flags["file"])
        elif lang == "console":
            for line in body.splitlines():
                if not line.startswith("$ "):
                    continue
                command, _, comment = line[2:].partition("#")
                want = int(m.group(1)) if (m := re.search(r"exit (\d+)", comment)) else 0
                proc = subprocess.run(shlex.split(command), cwd=tmp_path, env=env,
                                      capture_output=True, text=True)
                assert proc.returncode == want, (line, proc.stdout + proc.stderr)
                if want == 2:  # bad input: one line per problem, no traceback
                    assert "Traceback" not in proc.stderr and "kdd" in proc.stderr
                ran.append(command.split()[0:2])
    assert ran and "check.py" in ran
    summary = json.loads((tmp_path / "out" / "my_pd" / "summary.json").read_text())
    ctrl = summary["components"]["controller"]
    assert ctrl["model_name"] == "MyPD" and ctrl["generation_tool"].startswith("PythonFMU")
    assert ctrl["parameters"] == {"kp": 1e9, "kd": 1e6, "tf": 2.5e-4}
    assert Path(ctrl["fmu"]).name == "MyPD.fmu" and ctrl["guid"]
    assert summary["components"]["plant"]["model_name"] == "DrillstringPlant"
