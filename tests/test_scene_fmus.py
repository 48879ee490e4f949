"""FMUs built for a scene's layout (``drillcosim build --scene``): plant and strain controller.

References: the plant simulator driven with the same inputs by name (the variant routes every
input and output to the right entry of the model), the default FMUs (unchanged names and
behaviour), a MIMO law written here with numpy, and the in-process engine of the master (the
same models without the FMI boundary, bit for bit).
"""

from __future__ import annotations

import json
import zipfile
from pathlib import Path
from xml.etree import ElementTree as ET

import numpy as np
import pytest
from fmpy import extract, read_model_description
from fmpy.fmi2 import FMU2Slave
from fmpy.validation import validate_fmu

from drillcosim.controller import ControllerParams, StrainController, check_gain_matrix
from drillcosim.cosim.cli import main
from drillcosim.cosim.scenario.build import scene_recipes
from drillcosim.cosim.scenario.config import load_config
from drillcosim.cosim.scenario.scene_fmus import (
    built_for_scene,
    controller_recipe,
    plant_layout,
    plant_recipe,
)
from drillcosim.cosim.study.point import measure_point
from drillcosim.fmu_src.build import build_one
from drillcosim.plant.model import DrillstringModel
from drillcosim.plant.scene import list_scenes, load_scene
from drillcosim.plant.simulator import PlantSimulator

pytestmark = [pytest.mark.needs_cc]

DT = 1e-3
MATRIX = [[1.0, 0.5, 0.0, 0.0], [0.5, 1.0, 0.0, 0.0],
          [0.0, 0.0, 1.0, -0.25], [0.0, 0.0, -0.25, 1.0]]


def _mimo_scene(folder: Path) -> Path:
    path = folder / "four_sites_mimo.toml"
    rows = ", ".join("[" + ", ".join(repr(x) for x in row) + "]" for row in MATRIX)
    path.write_text(f'extends = "four_sites"\n\n[controller]\ngain_matrix = [{rows}]\n')
    return path


@pytest.fixture(scope="session")
def scene_dir(tmp_path_factory) -> Path:
    folder = tmp_path_factory.mktemp("scene_files")
    _mimo_scene(folder)
    (folder / "stick_slip_speed.toml").write_text(
        'extends = "stick_slip"\n\n[top_drive]\nmode = "speed"\n')
    return folder


@pytest.fixture(scope="session")
def four_sites_fmus(tmp_path_factory, scene_dir) -> Path:
    """A folder with the default FMUs and those built for four_sites and four_sites_mimo."""
    out = tmp_path_factory.mktemp("scene_fmus")
    recipes = {}
    for scene in ("four_sites", scene_dir / "four_sites_mimo.toml"):
        recipes.update({r.name: r for r in scene_recipes(load_config(scene)).values()})
    recipes.update({r.name: r for r in scene_recipes(load_config("paper_closed_loop")).values()})
    for recipe in recipes.values():
        path = build_one(recipe, out)
        assert validate_fmu(str(path)) == [], path
    return out


def _variables(fmu: Path) -> dict:
    return {v.name: v for v in read_model_description(str(fmu)).modelVariables}


# ------------------------------------------------------------------ which FMUs a scene needs
def test_the_paper_scenes_keep_the_default_fmus() -> None:
    for name in ("paper_open_loop", "paper_closed_loop", "paper_severe"):
        config = load_config(name)
        assert plant_layout(config.scene) is None
        assert [r.name for r in scene_recipes(config).values()][:1] == ["DrillstringPlant"]
        assert not any(built_for_scene(r) for r in scene_recipes(config).values())


