"""Scene -> co-simulation system mapping (the session's FMUs are read, none is run)."""

from __future__ import annotations

import dataclasses
import math

import pytest

from drillcosim.cosim.scenario.run import parse_set
from drillcosim.cosim.scenario.scene_system import (
    COSIM_KEYS,
    cosim_schema_markdown,
    cosim_settings,
    scene_system,
    span_info,
)
from drillcosim.plant.scene import load_scene

FMUS: dict[str, str] = {}


@pytest.fixture(autouse=True)
def _session_fmus(project_fmus) -> None:
    """scene_system reads the modelDescriptions (the pair is wired and checked by name)."""
    FMUS.update(plant_fmu=project_fmus["DrillstringPlant"],
                controller_fmu=project_fmus["StrainController"])


def _scene(name: str = "paper_closed_loop", cosim: dict | None = None, **over):
    """A shipped scene with its [cosim] table replaced (the scene files may set one)."""
    return dataclasses.replace(load_scene(name, overrides=over or None), cosim=dict(cosim or {}))


def _fmus(sc) -> dict[str, str]:
    """The session FMUs (the controller only when the scene's controller is on)."""
    on = sc.controller.get("enabled", False)
    return {k: v for k, v in FMUS.items() if on or k == "plant_fmu"}


def _system(name: str = "paper_closed_loop", **over):
    sc = _scene(name, **over)
    return scene_system(sc, **_fmus(sc))


def test_closed_loop_connections_delays_and_parameters() -> None:
    ss = _system(cosim={"actuator_delay": 0.003, "sensor_delay": 0.001, "coupling": "linear",
                        "controller_sample_period": 0.002, "algorithm": "gauss_seidel",
                        "order": ["controller", "plant"]})
    sys_ = ss.system
    assert [f.name for f in sys_.fmus] == ["plant", "controller"]
    conns = {(c.source, c.target): c for c in sys_.connections}
    assert len(conns) == 8
    for s in (1, 2):
        for a in ("C", "E"):
            sense = conns[(f"plant.strain{s}_{a}", f"controller.strain{s}_{a}")]
            act = conns[(f"controller.actuator{s}_force_{a}", f"plant.actuator{s}_force_{a}")]
            assert (sense.delay, act.delay) == (0.001, 0.003)
            assert sense.coupling == act.coupling == "linear"
    assert sys_.fmu("controller").sample_period_ticks == 2
    assert sys_.fmu("plant").sample_period_ticks == 1
    assert sys_.algorithm == "gauss_seidel" and sys_.stepping_order == ("controller", "plant")
    assert sys_.base_step == 1e-3 and sys_.stop_time == 30.0
    assert sys_.fmu("plant").parameters == {"scene": "paper_closed_loop"}
    assert sys_.fmu("controller").parameters == {
        "gain": 1e9, "mode": 0, "force_limit": 5000.0, "symmetric_force_limit": 1e30,
        "switch_on_time": 0.0, "lag_time_constant": 0.0, "enabled": True}
    assert "controller.actuator1_force_C" in ss.outputs
    assert {"plant.body11_X", "plant.body11_Y", "plant.body26_contact_force",
            "plant.actuator2_power", "plant.strain1_C"} <= set(ss.outputs)


def test_restricted_actuator_maps_mode_to_integer() -> None:
    params = _system("paper_restricted_actuator").system.fmu("controller").parameters
    assert params["mode"] == 1 and params["force_limit"] == 5000.0


def test_defaults_and_output_interval() -> None:
    s = cosim_settings(_scene(cosim={"step": 2e-4}))
    assert s.output_interval == pytest.approx(1e-3) and s.controller_sample_ticks == 1
    assert (s.actuator_delay, s.sensor_delay, s.coupling, s.algorithm) == (0.0, 0.0, "zoh",
                                                                         "jacobi")


def test_disabled_controller_runs_the_plant_alone() -> None:
    ss = _system("paper_open_loop")
    assert [f.name for f in ss.system.fmus] == ["plant"]
    assert ss.system.connections == ()
    assert not any(o.startswith("controller.") for o in ss.outputs)


