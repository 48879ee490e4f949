"""Reliability: bad parameters and scene files give one clear line, never a traceback.

Table-driven over every field of every plant parameter dataclass (``plant.params``,
found with ``dataclasses.fields`` and their ``metadata``): bad values (negative,
NaN, +-inf where not allowed, wrong type, bad list elements) must raise

* for library callers: ``ValueError`` (from the dataclass or from ``PlantParams``);
* through a scene file: ``SceneError`` (a ``ValueError``) whose message is one line
  naming the file, the key (``section.field``), the value and what is allowed.

Also: unknown keys get a "did you mean", malformed TOML points at the line, and the
CLI (``drillcosim modes`` / ``drillcosim run``) exits with code 2 and one line on
stderr, no traceback. Known bugs are ``xfail(strict=True)`` (see docs/reliability.md).
"""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys
from dataclasses import MISSING, fields
from pathlib import Path
from typing import Any

import pytest

from drillcosim.controller.params import ControllerParams
from drillcosim.plant.params import LoadParams, PlantParams, SectionParams
from drillcosim.plant.scene import SECTIONS, SceneError, load_scene, scene_from_dict

ROOT = Path(__file__).resolve().parents[1]
ALL_SECTIONS: dict[str, type] = {**SECTIONS, "loads": LoadParams, "sections": SectionParams}
#: A valid [[sections]] entry the bad value is added to (a string needs two bodies).
SECTION_BASE = {"length": 10.0, "segment_length": 1.0}

#: Fields that accept negative values (their range is still bounded below).
NEGATIVE_OK = {"top_drive.rotary_speed", "bit.weight_on_bit", "loads.magnitude", "gravity",
               "top_drive.hoisting_speed"}
#: Fields that accept +inf (documented: rigid springs, a load that never ends).
INF_OK = {"top_drive.axial_stiffness", "top_drive.lateral_stiffness",
          "top_drive.torsional_stiffness", "loads.duration", "damping.max_joint_rate"}
#: Sentinel values that look bad but are documented (stabilizers.damping = -1: material).
SENTINELS = {"stabilizers.damping": -1.0, "sections.added_mass_coefficient": -1.0}


def _param_fields() -> list[tuple[str, str, Any]]:
    """(section, field name, default) of every documented field, plus top-level gravity."""
    rows = []
    for sec, cls in ALL_SECTIONS.items():
        for f in fields(cls):
            if "unit" in f.metadata and f.default is not MISSING:
                rows.append((sec, f.name, f.default))
    rows.append(("", "gravity", 0.0))
    return rows


FIELDS = _param_fields()


def _bad_values(key: str, default: Any) -> list[tuple[str, Any, str]]:
    """(case id, bad value, fragment the message must contain) for one field."""
    cases: list[tuple[str, Any, str]] = []
    if isinstance(default, bool):
        cases += [("int", 1, "1"), ("str", "true", "'true'"), ("nan", math.nan, "nan")]
    elif isinstance(default, int):
        cases += [("fraction", 2.5, "2.5"), ("nan", math.nan, "nan"), ("inf", math.inf, "inf"),
                  ("str", "3", "'3'"), ("bool", True, "True"), ("negative", -1, "-1")]
    elif isinstance(default, float):
        cases += [("nan", math.nan, "nan"), ("-inf", -math.inf, "-inf"),
                  ("huge_negative", -1e20, "-1e+20"), ("str", "abc", "'abc'"),
                  ("bool", True, "True"), ("list", [1.0], "[1.0]")]
        if key not in INF_OK:
            cases.append(("inf", math.inf, "inf"))
        if key not in NEGATIVE_OK:
            neg = SENTINELS.get(key, 0.0) - 1.0
            cases.append(("negative", neg, repr(neg)))
    elif isinstance(default, str):
        cases += [("number", 5, "5"), ("unknown", "nonsense", "'nonsense'"),
                  ("nan", math.nan, "nan")]
    elif isinstance(default, tuple):
        cases += [("str", "abc", "'abc'"), ("number", 5, "5")]
        if key in ("stabilizers.heights", "sections.stabilizers"):
            cases += [("nan_element", [math.nan], "nan"), ("negative_element", [-1.0], "-1.0"),
                      ("str_element", ["a"], "'a'"), ("beyond_string", [1e3], "1000")]
        elif key.startswith("trajectory."):  # rows of numbers
            nan_row = [0.0, math.nan, 0.0] if key.endswith("survey") else [math.nan, 0.2]
            cases += [("number_element", [0], "0"), ("short_row", [[1.0]], "[1.0]"),
                      ("str_row", [["a", 1, 2]], "'a'"), ("nan_row", [nan_row], "nan")]
        else:  # 1-based body / joint numbers
            cases += [("zero_element", [0], "0"), ("fraction_element", [1.5], "1.5"),
                      ("bool_element", [True], "True"), ("beyond_n", [31], "31")]
    return cases


