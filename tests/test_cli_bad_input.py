"""Bad input on the command line: one line naming the option, exit code 2, no traceback, and an
earlier run's files in the output folder untouched.

* a file that is not an FMU given as ``--controller-fmu`` / ``--plant-fmu`` (not a zip archive,
  or a zip without ``modelDescription.xml``: refused with the scene's other settings; a zip
  whose ``modelDescription.xml`` cannot be read: refused when the system is built);
* a negative number in exponent notation after an option (``--delay -1e-4``: argparse alone
  reads it as an option);
* a value given on the command line named by its option (``--stop-time``, ``--step``,
  ``--delay``, ``--gain``, ``--set``), not blamed on the scene file; a bad value of the scene
  file itself still names the file. The API names its keywords the same way.
"""

from __future__ import annotations

import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

import drillcosim
from drillcosim.cosim.cli import main
from drillcosim.cosim.scenario.config import ConfigError

ROOT = Path(__file__).resolve().parents[1]
CONSOLE = Path(sys.executable).with_name("drillcosim")
README = str(ROOT / "README.md")
MULTIPLE = "must be a positive integer multiple of the step 0.00025 s"


def _broken_fmu(folder: Path) -> Path:
    path = folder / "broken.fmu"
    with zipfile.ZipFile(path, "w") as z:
        z.writestr("modelDescription.xml", "<fmiModelDescription")
    return path


def _zip_without_description(folder: Path) -> Path:
    path = folder / "empty.fmu"
    with zipfile.ZipFile(path, "w") as z:
        z.writestr("binaries/readme.txt", "no model description")
    return path


CASES = [
    (["--controller-fmu", README], f"--controller-fmu: '{README}' is not an FMU (an FMU is a "
                                   "zip archive with a modelDescription.xml)"),
    (["--plant-fmu", README], f"--plant-fmu: '{README}' is not an FMU"),
    (["--controller-fmu", "{empty}"], "--controller-fmu: '{empty}' is not an FMU: the zip "
                                      "archive has no modelDescription.xml"),
    (["--controller-fmu", "{broken}"], "FMU 'controller': cannot read the modelDescription of "
                                       "'{broken}'"),
    (["--plant-fmu", "no_such.fmu"], "--plant-fmu: no file 'no_such.fmu'"),
    (["--delay", "-1e-4"], "--delay: cosim.actuator_delay = -0.0001 must be >= 0 [s]"),
    (["--step", "-2.5E-4"], "--step: cosim.step = -0.00025 must be > 0 [s]"),
    (["--gain", "-.5"], "--gain: controller.gain = -0.5 is out of range; allowed: 0 <= gain"),
    (["--stop-time", "1.0001"], f"--stop-time: cosim.stop_time = 1.0001 s: {MULTIPLE}"),
    (["--set", "cosim.stop_time=1.0001"], f"--set: cosim.stop_time = 1.0001 s: {MULTIPLE}"),
    (["--set", "pipe.outer_diameter=-1"],
     "--set: pipe.outer_diameter = -1 is out of range: allowed (0, 5] m"),
]


@pytest.fixture
def earlier_run(tmp_path: Path) -> tuple[Path, dict[str, bytes]]:
    """An output folder holding an earlier run's files (stand-ins): the bad run must keep them."""
    out = tmp_path / "out"
    out.mkdir()
    files = {"results.csv": b"time,x\n0,1\n", "summary.json": b"{}\n", "orbit.png": b"png"}
    for name, data in files.items():
        (out / name).write_bytes(data)
    return out, files


@pytest.mark.parametrize(("args", "expected"), CASES, ids=[" ".join(a) for a, _ in CASES])
def test_bad_input_is_one_line_naming_the_option(args, expected, earlier_run, tmp_path,
                                                 capsys) -> None:
    out, files = earlier_run
    names = {"{broken}": str(_broken_fmu(tmp_path)), "{empty}": str(_zip_without_description(
        tmp_path))}
    for key, value in names.items():
        args = [value if a == key else a for a in args]
        expected = expected.replace(key, value)
    code = main(["run", *args, "--out", str(out), "--no-plots", "--no-progress"])
    err = capsys.readouterr().err
    assert code == 2, err
    assert err.startswith(f"drillcosim run: error: {expected}"), err
    assert err.count("\n") == 1 and "Traceback" not in err
    assert "paper_closed_loop.toml" not in err  # a command-line value is not the file's
    assert {p.name: p.read_bytes() for p in out.iterdir()} == files


def test_a_bad_value_of_the_scene_file_names_the_file(tmp_path: Path, capsys) -> None:
    """An override of another key does not take the blame from the file (here --step makes the
    file's stop time no multiple of the step: the file's key is named, with its value)."""
    scene = tmp_path / "odd.toml"
    scene.write_text('extends = "paper_closed_loop"\n\n[cosim]\nstop_time = 0.0101\n')
    code = main(["run", str(scene), "--step", "1e-3", "--gain", "1e8", "--no-plots",
                 "--out", str(tmp_path / "out")])
    err = capsys.readouterr().err
    assert code == 2
    assert err == (f"drillcosim run: error: {scene}: [cosim] stop_time = 0.0101 s: must be a "
                   "positive integer multiple of the step 0.001 s\n")


def test_the_console_script_joins_negative_numbers(tmp_path: Path) -> None:
    """The installed ``drillcosim`` script (sys.argv path) reads ``--delay -1e-4`` as a value."""
    proc = subprocess.run([str(CONSOLE), "run", "--delay", "-1e-4", "--no-plots",
                           "--out", str(tmp_path / "out")], capture_output=True, text=True,
                          timeout=300)
    assert proc.returncode == 2, proc.stderr
    assert proc.stderr == ("drillcosim run: error: --delay: cosim.actuator_delay = -0.0001 "
                           "must be >= 0 [s]\n")
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize(("kwargs", "expected"), [
    ({"controller_fmu": README}, f"controller_fmu: '{README}' is not an FMU"),
    ({"stop_time": 1.0001}, f"stop_time: cosim.stop_time = 1.0001 s: {MULTIPLE}"),
    ({"delay": -1e-4}, "delay: cosim.actuator_delay = -0.0001 must be >= 0 [s]"),
    ({"overrides": {"cosim.step": 0.0}}, "overrides: cosim.step = 0.0 must be > 0 [s]"),
])
def test_the_api_names_its_keywords(kwargs, expected) -> None:
    with pytest.raises(drillcosim.UserError) as info:
        drillcosim.load_scene("paper_closed_loop", **kwargs)
    assert isinstance(info.value, ConfigError) and isinstance(info.value, ValueError)
    assert str(info.value).startswith(expected), str(info.value)