def test_other_layouts_get_variants_named_after_the_scene(scene_dir) -> None:
    names = {i: r.name for i, r in scene_recipes(load_config("four_sites")).items()}
    assert names == {"plant": "DrillstringPlant_four_sites",
                     "controller": "StrainController_four_sites"}
    soft = scene_recipes(load_config("stick_slip_soft_torque"))
    assert {i: r.name for i, r in soft.items()} == {
        "plant": "DrillstringPlant_stick_slip_soft_torque",
        "top_drive_controller": "TopDriveController"}
    for scene in ("stick_slip", "bit_bounce", "backward_whirl", "forward_whirl"):
        assert plant_recipe(load_scene(scene)).name == f"DrillstringPlant_{scene}"
    # one module name per layout: two variants and the default live in one process
    mods = {plant_recipe(load_scene(s)).slave_module for s in
            ("four_sites", "stick_slip", "paper_open_loop", scene_dir / "four_sites_mimo.toml")}
    assert len(mods) == 4
    # a two-site controller with a matrix is a variant too
    mimo = load_config("paper_closed_loop", {"controller.gain_matrix": [[1.0, 0.1], [0.1, 1.0]]})
    recipe = controller_recipe(mimo.controller, mimo.scene, 2)
    assert recipe.name == "StrainController_paper_closed_loop" and built_for_scene(recipe)
    siso = load_config("paper_closed_loop")
    assert not built_for_scene(controller_recipe(siso.controller, siso.scene, 2))


def test_speed_command_input_when_the_scene_asks(scene_dir) -> None:
    layout = plant_layout(load_scene(scene_dir / "stick_slip_speed.toml"))
    assert [r[:2] for r in layout.inputs] == [("top_drive_speed_command", "rad/s")]
    torque = plant_layout(load_scene("stick_slip_soft_torque"))
    assert [r[:2] for r in torque.inputs] == [("top_drive_torque", "N m")]
    # the axial-torsional chain has no bending: no actuator inputs, no strains
    assert plant_layout(load_scene("stick_slip")).inputs == ()


# ------------------------------------------------------------------ the built FMUs
def test_four_sites_plant_fmu_declares_the_scene_layout(four_sites_fmus) -> None:
    fmu = four_sites_fmus / "DrillstringPlant_four_sites.fmu"
    md = read_model_description(str(fmu))
    default = read_model_description(str(four_sites_fmus / "DrillstringPlant.fmu"))
    assert md.coSimulation.modelIdentifier == "DrillstringPlant_four_sites"
    assert md.guid != default.guid
    var = {v.name: v for v in md.modelVariables}
    inputs = [v.name for v in md.modelVariables if v.causality == "input"]
    assert inputs == [f"actuator{s}_force_{a}" for s in range(1, 5) for a in "CE"]
    assert all(var[n].declaredType is None and var[n].unit == "N" for n in inputs)
    for s in range(1, 5):
        assert var[f"strain{s}_C"].unit == "1" and var[f"actuator{s}_power"].unit == "W"
    for b in (11, 26):
        assert var[f"body{b}_radial_deflection"].unit == "m"
        assert var[f"body{b}_contact_force"].unit == "N"
    outs = [v.name for v in md.modelVariables if v.causality == "output"]
    assert [u.variable.name for u in md.outputs] == outs  # ModelStructure lists every output
    assert all(u.dependencies == [] for u in md.outputs)  # no direct feedthrough
    assert var["scene"].start == "four_sites"
    assert all(var[n].description for n in inputs + outs)
    # the default build keeps its interface
    dvar = [v.name for v in default.modelVariables if v.causality == "input"]
    assert dvar == [f"actuator{s}_force_{a}" for s in (1, 2) for a in "CE"]
    assert default.coSimulation.modelIdentifier == "DrillstringPlant"


