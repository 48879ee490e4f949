"""The public API (``import drillcosim``): what it returns, checked against a second path to the
same numbers (the sweep's point against a plain simulate, the in-process engine against the
FMUs), and that importing it stays cheap for the command line."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

import drillcosim


def test_import_drillcosim_loads_no_heavy_module() -> None:
    code = ("import sys, drillcosim; heavy = [m for m in ('numpy', 'fmpy', 'numba', 'scipy') "
            "if m in sys.modules]; print(heavy)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True).stdout.strip()
    assert out == "[]"
    assert set(drillcosim.__all__) >= {"simulate", "sweep", "list_scenes", "load_scene", "modes",
                                       "build_fmus", "Result", "UserError"}


def test_result_table_units_and_engines_agree(project_fmus) -> None:
    """The in-process engine and the FMUs: the same table, bit for bit (fmu_dir: the session's
    FMUs), with the units the instances declare."""
    kw = {"stop_time": 0.05, "delay": 5e-4, "overrides": {"cosim.output_interval": 2.5e-4}}
    fmu = drillcosim.simulate("paper_closed_loop", fmu_dir=project_fmus["DrillstringPlant"].parent,
                              **kw)
    local = drillcosim.simulate("paper_closed_loop", engine="inprocess", **kw)
    a, b = fmu.to_pandas(), local.to_pandas()
    assert a.index.name == "time" and len(a) == 201
    assert a.index[-1] == 0.05 and list(a.columns) == list(b.columns)
    assert np.array_equal(a.to_numpy(), b.to_numpy())
    assert fmu.units == local.units and a.attrs["units"] == fmu.units
    assert fmu.units["time"] == "s" and fmu.units["plant.total_energy"] == "J"
    assert fmu.summary["cosim"]["actuator_delay"] == 5e-4 and fmu.completed
    assert "inprocess" in repr(local) and "201 rows" in repr(local)


def test_outputs_choose_the_recorded_variables() -> None:
    res = drillcosim.simulate("stick_slip", stop_time=0.1, engine="inprocess",
                              outputs=["plant.bit_twist", "plant.bit_rotary_speed"])
    assert res.columns == ("plant.bit_twist", "plant.bit_rotary_speed")
    assert res.units["plant.bit_twist"] == "rad"
    with pytest.raises(drillcosim.UserError, match=r"records no 'plant.bit_twst'; allowed: .*"
                                                   r"plant.bit_twist"):
        drillcosim.simulate("stick_slip", stop_time=0.1, engine="inprocess",
                            outputs=["plant.bit_twst"])


def test_sweep_rows_are_the_runs_simulate_makes(tmp_path) -> None:
    """A sweep point and a plain simulate of the same configuration: the same peak force."""
    frame = drillcosim.sweep("paper_closed_loop", gains=[2e8], delays=[2.5e-4], steps=[5e-4],
                             stop_time=0.2, engine="inprocess", out=tmp_path)
    assert list(frame["kind"]) == ["open_loop", "closed_loop"]
    assert list(frame["verdict"]) == ["reference", "undecided"]   # 0.2 s: too short to judge
    row = frame[frame["kind"] == "closed_loop"].iloc[0]
    res = drillcosim.simulate("paper_closed_loop", stop_time=0.2, step=5e-4, delay=2.5e-4,
                              gain=2e8, engine="inprocess")
    forces = res.to_pandas().filter(like="controller.actuator")
    assert row["peak_force"] == float(np.max(np.abs(forces.to_numpy()))) > 0
    assert frame.attrs["outcome"].n_points == 2 and (tmp_path / "results.csv").is_file()


def test_modes_and_scenes() -> None:
    assert "paper_closed_loop" in drillcosim.list_scenes()
    table = drillcosim.modes("table1_axial_pulse")
    assert table["model"] == "axial_torsional" and "lateral" not in table["modes"]
    axial = table["modes"]["axial"]
    assert axial["frequency_rad_s"] == pytest.approx(axial["analytic_rad_s"], rel=0.03)
    config = drillcosim.load_scene("stick_slip_soft_torque",
                                   overrides={"top_drive_controller.p_gain": 150.0})
    assert config.top_drive.params.p_gain == 150.0 and config.instances == ("plant",
                                                                     "top_drive_controller")
