"""PlantSimulator: divergence is returned with time and quantity, never hidden."""

from __future__ import annotations

import math

import numpy as np
import pytest

from drillcosim.plant.model import DrillstringModel
from drillcosim.plant.scene import load_scene
from drillcosim.plant.simulator import MAX_STRAIN, PlantSimulator


def test_runaway_actuator_stops_with_a_strain_report():
    """2 MN on the site-1 actuators bends that joint beyond the elastic range within steps."""
    sc = load_scene("paper_open_loop")
    sim = PlantSimulator(DrillstringModel(sc.plant, sc.model))
    sim.set_inputs(np.array([2e6, 2e6, 0.0, 0.0]))
    res = None
    for k in range(200):
        res = sim.do_step(k * 1e-3, 1e-3)
        if not res.ok:
            break
    assert res is not None and not res.ok
    assert res.quantity == "joint11.strain"
    assert res.value > MAX_STRAIN
    assert "t = " in res.message and "strain" in res.message
    assert np.all(np.isfinite(sim.outputs()))


def test_non_finite_input_is_refused_without_touching_the_state():
    sc = load_scene("paper_open_loop")
    sim = PlantSimulator(DrillstringModel(sc.plant, sc.model))
    y0 = sim.y.copy()
    sim.set_inputs(np.array([np.nan, 0.0, 0.0, 0.0]))
    res = sim.do_step(0.0, 1e-3)
    assert not res.ok and "actuator1_force_C = nan is not finite" in res.message
    assert np.array_equal(sim.y, y0)


@pytest.mark.parametrize(("t", "h", "fragment"), [
    (0.002, 1e-3, "is not the plant's time 0.001"),
    (math.nan, 1e-3, "is not the plant's time"),
    (0.001, 0.0, "must be > 0 and finite"),
    (0.001, math.inf, "must be > 0 and finite"),
    (0.001, 1e6, "internal steps"),
])
def test_bad_step_requests_are_refused_with_the_state_unchanged(t, h, fragment):
    """Out-of-order or non-finite time, bad step size, too many internal steps: refused."""
    sc = load_scene("paper_open_loop")
    sim = PlantSimulator(DrillstringModel(sc.plant, sc.model))
    assert sim.do_step(0.0, 1e-3).ok
    y0, t0 = sim.y.copy(), sim.time
    res = sim.do_step(t, h)
    assert not res.ok and fragment in res.message and not res.quantity
    assert np.array_equal(sim.y, y0) and sim.time == t0
    assert sim.do_step(t0, 1e-3).ok  # a valid step continues


def test_open_loop_scene_stays_inside_the_guards():
    """The paper's open-loop scene (contact, buckling) runs 3 s without tripping any guard."""
    sc = load_scene("paper_open_loop")
    sim = PlantSimulator(DrillstringModel(sc.plant, sc.model))
    for k in range(3000):
        res = sim.do_step(k * 1e-3, 1e-3)
        assert res.ok, res.message


def test_compiled_run_record_equals_stepping_bit_for_bit():
    """The compiled loop used by simulate() gives the same numbers as do_step + outputs."""
    for scene in ("paper_open_loop", "table1_axial_pulse"):
        sc = load_scene(scene)
        a = PlantSimulator(DrillstringModel(sc.plant, sc.model))
        b = PlantSimulator(DrillstringModel(sc.plant, sc.model))
        idx = np.arange(len(a.model.output_names))
        rows = [a.outputs().copy()]
        for k in range(300):
            assert a.do_step(k * 1e-3, 1e-3).ok
            rows.append(a.outputs().copy())
        rec, res = b.run_record(1e-3, 300, idx)
        assert res.ok
        assert np.array_equal(rec, np.array(rows))
        assert np.array_equal(a.y, b.y) and b.time == a.time


def test_compiled_run_record_reports_divergence_like_do_step():
    sc = load_scene("paper_open_loop")
    sim = PlantSimulator(DrillstringModel(sc.plant, sc.model))
    sim.set_inputs(np.array([2e6, 2e6, 0.0, 0.0]))
    rec, res = sim.run_record(1e-3, 500, np.array([0]))
    assert not res.ok and res.quantity == "joint11.strain"
    assert rec.shape[0] < 501
