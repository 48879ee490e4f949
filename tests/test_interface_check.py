"""Any FMU by path: the plant/controller pair is wired by name and checked before the first step.

Mismatched controllers are made from StrainControllerC.fmu by editing its modelDescription
(the check reads nothing else): a wrong unit, a wrong causality, a wrong type, a missing input,
a name declared twice; each is refused with one line naming both FMUs and the variable, all
problems at once, exit code 2 from the CLI. A controller serving fewer sites than the plant
has runs, the unserved plant inputs keep their start value, and a warning names them.
"""

from __future__ import annotations

import re
import shutil
import zipfile
from collections.abc import Callable
from pathlib import Path
from xml.etree import ElementTree as ET

import numpy as np
import pytest

from drillcosim.cosim.cli import main
from drillcosim.cosim.master.interface import (
    InterfaceError,
    check_system,
    pair_by_name,
    read_interface,
)
from drillcosim.cosim.master.master import Master
from drillcosim.cosim.master.system import FmuSpec
from drillcosim.cosim.scenario.build import build_system
from drillcosim.cosim.scenario.config import ConfigError, load_config
from drillcosim.cosim.scenario.interface import InterfaceWarning


def _build(scene, overrides=None, **fmus):
    """The scene's system through the one builder (FMU files: ``plant_fmu``,
    ``controller_fmu``)."""
    return build_system(load_config(scene, overrides, **fmus), "fmu")

PLANT_LABEL = "plant (DrillstringPlant.fmu)"


def variant(src: Path, out: Path, edit: Callable[[ET.Element], None]) -> Path:
    """A copy of FMU ``src`` at ``out`` whose modelDescription ``edit`` changed."""
    with zipfile.ZipFile(src) as zin, zipfile.ZipFile(out, "w", zipfile.ZIP_DEFLATED) as zout:
        for info in zin.infolist():
            data = zin.read(info.filename)
            if info.filename == "modelDescription.xml":
                root = ET.fromstring(data)
                edit(root)
                data = ET.tostring(root, encoding="UTF-8", xml_declaration=True)
            zout.writestr(info, data)
    return out


def _var(root: ET.Element, name: str) -> ET.Element:
    return next(sv for sv in root.iter("ScalarVariable") if sv.get("name") == name)


def _drop(root: ET.Element, names: set[str]) -> None:
    """Remove variables; the ModelStructure is rewritten for the new indices (still valid)."""
    mv = root.find("ModelVariables")
    for sv in [sv for sv in mv if sv.get("name") in names]:
        mv.remove(sv)
    structure = root.find("ModelStructure")
    structure.clear()
    outputs = ET.SubElement(structure, "Outputs")
    for i, sv in enumerate(mv, start=1):
        if sv.get("causality") == "output":
            ET.SubElement(outputs, "Unknown", index=str(i), dependencies="")


def _mismatched(root: ET.Element) -> None:
    _var(root, "actuator1_force_C").find("Real").set("unit", "kN")            # unit
    _var(root, "actuator1_force_E").set("causality", "local")                 # causality
    strain = _var(root, "strain2_E")                                          # type
    strain.remove(strain.find("Real"))
    ET.SubElement(strain, "Integer", start="0")
    _var(root, "actuator2_force_C").set("name", "actuator2_force_X")          # missing input
    mv = root.find("ModelVariables")                                          # duplicate
    dup = ET.fromstring(ET.tostring(_var(root, "strain1_C")))
    dup.set("valueReference", "99")
    mv.append(dup)


@pytest.fixture
def closed_loop():
    return "paper_closed_loop"


def test_the_default_pair_fits_and_is_wired_by_name(project_fmus, closed_loop) -> None:
    ss = _build(closed_loop, plant_fmu=project_fmus["DrillstringPlant"],
                      controller_fmu=project_fmus["StrainController"])
    pairs = {(c.source, c.target) for c in ss.system.connections}
    assert pairs == {(f"plant.strain{s}_{a}", f"controller.strain{s}_{a}") for s in (1, 2)
                     for a in "CE"} | {(f"controller.actuator{s}_force_{a}",
                                        f"plant.actuator{s}_force_{a}") for s in (1, 2)
                                       for a in "CE"}


def test_a_mismatched_controller_is_refused_with_every_reason(project_fmus, c_controller_fmu,
                                                              closed_loop, tmp_path) -> None:
    bad = variant(c_controller_fmu, tmp_path / "Bad.fmu", _mismatched)
    with pytest.raises(InterfaceError) as info:
        _build(closed_loop, plant_fmu=project_fmus["DrillstringPlant"],
                     controller_fmu=bad)
    lines = str(info.value).splitlines()
    assert lines[0].startswith(f"{PLANT_LABEL} and controller (Bad.fmu) do not fit: 5 problems")
    problems = [ln.strip() for ln in lines[1:]]
    expected = {
        "units differ ('kN' -> 'N')": "'actuator1_force_C'",
        "the source is declared 'local' in controller (Bad.fmu), must be 'output'":
            "'actuator1_force_E'",
        "types differ (Real -> Integer)": "'strain2_E'",
        "input 'actuator2_force_C' is not fed: controller (Bad.fmu) has no variable":
            "actuator2_force_C",
        "declares variable 'strain1_C' more than once": "strain1_C",
    }
    assert len(problems) == len(expected)
    for fragment, variable in expected.items():
        hits = [p for p in problems if fragment in p]
        assert len(hits) == 1, (fragment, problems)
        assert variable in hits[0]
        if "more than once" not in fragment:  # a declaration problem concerns one FMU only
            assert PLANT_LABEL in hits[0] and "controller (Bad.fmu)" in hits[0]