def test_variant_routes_inputs_and_outputs_by_name(four_sites_fmus, tmp_path) -> None:
    """Force at site 3 only: the FMU equals the plant simulator with that input set by name,
    and site 3's strain answers (a shifted input vector would move another site)."""
    fmu = four_sites_fmus / "DrillstringPlant_four_sites.fmu"
    md = read_model_description(str(fmu))
    vr = {v.name: v.valueReference for v in md.modelVariables}
    outs = [v.name for v in md.modelVariables if v.causality == "output"]
    inst = FMU2Slave(guid=md.guid, unzipDirectory=extract(str(fmu), str(tmp_path / "x")),
                     modelIdentifier=md.coSimulation.modelIdentifier, instanceName="plant")
    inst.instantiate()
    inst.setupExperiment(startTime=0.0)
    inst.enterInitializationMode()
    inst.exitInitializationMode()
    sc = load_scene("four_sites")
    sim = PlantSimulator(DrillstringModel(sc.plant, "full3d"))
    u = np.zeros(sim.model.n_inputs)
    u[sim.model.input_names.index("actuator3_force_C")] = 2000.0
    idx = [sim.model.output_names.index(n) for n in outs]
    n = 60
    got, ref = [], []
    for k in range(n):
        inst.setReal([vr["actuator3_force_C"]], [2000.0])
        inst.doStep(k * DT, DT)
        got.append(inst.getReal([vr[o] for o in outs]))
        sim.set_inputs(u)
        assert sim.do_step(k * DT, DT).ok
        ref.append(sim.outputs()[idx])
    inst.terminate()
    inst.freeInstance()
    np.testing.assert_array_equal(np.array(got), np.array(ref))
    free = PlantSimulator(DrillstringModel(sc.plant, "full3d"))
    for k in range(n):
        assert free.do_step(k * DT, DT).ok
    moved = {o: abs(ref[-1][j] - free.outputs()[idx[j]]) for j, o in enumerate(outs)}
    assert moved["actuator3_power"] > 0 and moved["actuator1_power"] == 0.0
    assert moved["strain3_C"] > 10 * moved["strain1_C"]


def test_two_layouts_live_in_one_process_and_one_folder(four_sites_fmus, tmp_path) -> None:
    insts = []
    for k, name in enumerate(("DrillstringPlant", "DrillstringPlant_four_sites",
                              "StrainController", "StrainController_four_sites")):
        fmu = four_sites_fmus / f"{name}.fmu"
        md = read_model_description(str(fmu))
        inst = FMU2Slave(guid=md.guid, unzipDirectory=extract(str(fmu), str(tmp_path / str(k))),
                         modelIdentifier=md.coSimulation.modelIdentifier, instanceName=name)
        inst.instantiate()
        inst.setupExperiment(startTime=0.0)
        inst.enterInitializationMode()
        inst.exitInitializationMode()
        insts.append((inst, {v.name: v.valueReference for v in md.modelVariables}))
    for inst, _vr in insts:
        inst.doStep(0.0, DT)
    ctrl, vr = insts[3]
    assert ctrl.getReal([vr["actuator4_force_E"]]) == [0.0]
    assert "actuator4_force_E" not in insts[2][1] and "strain4_C" not in insts[0][1]
    for inst, _vr in insts:
        inst.terminate()
        inst.freeInstance()


def test_controller_variant_has_the_sites_and_the_gain_matrix(four_sites_fmus) -> None:
    var = _variables(four_sites_fmus / "StrainController_four_sites_mimo.fmu")
    assert [n for n, v in var.items() if v.causality == "input"] == [
        f"strain{s}_{a}" for s in range(1, 5) for a in "CE"]
    assert [n for n, v in var.items() if v.causality == "output"] == [
        f"actuator{s}_force_{a}" for s in range(1, 5) for a in "CE"]
    starts = [[float(var[f"gain_matrix_{i}_{j}"].start) for j in range(1, 5)]
              for i in range(1, 5)]
    assert starts == MATRIX
    assert var["gain_matrix_1_2"].variability == "tunable" and var["gain_matrix_1_2"].unit == "1"
    ident = _variables(four_sites_fmus / "StrainController_four_sites.fmu")
    assert [float(ident[f"gain_matrix_{i}_{i}"].start) for i in range(1, 5)] == [1.0] * 4
    assert "gain_matrix_1_1" not in _variables(four_sites_fmus / "StrainController.fmu")


