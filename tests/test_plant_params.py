"""Parameter validation, scenes and model selection: clear errors, the right model per scene."""

from __future__ import annotations

import math
from pathlib import Path

import pytest

from drillcosim.plant.model import DrillstringModel
from drillcosim.plant.params import (
    ContactParams,
    LoadParams,
    PipeParams,
    PlantParams,
    StabilizerParams,
    TopDriveParams,
)
from drillcosim.plant.scene import SceneError, list_scenes, load_scene, scene_from_dict, schema_markdown

ROOT = Path(__file__).resolve().parents[1]


@pytest.mark.parametrize(
    ("build", "words"),
    [
        (lambda: PipeParams(n_segments=1), ["pipe.n_segments", "1", "[2"]),
        (lambda: PipeParams(outer_diameter=-0.1), ["pipe.outer_diameter", "-0.1"]),
        (lambda: PipeParams(inner_diameter=0.2), ["pipe.inner_diameter", "0.2"]),
        (lambda: PipeParams(youngs_modulus=math.nan), ["pipe.youngs_modulus", "nan"]),
        (lambda: TopDriveParams(axial_stiffness=-1.0), ["top_drive.axial_stiffness", "-1"]),
        (lambda: ContactParams(stiffness=-5.0), ["contact.stiffness", "-5"]),
        (lambda: ContactParams(clearance=-0.01), ["contact.clearance", "-0.01"]),
        (lambda: PlantParams(stabilizers=StabilizerParams(heights=(90.0,))),
         ["stabilizers.heights", "90", "beyond"]),
        (lambda: PlantParams(contact=ContactParams(bodies=(31,))), ["contact.bodies", "31"]),
        (lambda: PlantParams(loads=(LoadParams(body=40),)), ["loads.body", "40"]),
        (lambda: LoadParams(direction="w"), ["loads.direction", "'w'"]),
        (lambda: PipeParams(n_segments=2.5), ["pipe.n_segments", "integer"]),
        (lambda: PipeParams(length="80"), ["pipe.length", "number"]),
    ],
)
def test_bad_parameters_raise_one_line_value_error_naming_them(build, words):
    with pytest.raises(ValueError) as info:
        build()
    msg = str(info.value)
    assert "\n" not in msg
    for w in words:
        assert w in msg, (w, msg)


def test_defaults_reproduce_the_design_numbers():
    pipe = PipeParams()
    assert pipe.area == pytest.approx(7.913e-3, rel=1e-3)
    assert pipe.second_moment == pytest.approx(6.986e-6, rel=1e-3)
    assert pipe.kappa == pytest.approx(0.665, abs=2e-3)
    m = DrillstringModel(PlantParams())
    d = m.derived
    assert d.mass == pytest.approx(165.6, rel=1e-3)
    assert d.j_polar == pytest.approx(0.2925, rel=1e-3)
    assert d.j_transverse == pytest.approx(98.31, rel=1e-3)
    assert d.k_axial == pytest.approx(6.172e8, rel=1e-3)
    assert d.k_tors == pytest.approx(4.244e5, rel=1e-3)
    assert d.k_bend == pytest.approx(5.449e5, rel=1e-3)
    # paper: contact at bodies 11 and 26, actuators below 11 and 26 (span middles)
    assert m.contact_bodies == (11, 26)
    assert m.sites == (11, 26)


def test_every_shipped_scene_loads_with_the_cheapest_model():
    names = list_scenes()
    for required in ("table1_axial_pulse", "table1_torsional_pulse", "table1_lateral_step",
                     "paper_open_loop", "paper_closed_loop", "paper_switch_on_25s",
                     "paper_restricted_actuator", "paper_severe"):
        assert required in names
    expected = {"table1_axial_pulse": "axial_torsional", "table1_torsional_pulse":
                "axial_torsional", "table1_lateral_step": "full3d", "paper_open_loop": "full3d"}
    for name, kind in expected.items():
        assert load_scene(name).model == kind


def test_scene_inheritance_and_overrides():
    from drillcosim.cosim.scenario.config import load_config

    config = load_config("paper_restricted_actuator")
    assert config.controller.params.mode == "compressive_only"
    assert config.controller.params.force_limit == 5000.0
    sc = load_scene("paper_restricted_actuator")
    assert sc == config.scene
    assert sc.plant.bit.displacement_amplitude == 0.003  # from paper_open_loop
    sc2 = load_scene("paper_open_loop", overrides={"top_drive": {"rotary_speed": 10.0}})
    assert sc2.plant.top_drive.rotary_speed == 10.0
    assert sc2.plant.top_drive.axial_stiffness == 1e9


def test_unknown_key_suggests_the_right_one(tmp_path):
    f = tmp_path / "s.toml"
    f.write_text("[top_drive]\nrotary_sped = 3.0\n")
    with pytest.raises(SceneError, match=r"s.toml.*unknown key 'rotary_sped'.*rotary_speed"):
        load_scene(f)


def test_malformed_toml_points_at_the_line(tmp_path):
    f = tmp_path / "bad.toml"
    f.write_text('description = "x"\n[pipe]\nlength = = 3\n')
    with pytest.raises(SceneError, match=r"bad.toml.*line 3"):
        load_scene(f)


def test_bad_value_in_scene_names_file_and_key(tmp_path):
    f = tmp_path / "neg.toml"
    f.write_text("[contact]\nstiffness = -1e7\n")
    with pytest.raises(SceneError, match=r"neg.toml.*contact.stiffness = -10000000.0"):
        load_scene(f)


def test_output_the_model_lacks_is_an_error():
    with pytest.raises(SceneError, match="needs the lateral DOFs"):
        scene_from_dict({"model": "axial_torsional", "outputs": ["strain1_C"],
                         "unbalance": {"enabled": False}})
    with pytest.raises(SceneError, match="unknown output 'strain9_C'"):
        scene_from_dict({"outputs": ["strain9_C"]})
    # auto picks the 3D model when a lateral output is asked for
    sc = scene_from_dict({"outputs": ["strain1_C"], "unbalance": {"enabled": False}})
    assert sc.model == "full3d"


def test_axial_torsional_refuses_what_it_cannot_represent():
    with pytest.raises(ValueError, match="unbalance"):
        DrillstringModel(PlantParams(), "axial_torsional")
    with pytest.raises(SceneError, match="controller is enabled"):
        scene_from_dict({"model": "axial_torsional", "unbalance": {"enabled": False},
                         "controller": {"enabled": True}})


def test_unknown_scene_name_suggests():
    with pytest.raises(SceneError, match="paper_open_loop"):
        load_scene("paper_open_lop")


def test_scene_schema_doc_is_current():
    from drillcosim.cosim.scenario.schema import scene_schema

    doc = (ROOT / "docs" / "scenes.md").read_text()
    assert schema_markdown() in doc
    assert doc == scene_schema(), "regenerate: drillcosim schema > docs/scenes.md"