def test_the_cli_lists_all_problems_and_exits_2(project_fmus, c_controller_fmu, tmp_path,
                                                capsys) -> None:
    bad = variant(c_controller_fmu, tmp_path / "Bad.fmu", _mismatched)
    code = main(["run", "paper_closed_loop", "--plant-fmu", str(project_fmus["DrillstringPlant"]),
                 "--controller-fmu", str(bad), "--out", str(tmp_path / "out"), "--no-progress"])
    err = capsys.readouterr().err
    assert code == 2 and "Traceback" not in err
    lines = err.strip().splitlines()
    assert lines[0].startswith("drillcosim run: error: ") and "5 problems" in lines[0]
    assert len(lines) == 6
    assert not (tmp_path / "out").exists()  # refused before anything was written


def test_a_target_connected_twice_is_refused(project_fmus, c_controller_fmu) -> None:
    plant = read_interface("plant", project_fmus["DrillstringPlant"])
    ctrl = read_interface("controller", c_controller_fmu)
    pairs = pair_by_name(plant, ctrl) + [("plant.strain1_E", "controller.strain1_C")]
    report = check_system([FmuSpec("plant", plant.path), FmuSpec("controller", ctrl.path)],
                          pairs, {"plant": plant, "controller": ctrl})
    assert report.problems == [
        "controller (StrainControllerC.fmu) input 'strain1_C' is connected 2 times (from "
        "plant.strain1_C, plant.strain1_E)"]


def test_a_law_key_a_foreign_controller_lacks_is_not_required_an_override_of_it_is(
        project_fmus, c_controller_fmu, tmp_path) -> None:
    """The scene file's law keys a foreign FMU does not declare are not required of
    it (a warning names them); an override of one would change nothing: a problem."""
    no_lag = variant(c_controller_fmu, tmp_path / "NoLag.fmu",
                     lambda r: _drop(r, {"lag_time_constant", "enabled", "mode"}))
    plant = project_fmus["DrillstringPlant"]
    with pytest.warns(InterfaceWarning, match=r"controller \(NoLag.fmu\) has no parameter "
                                              r"'mode': \[controller\] mode of "
                                              r".*paper_closed_loop.toml not applied"):
        ss = _build("paper_closed_loop", plant_fmu=plant, controller_fmu=no_lag)
    params = ss.system.fmu("controller").parameters
    assert "lag_time_constant" not in params and "mode" not in params
    assert params["gain"] == 1e9  # what it has, it gets
    with pytest.raises(InterfaceError, match=r"override controller.lag_time_constant = 0.01: "
                                             r"controller \(NoLag.fmu\) has no parameter "
                                             r"'lag_time_constant'"):
        _build("paper_closed_loop", {"controller.lag_time_constant": 0.01}, plant_fmu=plant,
               controller_fmu=no_lag)


def test_a_controller_serving_fewer_sites_warns_and_runs(project_fmus, c_controller_fmu,
                                                         tmp_path) -> None:
    one_site = variant(c_controller_fmu, tmp_path / "OneSite.fmu", lambda r: _drop(
        r, {"strain2_C", "strain2_E", "actuator2_force_C", "actuator2_force_E"}))
    with pytest.warns(InterfaceWarning, match=r"keep their start value: "
                                              r"plant.actuator2_force_C, plant.actuator2_force_E$"):
        ss = _build("paper_closed_loop", plant_fmu=project_fmus["DrillstringPlant"],
                    controller_fmu=one_site)
    assert len(ss.system.connections) == 4
    data = Master(ss.system).simulate(0.2, ss.outputs).data
    assert np.max(np.abs(data["controller.actuator1_force_C"])) > 0  # site 1 is controlled
    assert np.all(data["plant.actuator2_power"] == 0.0)  # site 2 keeps 0 N: no actuation


def test_the_cli_prints_the_warning_in_one_line(project_fmus, c_controller_fmu, tmp_path,
                                                capsys) -> None:
    one_site = variant(c_controller_fmu, tmp_path / "OneSite.fmu", lambda r: _drop(
        r, {"strain2_C", "strain2_E", "actuator2_force_C", "actuator2_force_E"}))
    code = main(["run", "paper_closed_loop", "--stop-time", "0.01", "--controller-fmu",
                 str(one_site), "--plant-fmu", str(project_fmus["DrillstringPlant"]),
                 "--out", str(tmp_path / "out"), "--no-progress", "--no-plots"])
    err = capsys.readouterr().err
    assert code == 0
    warning = [ln for ln in err.splitlines() if "warning" in ln]
    assert warning == [f"drillcosim run: warning: {PLANT_LABEL} and controller (OneSite.fmu): "
                       "inputs of sites the other FMU does not serve keep their start value: "
                       "plant.actuator2_force_C, plant.actuator2_force_E"]