CASES = [pytest.param(sec, name, value, fragment, id=f"{sec or 'plant'}.{name}-{cid}")
         for sec, name, default in FIELDS
         for cid, value, fragment in _bad_values(f"{sec}.{name}" if sec else name, default)]


def test_table_covers_every_field_of_every_parameter_dataclass() -> None:
    documented = {(sec, f.name) for sec, cls in ALL_SECTIONS.items() for f in fields(cls)
                  if "unit" in f.metadata}
    covered = {(c.values[0], c.values[1]) for c in CASES}
    assert documented <= covered
    assert len(documented) >= 40
    for key in NEGATIVE_OK | INF_OK | set(SENTINELS):
        sec, _, name = key.rpartition(".")
        assert (sec, name) in covered or (sec == "" and name == "gravity"), key


def _toml_value(v: Any) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, float):
        return "nan" if math.isnan(v) else ("inf" if v > 0 else "-inf") if math.isinf(v) \
            else repr(v)
    if isinstance(v, int):
        return str(v)
    if isinstance(v, str):
        return json.dumps(v)
    if isinstance(v, list):
        return "[" + ", ".join(_toml_value(x) for x in v) + "]"
    raise TypeError(v)


def _scene_text(sec: str, name: str, value: Any) -> str:
    line = f"{name} = {_toml_value(value)}\n"
    if sec == "":
        return line
    if sec == "loads":
        return "[[loads]]\nmagnitude = 1.0\n" + line if name != "magnitude" else \
            "[[loads]]\n" + line
    if sec == "sections":
        base = "".join(f"{k} = {v!r}\n" for k, v in SECTION_BASE.items() if k != name)
        return "[contact]\nbodies = [1]\n\n[[sections]]\n" + base + line
    return f"[{sec}]\n{line}"


def _library_call(sec: str, name: str, value: Any) -> None:
    if sec == "":
        PlantParams(**{name: value})
    elif sec == "loads":
        PlantParams(loads=(LoadParams(**{name: value}),))
    elif sec == "sections":
        PlantParams(sections=(SectionParams(**{**SECTION_BASE, name: value}),))
    else:
        PlantParams(**{sec: ALL_SECTIONS[sec](**{name: value})})


# Bugs found here get an entry (key -> reason) and a strict xfail until fixed; none open now.
KNOWN_LIBRARY_BUGS: dict[tuple[str, str, str], str] = {}
KNOWN_SCENE_BUGS: dict[tuple[str, str, str], str] = {}


def _case_id(request: pytest.FixtureRequest) -> str:
    return request.node.callspec.id.split("-", 1)[1]


@pytest.mark.parametrize("sec, name, value, fragment", CASES)
def test_bad_value_raises_value_error_for_library_callers(
        request: pytest.FixtureRequest, sec: str, name: str, value: Any, fragment: str) -> None:
    reason = KNOWN_LIBRARY_BUGS.get((sec, name, _case_id(request)))
    if reason:
        request.applymarker(pytest.mark.xfail(strict=True, reason=reason))
    with pytest.raises(ValueError) as info:
        _library_call(sec, name, value)
    assert "\n" not in str(info.value)


@pytest.mark.parametrize("sec, name, value, fragment", CASES)
def test_bad_value_in_a_scene_file_gives_one_line_naming_file_key_value_and_range(
        request: pytest.FixtureRequest, tmp_path: Path, sec: str, name: str, value: Any,
        fragment: str) -> None:
    reason = KNOWN_SCENE_BUGS.get((sec, name, _case_id(request)))
    if reason:
        request.applymarker(pytest.mark.xfail(strict=True, reason=reason))
    path = tmp_path / "bad.toml"
    path.write_text(_scene_text(sec, name, value))
    with pytest.raises(SceneError) as info:
        load_scene(path)
    msg = str(info.value)
    assert isinstance(info.value, ValueError)
    assert "\n" not in msg
    assert msg.startswith(f"{path}: "), msg
    assert name in msg, msg
    if sec:
        assert f"{sec}." in msg or f"[{sec}]" in msg, msg
    assert fragment in msg, msg
    assert any(w in msg for w in ("allowed", "must", "beyond")), msg