# ------------------------------------------------------------------ the MIMO law
def test_mimo_law_is_the_gain_matrix_per_axis() -> None:
    rng = np.random.default_rng(3)
    eps = rng.normal(size=8) * 1e-5
    law = StrainController(ControllerParams(gain=1e8, gain_matrix=MATRIX), n_sites=4)
    out = law.command(0.0, eps)
    m = np.array(MATRIX)
    ref = np.empty(8)
    ref[0::2] = 1e8 * m @ eps[0::2]   # axis C of sites 1..4
    ref[1::2] = 1e8 * m @ eps[1::2]   # axis E
    np.testing.assert_allclose(out, ref, rtol=1e-14, atol=0)
    siso = StrainController(ControllerParams(gain=1e8), n_sites=4)
    ident = StrainController(ControllerParams(gain=1e8, gain_matrix=np.eye(4).tolist()), 4)
    np.testing.assert_array_equal(siso.command(0.0, eps), ident.command(0.0, eps))
    assert not np.allclose(out, siso.command(0.0, eps))
    sat = StrainController(ControllerParams(gain=1e8, gain_matrix=MATRIX, force_limit=100.0,
                                            mode="compressive_only"), n_sites=4)
    np.testing.assert_array_equal(sat.command(0.0, eps), np.clip(ref, 0.0, 100.0))
    late = StrainController(ControllerParams(gain=1e8, gain_matrix=MATRIX, switch_on_time=1.0),
                            n_sites=4)
    assert np.all(late.command(0.5, eps) == 0.0)
    np.testing.assert_array_equal(late.command(1.0, eps), out)


@pytest.mark.parametrize("bad, fragment", [
    ([[1.0, 0.0]], "row 1"), ("eye", "square matrix"), ([[1.0, float("nan")], [0.0, 1.0]],
                                                        "gain_matrix[1][2]")])
def test_bad_gain_matrix_is_refused_in_one_line(bad, fragment) -> None:
    with pytest.raises(ValueError, match=r"gain_matrix") as exc:
        check_gain_matrix(bad)
    assert fragment in str(exc.value) and "\n" not in str(exc.value)
    with pytest.raises(ValueError, match="serves 4 sites"):
        StrainController(ControllerParams(gain_matrix=[[1.0, 0.2], [0.2, 1.0]]), n_sites=4)


# ------------------------------------------------------------------ closed loops through the master
@pytest.mark.parametrize("scene", ["four_sites", "four_sites_mimo"])
def test_scene_fmus_equal_the_in_process_models(four_sites_fmus, scene_dir, scene) -> None:
    path = "four_sites" if scene == "four_sites" else str(scene_dir / f"{scene}.toml")
    rows = [measure_point(path, 1e8, 0.0, 2.5e-4, 0.05, engine, fmu_dir=str(four_sites_fmus),
                          rms_fraction=1.0) for engine in ("fmu", "inprocess")]
    for key in ("rms_long", "rms_short", "peak_force", "peak_power", "end_time"):
        assert rows[0][key] == rows[1][key], key
    assert rows[0]["status"] == "ok" and rows[0]["peak_force"] > 0.0


def test_mimo_closed_loop_differs_from_siso(four_sites_fmus, scene_dir) -> None:
    kw = dict(fmu_dir=str(four_sites_fmus), rms_fraction=1.0)
    siso = measure_point("four_sites", 1e8, 0.0, 2.5e-4, 0.05, "fmu", **kw)
    mimo = measure_point(str(scene_dir / "four_sites_mimo.toml"), 1e8, 0.0, 2.5e-4, 0.05,
                         "fmu", **kw)
    assert mimo["peak_force"] != siso["peak_force"]


