"""libcosim (Open Simulation Platform, via libcosimpy) runs our exported SSP like our master.

Same system, same step, same algorithm: Jacobi with a zero-order hold and no delays, the
fixed-step algorithm libcosim implements. Both engines drive the same FMU code with the same
inputs in the same order; only the float time differs (libcosim counts integer nanoseconds,
we round start + k H once), so the plant's time-dependent forcing (top-drive ramp, bit
displacement) differs by a few ulps. Every recorded signal must agree to 1e-9 of its peak: a
one-step exchange mismatch shows at the 1e-2 level on the forces, a wrong parameter binding
at 1e-1 or more.

libcosim runs in a subprocess (support.engines): it loads the FMUs in process.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from drillcosim.cosim.master.master import Master
from drillcosim.cosim.master.ssp import export_ssp
from drillcosim.cosim.scenario.build import build_system
from drillcosim.cosim.scenario.config import load_config
from support.closed_loop import ClosedLoop
from support.engines import compare, run_libcosim
from support.required import import_module

pytestmark = [pytest.mark.interop]

import_module("libcosimpy")


def _check(loop: ClosedLoop, tmp_path: Path, record_property, label: str) -> None:
    rows = run_libcosim(loop.ssp, loop.step, loop.n_steps, loop.outputs, tmp_path)
    theirs = {name: rows[:, j] for j, name in enumerate(loop.outputs)}
    result = compare(loop.data[1:], theirs, rtol=1e-9)  # libcosim: the values after each step
    record_property("max_rel_diff", result.worst()[1])
    print(f"\nENGINE {label}: {result.summary()}; {loop.n_steps} steps of {loop.step:g} s")
    assert result.n_moving() > 15  # not a comparison between constants
    forces = [o for o in loop.outputs if "_force_" in o and o.startswith("controller.")]
    assert min(result.peak[f] for f in forces) > 1.0  # the controller acted (N) at every site


def test_libcosim_equals_our_master_on_the_closed_loop(closed_loop_py, tmp_path,
                                                        record_property) -> None:
    _check(closed_loop_py, tmp_path, record_property, "libcosim (Python controller)")


def test_libcosim_runs_the_c_controller_like_our_master(closed_loop_c, tmp_path,
                                                         record_property) -> None:
    _check(closed_loop_c, tmp_path, record_property, "libcosim (C controller)")


def test_libcosim_multirate_restricted_actuator(project_fmus, tmp_path: Path) -> None:
    """Controller every 2 base steps (osp:StepSizeHint), Integer/Boolean/String bindings."""
    config = load_config("paper_restricted_actuator", {
        "controller.gain": 5e8, "cosim.step": 1e-3, "cosim.controller_sample_period": 2e-3,
        "cosim.algorithm": "jacobi", "cosim.order": ["plant", "controller"]})
    ss = build_system(config, "fmu", fmu_dir=project_fmus["DrillstringPlant"].parent)
    n = 200
    ours = Master(ss.system).simulate(n * 1e-3, ss.outputs).data
    exp = export_ssp(ss.system, tmp_path / "sys.ssp")
    rows = run_libcosim(exp.path, 1e-3, n, ss.outputs, tmp_path)
    result = compare(ours[1:], {o: rows[:, j] for j, o in enumerate(ss.outputs)}, rtol=1e-9)
    assert result.n_moving() > 10
    forces = [o for o in ss.outputs if "force_C" in o and o.startswith("controller.")]
    assert max(result.peak[f] for f in forces) > 0  # the controller acted
    pushed = rows[:, list(ss.outputs).index("controller.actuator1_force_C")]
    assert np.all(pushed >= 0) and np.max(pushed) > 0  # compressive_only (mode = 1) reached it


def test_libcosim_runs_the_four_sites_ssp_written_by_the_cli(tmp_path: Path) -> None:
    """``drillcosim ssp four_sites``: FMUs built for the scene (4 sites, 8 forces), Jacobi at
    H = 0.1 ms (SSP 1.0 holds no Gauss-Seidel order), libcosim against our master."""
    from drillcosim.cosim.cli import main

    fmus, ssp = tmp_path / "fmus", tmp_path / "four_sites.ssp"
    assert main(["ssp", "four_sites", "--out", str(ssp), "--step", "1e-4", "--set",
                 "cosim.algorithm='jacobi'", "--fmu-dir", str(fmus)]) == 0
    config = load_config("four_sites", {"cosim.step": 1e-4, "cosim.algorithm": "jacobi"})
    ss = build_system(config, "fmu", fmu_dir=fmus)
    assert {f.path.name for f in ss.system.fmus} == {"DrillstringPlant_four_sites.fmu",
                                                     "StrainController_four_sites.fmu"}
    assert len(ss.system.connections) == 16
    n = 2000
    ours = Master(ss.system).simulate(n * 1e-4, ss.outputs).data
    rows = run_libcosim(ssp, 1e-4, n, ss.outputs, tmp_path)
    result = compare(ours[1:], {o: rows[:, j] for j, o in enumerate(ss.outputs)}, rtol=1e-9)
    print(f"\nENGINE libcosim four_sites: {result.summary()}; {n} steps of 1e-4 s")
    assert result.n_moving() > 30
    forces = [o for o in ss.outputs if "_force_" in o and o.startswith("controller.")]
    assert len(forces) == 8 and min(result.peak[f] for f in forces) > 0.0  # every site acted
