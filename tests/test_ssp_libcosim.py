"""SSP export: the archive's structure, and libcosim running it like our master.

libcosim (libcosimpy) runs in a subprocess: it loads the FMUs in process and a
crash there must not take pytest down. Its step size is an int in nanoseconds,
and its execution is freed explicitly (it aborts if freed at interpreter exit).
"""

from __future__ import annotations

import dataclasses
import json
import subprocess
import sys
import textwrap
import zipfile
from pathlib import Path
from xml.etree import ElementTree as ET

import numpy as np
import pytest

from drillcosim.cosim.master.master import Master
from drillcosim.cosim.master.ssp import NS, export_ssp, unsupported_features
from drillcosim.cosim.master.system import Connection
from drillcosim.cosim.scenario.scene_system import scene_system
from drillcosim.plant.scene import load_scene

pytestmark = [pytest.mark.interop]

HOST = textwrap.dedent("""
    import json, sys
    from libcosimpy.CosimExecution import CosimExecution
    from libcosimpy.CosimObserver import CosimObserver

    ssp, step_ns, n_steps, wanted = sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), \\
        json.loads(sys.argv[4])
    ex = CosimExecution.from_ssp_file(ssp, step_size=step_ns)
    obs = CosimObserver.create_last_value()
    ex.add_observer(observer=obs)
    index, refs = {}, {}
    for ref in wanted:
        inst = ref.split(".", 1)[0]
        if inst not in index:
            index[inst] = i = ex.slave_index_from_instance_name(inst)
            refs[inst] = {v.name.decode(): v.reference for v in ex.slave_variables(i)}
    rows, ok = [], True
    for _ in range(n_steps):
        ok = ex.step(1) and ok
        rows.append([obs.last_real_values(index[r.split(".")[0]],
                                          [refs[r.split(".")[0]][r.split(".", 1)[1]]])[0]
                     for r in wanted])
    print("RESULT " + json.dumps({"ok": bool(ok), "rows": rows}), flush=True)
    del obs
    del ex
""")


@pytest.fixture(scope="module")
def scene_sys(project_fmus):
    pytest.importorskip("libcosimpy")
    # Multirate (controller every 2 ms), a non-default gain and the restricted mode, so the
    # parameter bindings (Real, Integer, Boolean, String) and the step-size hint matter.
    sc = load_scene("paper_restricted_actuator", overrides={"controller": {"gain": 5e8}})
    sc = dataclasses.replace(sc, cosim={"step": 1e-3, "controller_sample_period": 2e-3})
    return scene_system(sc, project_fmus["DrillstringPlant"].parent)


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


def test_libcosim_runs_the_exported_ssp_like_our_master(scene_sys, tmp_path: Path) -> None:
    """libcosim == our master (Jacobi, ZOH, multirate) to 1e-9 of each signal's peak.

    Both drive the same FMU code with the same inputs in the same order, so only the
    float time differs: libcosim converts integer nanoseconds (k * 1e6 ns * 1e-9), we
    round start + k * H once; the plant's time-dependent forcing (top-drive ramp, bit
    displacement) then differs by a few ulps. Measured: <= 1e-13 relative after
    200 steps; 1e-9 leaves room without hiding a one-step exchange mismatch (which
    would show at the 1e-2 level on the forces).
    """
    n = 200
    ours = Master(scene_sys.system).simulate(n * 1e-3, scene_sys.outputs).data
    exp = export_ssp(scene_sys.system, tmp_path / "sys.ssp")
    host = tmp_path / "host.py"
    host.write_text(HOST)
    proc = subprocess.run([sys.executable, str(host), str(exp.path), "1000000", str(n),
                           json.dumps(list(scene_sys.outputs))], cwd=tmp_path,
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr[-3000:]
    lines = [ln for ln in proc.stdout.splitlines() if ln.startswith("RESULT ")]
    assert lines, proc.stdout[-3000:]
    res = json.loads(lines[-1].removeprefix("RESULT "))
    assert res["ok"]
    lib = np.array(res["rows"])
    assert lib.shape == (n, len(scene_sys.outputs))
    moving = 0
    for j, name in enumerate(scene_sys.outputs):
        mine = ours[name][1:]
        scale = float(np.max(np.abs(mine)))
        np.testing.assert_allclose(lib[:, j], mine, rtol=0, atol=1e-9 * scale + 1e-300,
                                   err_msg=name)
        moving += scale > 0 and np.ptp(mine) > 0
    assert moving > 10  # the comparison is not between constants
    forces = [j for j, nm in enumerate(scene_sys.outputs) if "force_C" in nm]
    assert np.max(np.abs(lib[:, forces])) > 0  # the controller acted
