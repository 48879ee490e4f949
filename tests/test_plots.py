"""PNG plots of a run (cosim.scenario.plots): which figures a run's recorded outputs give."""

from __future__ import annotations

import numpy as np
from matplotlib.image import imread

from drillcosim.cosim.scenario.plots import plot_axial_torsional, plot_run


def _record(names: list[str], n: int = 400) -> np.ndarray:
    t = np.linspace(0.0, 4.0, n)
    data = np.zeros(n, dtype=[("time", float)] + [(c, float) for c in names])
    data["time"] = t
    for k, c in enumerate(names):
        data[c] = np.sin((k + 1) * t)
    return data


def test_a_chain_run_gets_the_axial_torsional_figure_only(tmp_path) -> None:
    data = _record(["plant.top_rotary_speed", "plant.bit_rotary_speed", "plant.top_torque",
                    "plant.bit_torque", "plant.bit_axial_force", "plant.bit_on_bottom"])
    paths = plot_run(data, tmp_path, clearance=0.02, title="chain")
    assert [p.name for p in paths] == ["axial_torsional.png"]
    assert imread(paths[0]).shape[0] > 800     # three stacked panels (2.4 in each, 120 dpi)


def test_panels_follow_the_recorded_outputs(tmp_path) -> None:
    one = plot_axial_torsional(_record(["plant.bit_rotary_speed"]), tmp_path / "one.png")
    three = plot_axial_torsional(_record(["plant.bit_rotary_speed", "plant.bit_torque",
                                          "plant.bit_axial_force"]), tmp_path / "three.png")
    assert imread(three).shape[0] > 2 * imread(one).shape[0]
    assert plot_axial_torsional(_record(["plant.hook_load"]), tmp_path / "none.png") is None
    assert not (tmp_path / "none.png").exists()


def test_a_3d_run_keeps_the_lateral_figures(tmp_path) -> None:
    data = _record(["plant.body11_X", "plant.body11_Y", "plant.body11_radial_deflection",
                    "plant.body11_contact_force", "plant.bit_rotary_speed"])
    names = sorted(p.name for p in plot_run(data, tmp_path, clearance=0.02))
    assert names == ["deflection_contact.png", "orbit.png", "orbit_steady.png"]


def test_a_chain_run_summary_has_no_bending_actuators(tmp_path) -> None:
    """stick_slip keeps the default [actuators] joints, but its chain has no bending actuators:
    the summary must not list two sites with zero force."""
    import json

    from drillcosim import simulate

    res = simulate("stick_slip", stop_time=0.5)
    res.save(tmp_path, plots=False)
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert res.completed and summary["actuators"] == {}
    assert summary["torsional"]["bit_speed_max_rad_s"] > 0.0
