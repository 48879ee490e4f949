"""The typed configuration (cosim.scenario.config) and the one builder (cosim.scenario.build):
scene -> config -> system (the session's FMUs are read, none is run)."""

from __future__ import annotations

import math

import pytest

from drillcosim.cosim.scenario.build import build_system
from drillcosim.cosim.scenario.config import (
    COSIM_KEYS,
    ConfigError,
    key_paths,
    load_config,
    parse_set,
)
from drillcosim.cosim.scenario.schema import cosim_schema_markdown
from drillcosim.cosim.scenario.summary import span_info
from drillcosim.plant.scene import load_scene

FMUS: dict[str, str] = {}
#: The scene files' [cosim] keys back at their defaults (the scene files may set them).
DEFAULTS = {"cosim.step": 1e-3, "cosim.algorithm": "jacobi", "cosim.order": ["plant", "controller"]}


@pytest.fixture(autouse=True)
def _session_fmus(project_fmus) -> None:
    """The builder reads the modelDescriptions (the pair is wired and checked by name)."""
    FMUS.update(plant_fmu=project_fmus["DrillstringPlant"],
                controller_fmu=project_fmus["StrainController"])


def _config(name: str = "paper_closed_loop", over: dict | None = None):
    """A shipped scene's configuration with the session FMUs (the controller's only when the
    scene's controller is on)."""
    over = {**DEFAULTS, **key_paths(over)}
    on = load_config(name, over).controller.enabled
    return load_config(name, over, plant_fmu=FMUS["plant_fmu"],
                       controller_fmu=FMUS["controller_fmu"] if on else None)


def _system(name: str = "paper_closed_loop", over: dict | None = None):
    return build_system(_config(name, over), "fmu")


def test_closed_loop_connections_delays_and_parameters() -> None:
    ss = _system(over={"cosim": {"actuator_delay": 0.003, "sensor_delay": 0.001,
                                 "coupling": "linear", "controller_sample_period": 0.002,
                                 "algorithm": "gauss_seidel", "order": ["controller", "plant"]}})
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
    s = load_config("paper_open_loop", {"cosim.step": 2e-4}).cosim
    assert s.output_interval == pytest.approx(1e-3) and s.controller_ticks == 1
    assert (s.output_ticks, s.stop_ticks) == (5, 150000)
    assert (s.actuator_delay, s.sensor_delay, s.coupling, s.algorithm) == (0.0, 0.0, "zoh",
                                                                         "jacobi")


def test_times_are_ticks_and_come_back_exactly() -> None:
    """120000 steps of 0.25 ms are 30.0 s, as the master counts them (one exact product)."""
    s = load_config("paper_closed_loop").cosim
    assert (s.step, s.stop_ticks, s.stop_time) == (2.5e-4, 120000, 30.0)
    with pytest.raises(ConfigError, match=r"stop_time = 1.0001 s: must be a positive integer "
                                          r"multiple of the step 0.00025 s"):
        load_config("paper_closed_loop", {"cosim.stop_time": 1.0001})


def test_disabled_controller_runs_the_plant_alone() -> None:
    ss = _system("paper_open_loop")
    assert ss.config.instances == ("plant",)
    assert [f.name for f in ss.system.fmus] == ["plant"]
    assert ss.system.connections == ()
    assert not any(o.startswith("controller.") for o in ss.outputs)


def test_plant_overrides_become_the_plant_fmus_parameters_and_nothing_else() -> None:
    """Only plant keys reach the plant FMU: a controller's or the co-simulation's key never
    does (the top-drive controller's p_gain once did: 'plant has no variable ...')."""
    ss = _system(over={"top_drive.rotary_speed": 10.0, "gravity": 0.0,
                       "controller.gain": 2e8, "cosim.actuator_delay": 1e-3})
    assert ss.system.fmu("plant").parameters == {
        "scene": "paper_closed_loop", "top_drive.rotary_speed": 10.0, "gravity": 0.0}
    assert ss.system.fmu("controller").parameters["gain"] == 2e8
    assert ss.config.scene.plant.top_drive.rotary_speed == 10.0
    with pytest.raises(ConfigError, match=r"stabilizers.heights .*scene file"):
        _system(over={"stabilizers.heights": [0.0, 30.0]})


def test_top_drive_controller_keys_go_to_the_top_drive_controller() -> None:
    config = load_config("stick_slip_soft_torque", {"top_drive_controller.p_gain": 150.0})
    assert config.top_drive.params.p_gain == 150.0 and config.top_drive.enabled
    ss = build_system(config, "inprocess")
    assert [f.name for f in ss.system.fmus] == ["plant", "top_drive_controller"]
    assert ss.slaves["top_drive_controller"].law.params.p_gain == 150.0


def test_spans_long_and_short() -> None:
    info = span_info(load_scene("paper_open_loop"))
    assert info[11]["span"] == "long" and info[26]["span"] == "short"
    assert info[11]["span_length"] == pytest.approx(53.33)