@pytest.mark.parametrize("sec, name", [(s, n) for s, n, _ in FIELDS if s])
def test_misspelt_key_gets_did_you_mean(tmp_path: Path, sec: str, name: str) -> None:
    typo = name[:-1] if len(name) > 4 else name + "x"
    path = tmp_path / "typo.toml"
    path.write_text(_scene_text(sec, typo, 1.0))
    with pytest.raises(SceneError) as info:
        load_scene(path)
    msg = str(info.value)
    assert msg.startswith(str(path)) and f"unknown key '{typo}'" in msg
    assert f"did you mean '{name}'?" in msg, msg


@pytest.mark.parametrize("text, expected", [
    ("gravty = 9.81\n", "did you mean 'gravity'?"),
    ("[pipes]\nlength = 80.0\n", "did you mean 'pipe'?"),
    ("[[load]]\nmagnitude = 1.0\n", "did you mean 'loads'?"),
    ("[cosim]\nstepp = 1e-3\n", None),  # validated by the run's config, not by load_scene
])
def test_unknown_top_level_keys_get_did_you_mean(tmp_path: Path, text: str,
                                                 expected: str | None) -> None:
    path = tmp_path / "typo.toml"
    path.write_text(text)
    if expected is None:
        from drillcosim.cosim.scenario.config import ConfigError, load_config

        assert load_scene(path).plant == load_scene("paper_open_loop").plant.__class__()
        with pytest.raises(ConfigError, match=r"\[cosim\] unknown key 'stepp' \(did you mean "
                                              r"'step'\?\)"):
            load_config(path)
        return
    with pytest.raises(SceneError, match=expected):
        load_scene(path)


@pytest.mark.parametrize("text, line", [
    ('description = "x"\n[pipe]\nlength = \n', 3),
    ("[pipe]\nlength = 80.0\nlength = 81.0\n", 3),  # duplicate key
    ("[pipe\nlength = 80.0\n", 1),
    ('gravity = 9.81\n\n\n\ndescription = "unterminated\n', 5),
    ("[bit]\ndisplacement_amplitude = 3 mm\n", 2),
])
def test_malformed_toml_points_at_the_line(tmp_path: Path, text: str, line: int) -> None:
    path = tmp_path / "broken.toml"
    path.write_text(text)
    with pytest.raises(SceneError) as info:
        load_scene(path)
    msg = str(info.value)
    assert msg.startswith(f"{path}: malformed TOML") and f"line {line}" in msg, msg
    assert "\n" not in msg


def test_extends_errors_name_the_file(tmp_path: Path) -> None:
    (tmp_path / "a.toml").write_text('extends = "b"\n')
    (tmp_path / "b.toml").write_text('extends = "a"\n')
    with pytest.raises(SceneError, match="cycle"):
        load_scene(tmp_path / "a.toml")
    (tmp_path / "c.toml").write_text('extends = "no_such_scene"\n')
    with pytest.raises(SceneError, match="'no_such_scene' not found"):
        load_scene(tmp_path / "c.toml")
    (tmp_path / "d.toml").write_text("extends = 5\n")
    with pytest.raises(SceneError, match="must be a scene name"):
        load_scene(tmp_path / "d.toml")


@pytest.mark.parametrize("bad", [
    {"pipe": 5}, {"loads": {"magnitude": 1.0}}, {"loads": [5]}, {"outputs": "strain1_C"},
    {"outputs": ["no_such_output"]}, {"model": "fem"}, {"description": 5}, {"controller": 1},
    {"model": "axial_torsional", "controller": {"enabled": True}},
])
def test_malformed_tables_raise_scene_error(bad: dict) -> None:
    with pytest.raises(SceneError) as info:
        scene_from_dict(bad, source="s.toml")
    assert str(info.value).startswith("s.toml: ") and "\n" not in str(info.value)