def test_a_partly_served_site_is_a_problem(project_fmus, c_controller_fmu, tmp_path) -> None:
    half = variant(c_controller_fmu, tmp_path / "Half.fmu",
                   lambda r: _drop(r, {"actuator2_force_E"}))
    with pytest.raises(InterfaceError, match=r"plant \(DrillstringPlant.fmu\) input "
                                             r"'actuator2_force_E' is not fed: controller "
                                             r"\(Half.fmu\) has no variable"):
        _build("paper_closed_loop", plant_fmu=project_fmus["DrillstringPlant"],
               controller_fmu=half)


def test_scene_tables_choose_the_fmus_relative_to_the_scene_file(project_fmus, c_controller_fmu,
                                                                 tmp_path) -> None:
    shutil.copy(c_controller_fmu, tmp_path / "ctrl.fmu")
    scene = tmp_path / "my_loop.toml"
    base = 'extends = "paper_closed_loop"\n'
    scene.write_text(f'{base}\n[plant]\nfmu = "{project_fmus["DrillstringPlant"]}"\n\n'
                     '[controller]\nfmu = "ctrl.fmu"\n')
    ss = _build(scene)
    assert Path(ss.system.fmu("controller").path) == (tmp_path / "ctrl.fmu").resolve()
    assert Path(ss.system.fmu("plant").path) == project_fmus["DrillstringPlant"]
    # the command line takes precedence over the scene
    ss = _build(scene, controller_fmu=project_fmus["StrainController"])
    assert Path(ss.system.fmu("controller").path) == project_fmus["StrainController"]
    scene.write_text(f'{base}[controller]\nfmu = "missing.fmu"\n')
    with pytest.raises(ConfigError, match=r"\[controller\] fmu = 'missing.fmu': no file"):
        _build(scene)
    scene.write_text(f'{base}[plant]\nfmuu = "x.fmu"\n')
    with pytest.raises(ConfigError, match=r"\[plant\] unknown key 'fmuu'; allowed: fmu"):
        _build(scene)


def test_a_plant_without_a_scene_parameter_is_warned_about(project_fmus, tmp_path,
                                                           closed_loop) -> None:
    plant = variant(project_fmus["DrillstringPlant"], tmp_path / "OtherPlant.fmu",
                    lambda r: _var(r, "scene").set("name", "config"))
    with pytest.warns(InterfaceWarning, match=r"plant \(OtherPlant.fmu\) has no 'scene' "
                                              r"parameter: the plant tables of .* not applied"):
        ss = _build(closed_loop, plant_fmu=plant,
                          controller_fmu=project_fmus["StrainController"])
    assert ss.system.fmu("plant").parameters == {}


@pytest.mark.parametrize("name, value, words", [
    ("kx", 3, "has no variable 'kx' to set"),
    ("mode", 0.5, "'mode' is Integer; got float 0.5"),
    ("mode", 3, "'mode' = 3 is outside its declared range [0, 1]"),
])
def test_a_foreign_fmus_own_parameters_are_checked_from_every_door(
        project_fmus, tmp_path, capsys, name, value, words) -> None:
    """A foreign controller FMU's own parameter, from the API's ``overrides``, from ``--set``
    and from a scene's ``[controller.parameters]``: checked against its modelDescription before
    the first step (the project's strain controller given as a file is a foreign FMU; it
    declares ``mode`` Integer in [0, 1]); the CLI exits 2 with no traceback."""
    import drillcosim
    from drillcosim.cosim.master.errors import UserError

    plant, c_controller_fmu = project_fmus["DrillstringPlant"], project_fmus["StrainController"]
    key = f"controller.parameters.{name}"
    with pytest.raises(UserError, match=re.escape(words)):
        drillcosim.simulate("paper_closed_loop", stop_time=0.01, overrides={key: value},
                            plant_fmu=plant, controller_fmu=c_controller_fmu)
    scene = tmp_path / "mine.toml"
    shutil.copy(c_controller_fmu, tmp_path / "C.fmu")
    scene.write_text(f'extends = "paper_closed_loop"\n[controller]\nenabled = true\n'
                     f'fmu = "C.fmu"\n[controller.parameters]\n{name} = {value}\n')
    for argv in (["run", "paper_closed_loop", "--controller-fmu", str(c_controller_fmu),
                  "--set", f"{key}={value}"], ["run", str(scene)]):
        assert main([*argv, "--stop-time", "0.01", "--no-plots", "--out",
                     str(tmp_path / "out")]) == 2
        err = capsys.readouterr().err
        assert words in err and "Traceback" not in err
    assert not (tmp_path / "out" / "results.csv").exists()
