"""Stress tests of the nonsmooth extensions: stiff contact, high friction, zero clearance.

Like ``tests/test_stress.py``: each case must either finish with finite outputs or stop with a
divergence StepResult naming the time and the quantity, never produce NaN outputs or hang.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from drillcosim.plant.model import DrillstringModel
from drillcosim.plant.scene import load_scene
from drillcosim.plant.simulator import PlantSimulator

H = 1e-3
KICK = [{"kind": "force", "body": 6, "direction": "x", "magnitude": 2e4, "start": 0.05,
         "duration": 0.01}]

WALL_CASES = {
    "wall stiffness 1e10 N/m": {"contact": {"stiffness": 1e10}},
    "friction coefficient 2": {"contact": {"friction_coefficient": 2.0}},
    "zero clearance": {"contact": {"clearance": 0.0}},
    "friction slip speed 1e-4 m/s": {"contact": {"friction_velocity": 1e-4}},
    "all at once": {"contact": {"clearance": 0.0, "friction_coefficient": 2.0,
                                "stiffness": 1e10, "friction_velocity": 1e-4}},
}


def _run(sim: PlantSimulator, stop: float) -> bool:
    for k in range(round(stop / H)):
        res = sim.do_step(k * H, H)
        if not res.ok:
            assert res.message.startswith("diverged at t = ") and math.isfinite(res.time)
            assert res.quantity
            return False
        assert np.all(np.isfinite(sim.outputs())), f"non-finite output at t = {sim.time}"
    return True


@pytest.mark.parametrize("case", list(WALL_CASES))
def test_wall_friction_case_finishes_finite_or_reports(case):
    sc = load_scene("backward_whirl", overrides={**WALL_CASES[case], "loads": KICK})
    sim = PlantSimulator(DrillstringModel(sc.plant, sc.model))
    if _run(sim, 0.4):
        assert sim.time == pytest.approx(0.4)
        assert np.all(np.isfinite(sim.y))


def test_stiff_wall_with_a_finer_step_rolls_backward():
    """The case that the automatic step cannot take (all at once) runs with a finer internal
    step, and the collar rolls backward (the report above is a step-size limit, not physics)."""
    sc = load_scene("backward_whirl", overrides={**WALL_CASES["all at once"], "loads": KICK})
    m = DrillstringModel(sc.plant, sc.model)
    sim = PlantSimulator(m, max_step=2e-6)
    assert _run(sim, 0.1)
    i = m.output_names.index("body6_whirl_direction")
    assert sim.outputs()[i] == -1.0


BIT_CASES = {
    "stick_slip: rock contact 1e12 N/m": ("stick_slip", {"bit": {"axial_stiffness": 1e12}}),
    "stick_slip: friction 5, static/dynamic 10": (
        "stick_slip", {"bit": {"friction_coefficient": 5.0, "static_friction_ratio": 10.0}}),
    "stick_slip: slip speed 1e-4 rad/s": ("stick_slip", {"bit": {"slip_speed": 1e-4}}),
    "bit_bounce: 1 cm profile": ("bit_bounce", {"bit": {"displacement_amplitude": 0.01}}),
    "bit_bounce: no bit inertia, 5 lobes": ("bit_bounce", {"bit": {"inertia": 0.0,
                                                                   "lobes": 5.0}}),
}


@pytest.mark.parametrize("case", list(BIT_CASES))
def test_bit_case_finishes_finite_or_reports(case):
    scene, over = BIT_CASES[case]
    sc = load_scene(scene, overrides=over)
    m = DrillstringModel(sc.plant, sc.model)
    sim = PlantSimulator(m)
    if _run(sim, 3.0):
        assert sim.time == pytest.approx(3.0)
        assert np.all(np.isfinite(sim.y))
        i = m.output_names.index("drilled_depth")
        assert sim.outputs()[i] >= 0.0  # the hole never fills back