CONTROLLER_BAD = [("gain", v) for v in (math.nan, -1.0, math.inf, "1e9", True)] + \
    [("force_limit", v) for v in (math.nan, -1.0, "x")] + \
    [("symmetric_force_limit", v) for v in (math.nan, -1.0)] + \
    [("switch_on_time", v) for v in (math.nan, -1.0, math.inf)] + \
    [("lag_time_constant", v) for v in (math.nan, -1.0, math.inf)] + \
    [("mode", v) for v in ("both", 1, None)] + [("enabled", v) for v in (1, "yes", None)] + \
    [("gain_matrix", v) for v in ("eye", 3.0, None)]


def test_controller_table_covers_every_field() -> None:
    assert {f.name for f in fields(ControllerParams)} == {n for n, _ in CONTROLLER_BAD}


@pytest.mark.parametrize("name, value", CONTROLLER_BAD)
def test_bad_controller_parameter_raises_one_line_value_error(name: str, value: Any) -> None:
    with pytest.raises(ValueError) as info:
        ControllerParams(**{name: value})
    msg = str(info.value)
    assert msg.startswith(f"{name} = ") and "allowed" in msg and "\n" not in msg, msg


# --------------------------------------------------------------------------- CLI
def _cli(args: list[str], cwd: Path) -> subprocess.CompletedProcess:
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    return subprocess.run([sys.executable, "-m", "cosim.cli", *args], cwd=cwd, env=env,
                          capture_output=True, text=True, timeout=300)


BAD_FILES = {
    "neg.toml": "[pipe]\nlength = -80.0\n",
    "typo.toml": "[pipe]\nlenght = 80.0\n",
    "broken.toml": 'description = "x"\n[pipe]\nlength = \n',
    "inf.toml": "[pipe]\nlength = inf\n",
}


@pytest.mark.parametrize("args, expected", [
    (["modes", "NO_SUCH_SCENE"], "scene 'NO_SUCH_SCENE' not found"),
    (["modes", "neg.toml"], "neg.toml: pipe.length = -80.0 is out of range: allowed (0, inf) m"),
    (["modes", "typo.toml"], "did you mean 'length'?"),
    (["modes", "broken.toml"], "malformed TOML: Invalid value (at line 3"),
    (["modes", "missing.toml"], "missing.toml: scene file not found"),
    (["modes", "inf.toml"], "pipe.length"),
    (["run", "NO_SUCH_SCENE"], "scene 'NO_SUCH_SCENE' not found"),
    (["run", "neg.toml", "--no-plots"], "pipe.length = -80.0"),
    (["run", "broken.toml"], "line 3"),
    (["run", "--set", "pipe.length=-1", "--no-plots"], "pipe.length = -1"),
    (["run", "--set", "cosim.stepp=1e-3", "--no-plots"], "did you mean 'step'?"),
    (["run", "--stop-time", "nan", "--no-plots"], "stop_time = nan"),
    (["run", "--gain", "-1", "--no-plots"], "gain = -1.0 is out of range"),
    (["run", "--set", "pipe.length", "--no-plots"], "expected KEY=VALUE"),
])
def test_cli_bad_input_exits_2_with_one_line_and_no_traceback(
        tmp_path: Path, args: list[str], expected: str) -> None:
    for name, text in BAD_FILES.items():
        (tmp_path / name).write_text(text)
    proc = _cli(args, tmp_path)
    assert proc.returncode == 2, proc.stderr
    assert "Traceback" not in proc.stderr and "Traceback" not in proc.stdout
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1, proc.stderr
    assert lines[0].startswith(f"drillcosim {args[0]}: error: ")
    assert expected in lines[0], lines[0]
    assert not (tmp_path / "out").exists()  # nothing written


def test_library_callers_get_a_user_error_from_simulate(tmp_path: Path) -> None:
    from drillcosim import UserError, simulate

    with pytest.raises(UserError, match="not found"):
        simulate("NO_SUCH_SCENE", csv_path=tmp_path / "out" / "results.csv")
    with pytest.raises(UserError, match="pipe.length"):
        simulate(overrides={"pipe.length": -1}, csv_path=tmp_path / "out" / "results.csv")
    assert issubclass(UserError, ValueError)
    assert not (tmp_path / "out").exists()