def test_plant_overrides_become_flattened_parameters() -> None:
    sc = _scene(top_drive={"rotary_speed": 10.0})
    ss = scene_system(sc, plant_overrides={"top_drive": {"rotary_speed": 10.0}, "gravity": 0.0},
                      **_fmus(sc))
    assert ss.system.fmu("plant").parameters == {
        "scene": "paper_closed_loop", "top_drive.rotary_speed": 10.0, "gravity": 0.0}
    with pytest.raises(ValueError, match=r"stabilizers.heights .*scene file"):
        scene_system(sc, plant_overrides={"stabilizers": {"heights": [0.0, 30.0]}}, **_fmus(sc))


def test_spans_long_and_short() -> None:
    info = span_info(load_scene("paper_open_loop"))
    assert info[11]["span"] == "long" and info[26]["span"] == "short"
    assert info[11]["span_length"] == pytest.approx(53.33)


@pytest.mark.parametrize(("over", "pattern"), [
    ({"cosim": {"stepp": 1e-3}}, r"\[cosim\] unknown key 'stepp' \(did you mean 'step'\?\)"),
    ({"cosim": {"actuator_dealy": 0.1}}, r"did you mean 'actuator_delay'"),
    ({"cosim": {"step": 0.0}}, r"\[cosim\] step = 0.0 must be > 0"),
    ({"cosim": {"step": "fast"}}, r"\[cosim\] step = 'fast' must be a finite number"),
    ({"cosim": {"sensor_delay": -1e-3}}, r"\[cosim\] sensor_delay = -0.001 must be >= 0"),
    ({"cosim": {"controller_sample_period": 0.0015}},
     r"controller_sample_period = 0.0015 must be a positive integer multiple of step"),
    ({"cosim": {"output_interval": 2.5e-3}}, r"output_interval"),
    ({"cosim": {"algorithm": "jacobbi"}}, r"did you mean 'jacobi'"),
    ({"cosim": {"coupling": "cubic"}}, r"\[cosim\] coupling = 'cubic' is not allowed"),
    ({"cosim": {"order": ["plant"]}}, r"order .* permutation"),
    ({"controller": {"gian": 1e9}}, r"\[controller\] unknown key 'gian' \(did you mean 'gain'"),
    ({"controller": {"gain": -1.0}}, r"\[controller\] gain = -1.0 is out of range"),
    ({"controller": {"mode": "pull"}}, r"\[controller\] mode = 'pull'"),
])
def test_bad_keys_and_values_are_one_line_errors(over, pattern) -> None:
    with pytest.raises(ValueError, match=pattern) as info:
        _system(**over)
    msg = str(info.value)
    assert "\n" not in msg and "paper_closed_loop.toml" in msg


def test_schema_markdown_lists_every_key_with_units() -> None:
    doc = cosim_schema_markdown()
    for key, (_default, unit, _text) in COSIM_KEYS.items():
        assert any(line.startswith(f"| {key} |") and f"| {unit} |" in line
                   for line in doc.splitlines()), key
    assert "| gain | 1e+09 | N |" in doc and "## [cosim]" in doc


def test_parse_set_values_are_toml() -> None:
    assert parse_set(["cosim.actuator_delay=2e-3", "controller.enabled=true",
                      "controller.mode=compressive_only", 'controller.mode2="x"',
                      "gravity=0", "stabilizers.heights=[0.0, 30.0]"]) == {
        "cosim": {"actuator_delay": 0.002},
        "controller": {"enabled": True, "mode": "compressive_only", "mode2": "x"},
        "gravity": 0, "stabilizers": {"heights": [0.0, 30.0]}}
    for bad in ("cosim.step", "=1", "cosim..step=1"):
        with pytest.raises(ValueError, match="expected section.key=value"):
            parse_set([bad])
    assert math.isinf(parse_set(["controller.symmetric_force_limit=inf"])["controller"][
        "symmetric_force_limit"])
