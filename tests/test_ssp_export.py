"""SSP export: the archive's structure and what it refuses (third-party engines running it:
tests/test_interop_libcosim.py, tests/test_interop_ecos.py; importing it: tests/test_ssp_import.py).
"""

from __future__ import annotations

import dataclasses
import zipfile
from pathlib import Path
from xml.etree import ElementTree as ET

import pytest

from drillcosim.cosim.master.ssp import NS, export_ssp, unsupported_features
from drillcosim.cosim.master.system import Connection
from drillcosim.cosim.scenario.build import build_system
from drillcosim.cosim.scenario.config import load_config


@pytest.fixture(scope="module")
def scene_sys(project_fmus):
    # Multirate (controller every 2 ms), a non-default gain and the restricted mode, so the
    # parameter bindings (Real, Integer, Boolean, String) and the step-size hint matter.
    config = load_config("paper_restricted_actuator", {
        "controller.gain": 5e8, "cosim.step": 1e-3, "cosim.controller_sample_period": 2e-3,
        "cosim.algorithm": "jacobi", "cosim.order": ["plant", "controller"]})
    return build_system(config, "fmu", fmu_dir=project_fmus["DrillstringPlant"].parent)


def test_ssd_structure(scene_sys, tmp_path: Path) -> None:
    exp = export_ssp(scene_sys.system, tmp_path / "sys.ssp")
    assert exp.omitted == ()
    with zipfile.ZipFile(exp.path) as zf:
        names = set(zf.namelist())
        root = ET.fromstring(zf.read("SystemStructure.ssd"))
    assert {"resources/DrillstringPlant.fmu", "resources/StrainController.fmu"} <= names
    ns = {k: v for k, v in NS.items()}
    comps = {c.get("name"): c for c in root.iterfind(".//ssd:Component", ns)}
    assert set(comps) == {"plant", "controller"}
    assert comps["plant"].get("source") == "resources/DrillstringPlant.fmu"
    params = {p.get("name"): p[0] for p in comps["controller"].iterfind(".//ssv:Parameter", ns)}
    assert params["mode"].tag == f"{{{NS['ssv']}}}Integer" and params["mode"].get("value") == "1"
    assert params["enabled"].tag.endswith("Boolean") and params["enabled"].get("value") == "true"
    assert float(params["gain"].get("value")) == 5e8
    scene_p = comps["plant"].find(".//ssv:Parameter[@name='scene']", ns)[0]
    assert scene_p.tag.endswith("String") and scene_p.get("value") == "paper_restricted_actuator"
    hint = comps["controller"].find(".//osp:StepSizeHint", ns)
    assert float(hint.get("value")) == pytest.approx(2e-3)
    assert len(root.findall(".//ssd:Connection", ns)) == 8
    # one parameter-set name for all components (Ecos applies the sets of one name)
    assert {ps.get("name") for ps in root.iterfind(".//ssv:ParameterSet", ns)} == {"drillcosim"}
    algo = root.find(".//osp:FixedStepAlgorithm", ns)
    assert float(algo.get("baseStepSize")) == 1e-3


def test_unrepresentable_features_are_refused_or_listed(scene_sys, tmp_path: Path) -> None:
    system = scene_sys.system
    conns = list(system.connections)
    conns[1] = dataclasses.replace(conns[1], delay=0.002)
    conns[2] = Connection(conns[2].source, conns[2].target, 0.0, "linear")
    odd = dataclasses.replace(system, connections=conns, algorithm="gauss_seidel")
    assert len(unsupported_features(odd)) == 3
    with pytest.raises(ValueError, match=r"algorithm 'gauss_seidel'.*\(and 2 more\)"):
        export_ssp(odd, tmp_path / "odd.ssp")
    exp = export_ssp(odd, tmp_path / "odd.ssp", strict=False)
    assert len(exp.omitted) == 3 and exp.path.is_file()
    with pytest.raises(ValueError, match=r"must end in '.ssp'"):
        export_ssp(system, tmp_path / "sys.zip")


@pytest.mark.needs_cc
def test_a_user_scene_ssp_names_no_path_of_this_machine(tmp_path: Path) -> None:
    """A plant FMU built for a user's scene file carries that file; the system and its SSP must
    name the scene as the FMU does, not by this machine's absolute path: the SSP then runs with
    the scene file gone (as on another machine)."""
    from drillcosim.cosim.scenario.ssp_run import simulate_ssp

    scene_file = tmp_path / "user_sites.toml"
    scene_file.write_text('extends = "four_sites"\n\n[controller]\ngain = 5e7\n\n'
                          '[cosim]\nalgorithm = "jacobi"\nstep = 1e-4\nstop_time = 0.005\n')
    ss = build_system(load_config(scene_file), "fmu", fmu_dir=tmp_path / "fmus")
    plant = next(f for f in ss.system.fmus if f.name == "plant")
    assert plant.parameters["scene"] == "user_sites"
    ssp = tmp_path / "user.ssp"
    export_ssp(ss.system, ssp, name="user_sites")
    with zipfile.ZipFile(ssp) as zf:
        assert str(tmp_path) not in zf.read("SystemStructure.ssd").decode()
    scene_file.unlink()
    out = simulate_ssp(ssp, out_dir=tmp_path / "run", progress=False)
    assert out.completed, out.message