# ------------------------------------------------------------------ the CLI
def test_cli_build_scene_then_run(tmp_path, capsys) -> None:
    out = tmp_path / "fmus"
    assert main(["build", "--scene", "four_sites", "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert "DrillstringPlant_four_sites.fmu (plant: built for the scene)" in text
    assert sorted(p.name for p in out.glob("*.fmu")) == [
        "DrillstringPlant_four_sites.fmu", "StrainController_four_sites.fmu"]
    with zipfile.ZipFile(out / "DrillstringPlant_four_sites.fmu") as zf:
        root = ET.fromstring(zf.read("modelDescription.xml"))
    assert root.get("modelName") == "DrillstringPlant_four_sites"
    res = tmp_path / "run"
    assert main(["run", "four_sites", "--fmu-dir", str(out), "--stop-time", "0.02",
                 "--out", str(res), "--no-plots", "--no-progress"]) == 0
    header = (res / "results.csv").read_text().splitlines()[0].split(",")
    assert "controller.actuator4_force_E" in header and "plant.strain4_E" in header
    summary = json.loads((res / "summary.json").read_text())
    assert summary["end_time_s"] == pytest.approx(0.02)


def test_cli_build_scene_refuses_an_unknown_scene(capsys) -> None:
    assert main(["build", "--scene", "four_site"]) == 2
    err = capsys.readouterr().err
    assert "four_site" in err and "four_sites" in err and len(err.strip().splitlines()) == 1


@pytest.mark.slow
@pytest.mark.parametrize("scene", list_scenes())
def test_every_shipped_scene_runs_through_the_cli(scene, tmp_path, capsys) -> None:
    """``drillcosim run SCENE`` builds the FMUs the scene needs into the folder and runs."""
    fmus, res = tmp_path / "fmus", tmp_path / "run"
    assert main(["run", scene, "--fmu-dir", str(fmus), "--stop-time", "0.05", "--out", str(res),
                 "--no-plots", "--no-progress"]) == 0
    built = {p.stem for p in fmus.glob("*.fmu")}
    assert {r.name for r in scene_recipes(load_config(scene)).values()} == built
    for path in fmus.glob("*.fmu"):
        assert validate_fmu(str(path)) == [], path
    assert json.loads((res / "summary.json").read_text())["end_time_s"] == pytest.approx(0.05)


def test_controller_variant_equals_the_law_and_tunes_the_matrix(four_sites_fmus, tmp_path) -> None:
    """The MIMO controller FMU against the law, with ``gain_matrix_1_3`` retuned between steps
    (tunable) and a force limit (saturation as the default controller's)."""
    fmu = four_sites_fmus / "StrainController_four_sites_mimo.fmu"
    md = read_model_description(str(fmu))
    vr = {v.name: v.valueReference for v in md.modelVariables}
    ins = [f"strain{s}_{a}" for s in range(1, 5) for a in "CE"]
    outs = [f"actuator{s}_force_{a}" for s in range(1, 5) for a in "CE"]
    inst = FMU2Slave(guid=md.guid, unzipDirectory=extract(str(fmu), str(tmp_path / "c")),
                     modelIdentifier=md.coSimulation.modelIdentifier, instanceName="controller")
    inst.instantiate()
    inst.setupExperiment(startTime=0.0)
    inst.enterInitializationMode()
    inst.setReal([vr["gain"], vr["symmetric_force_limit"]], [1e8, 800.0])
    inst.exitInitializationMode()
    matrix = [row[:] for row in MATRIX]
    law = StrainController(ControllerParams(gain=1e8, symmetric_force_limit=800.0,
                                            gain_matrix=matrix), n_sites=4)
    rng = np.random.default_rng(7)
    for k in range(40):
        if k == 20:
            inst.setReal([vr["gain_matrix_1_3"]], [0.75])
            matrix[0][2] = 0.75
            law.params = ControllerParams(gain=1e8, symmetric_force_limit=800.0,
                                          gain_matrix=matrix)
        eps = rng.normal(size=8) * 5e-6
        inst.setReal([vr[n] for n in ins], eps.tolist())
        inst.doStep(k * DT, DT)
        np.testing.assert_array_equal(inst.getReal([vr[n] for n in outs]),
                                      law.step(k * DT, DT, eps))
    assert np.abs(law.forces).max() == 800.0  # the limit was reached
    inst.terminate()
    inst.freeInstance()