@pytest.mark.parametrize(("over", "pattern"), [
    ({"top_drive_controler": {"p_gain": 1.0}},
     r"unknown table 'top_drive_controler' \(did you mean 'top_drive_controller'\?\)"),
    ({"gravty": 0.0}, r"'gravty': not a key path|did you mean 'gravity'"),
    ({"cosim": {"stop_time": 0.0001}}, r"^override: cosim\.stop_time = 0.0001 s: must be a positive integer"),
    ({"cosim": {"stepp": 1e-3}}, r"\[cosim\] unknown key 'stepp' \(did you mean 'step'\?\)"),
    ({"cosim": {"actuator_dealy": 0.1}}, r"did you mean 'actuator_delay'"),
    ({"cosim": {"step": 0.0}}, r"^override: cosim\.step = 0.0 must be > 0"),
    ({"cosim": {"step": "fast"}}, r"^override: cosim\.step = 'fast' must be a finite number"),
    ({"cosim": {"sensor_delay": -1e-3}}, r"^override: cosim\.sensor_delay = -0.001 must be >= 0"),
    ({"cosim": {"controller_sample_period": 3.75e-4}},
     r"controller_sample_period = 0.000375 s: must be a positive integer multiple of the step "
     r"0.00025 s"),
    ({"cosim": {"output_interval": 3.75e-4}}, r"output_interval = 0.000375 s"),
    ({"cosim": {"algorithm": "jacobbi"}}, r"did you mean 'jacobi'"),
    ({"cosim": {"coupling": "cubic"}}, r"^override: cosim\.coupling = 'cubic' is not allowed"),
    ({"cosim": {"order": ["plant"]}}, r"order .* permutation"),
    ({"controller": {"gian": 1e9}}, r"\[controller\] unknown key 'gian' \(did you mean 'gain'"),
    ({"controller": {"gain": -1.0}}, r"^override: controller\.gain = -1.0 is out of range"),
    ({"controller": {"mode": "pull"}}, r"^override: controller\.mode = 'pull'"),
])
def test_bad_keys_and_values_are_one_line_errors(over, pattern) -> None:
    with pytest.raises(ConfigError, match=pattern) as info:
        load_config("paper_closed_loop", over)
    msg = str(info.value)
    assert isinstance(info.value, ValueError)
    # a bad key path or a bad value of an override names the override, not the scene file
    assert "\n" not in msg and "paper_closed_loop.toml" not in msg, msg
    assert msg.startswith(("override", "unknown table")) or "override '" in msg, msg


def test_bad_keys_in_a_scene_file_name_the_file(tmp_path) -> None:
    path = tmp_path / "typo.toml"
    path.write_text('extends = "paper_closed_loop"\n\n[cosim]\nstepp = 1e-3\n')
    with pytest.raises(ConfigError, match=r"typo.toml: \[cosim\] unknown key 'stepp' \(did you "
                                          r"mean 'step'\?\)"):
        load_config(path)


def test_schema_markdown_lists_every_key_with_units() -> None:
    doc = cosim_schema_markdown()
    for key, (_default, unit, _text) in COSIM_KEYS.items():
        assert any(line.startswith(f"| {key} |") and f"| {unit} |" in line
                   for line in doc.splitlines()), key
    assert "| gain | 1e+09 | N |" in doc and "## [cosim]" in doc


def test_parse_set_values_are_toml_by_key_path() -> None:
    assert parse_set(["cosim.actuator_delay=2e-3", "controller.enabled=true",
                      "controller.mode=compressive_only", 'top_drive_controller.p_gain=150',
                      "gravity=0", "stabilizers.heights=[0.0, 30.0]"]) == {
        "cosim.actuator_delay": 0.002, "controller.enabled": True,
        "controller.mode": "compressive_only", "top_drive_controller.p_gain": 150,
        "gravity": 0, "stabilizers.heights": [0.0, 30.0]}
    for bad in ("cosim.step", "=1"):
        with pytest.raises(ConfigError, match="expected KEY=VALUE"):
            parse_set([bad])
    with pytest.raises(ConfigError, match="not a key path"):
        parse_set(["cosim..step=1"])
    with pytest.raises(ConfigError, match=r"\[controller\] unknown key 'mode2' \(did you mean "
                                          "'mode'"):
        parse_set(['controller.mode2="x"'])
    assert math.isinf(parse_set(["controller.symmetric_force_limit=inf"])[
        "controller.symmetric_force_limit"])


def test_one_override_mechanism_nested_and_flat_agree() -> None:
    flat = load_config("paper_closed_loop", {"controller.gain": 2e8, "cosim.step": 5e-4,
                                             "bit.weight_on_bit": 1e4})
    nested = load_config("paper_closed_loop", {"controller": {"gain": 2e8},
                                               "cosim": {"step": 5e-4},
                                               "bit": {"weight_on_bit": 1e4}})
    assert flat == nested
    assert (flat.controller.params.gain, flat.cosim.step, flat.scene.plant.bit.weight_on_bit) == (
        2e8, 5e-4, 1e4)
