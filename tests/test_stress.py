"""Numerical stress tests of the plant: stiff parameters, fine discretisation, fast spin.

Each case runs paper_open_loop for 0.5 s through PlantSimulator (RK4, automatic step) and must
either finish with finite outputs or stop with a divergence StepResult: never NaN outputs, never
a hang. Raising a stiffness 10x must keep the automatic step stable (bounded energy).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from drillcosim.plant.model import DrillstringModel
from drillcosim.plant.scene import load_scene
from drillcosim.plant.simulator import PlantSimulator

T = 0.5
H = 1e-3


def _model(**ov) -> DrillstringModel:
    sc = load_scene("paper_open_loop", overrides=ov or None)
    return DrillstringModel(sc.plant, sc.model)


def _run(m: DrillstringModel, T: float = T) -> tuple[PlantSimulator, bool, list[float]]:
    sim = PlantSimulator(m)
    energy = []
    ok = True
    for k in range(int(round(T / H))):
        res = sim.do_step(k * H, H)
        if not res.ok:
            assert res.message and math.isfinite(res.time)  # a named divergence report
            ok = False
            break
        out = sim.outputs()
        assert np.all(np.isfinite(out)), f"non-finite output at t = {sim.time}"
        energy.append(float(out[-1]))
    return sim, ok, energy


CASES = {
    "contact stiffness 1e9 N/m": {"contact": {"stiffness": 1e9}},
    "top spring 1e10 N/m": {"top_drive": {"axial_stiffness": 1e10, "lateral_stiffness": 1e10}},
    "n = 120": {"pipe": {"n_segments": 120}, "contact": {"bodies": []}, "outputs": []},
    "rotary speed 30 rad/s": {"top_drive": {"rotary_speed": 30.0}},
    "clearance 1 mm": {"contact": {"clearance": 0.001}},
}


@pytest.mark.slow
@pytest.mark.parametrize("case", list(CASES))
def test_stress_case_finishes_finite_or_reports(case):
    m = _model(**CASES[case])
    sim, ok, _ = _run(m)
    if ok:
        assert sim.time == pytest.approx(T)
        assert np.all(np.isfinite(sim.y))


def _undamped(**ov) -> dict:
    base = {"damping": {"axial_ratio": 0.0, "torsional_ratio": 0.0, "lateral_ratio": 0.0},
            "top_drive": {"rotary_speed": 0.0}, "bit": {"displacement_amplitude": 0.0},
            "unbalance": {"enabled": False}, "gravity": 0.0,
            "loads": [{"kind": "force", "body": 15, "direction": "x", "magnitude": 1e4,
                       "start": 0.0, "duration": 0.005}]}
    for k, v in ov.items():
        base[k] = {**base.get(k, {}), **v} if isinstance(v, dict) else v
    return base


@pytest.mark.parametrize("param", [
    ("top_drive", "axial_stiffness", 1e9),
    ("top_drive", "lateral_stiffness", 1e9),
    ("stabilizers", "stiffness", 1e9),
    ("contact", "stiffness", 1e7),
])
def test_ten_times_stiffer_keeps_automatic_step_stable(param):
    """Undamped, unforced after a 5 ms lateral kick: RK4 at the automatic step keeps the energy
    bounded (RK4 is slightly dissipative inside its stability region) for 10x the stiffness."""
    sec, key, val = param
    for factor in (1.0, 10.0):
        ov = _undamped(**{sec: {key: val * factor}})
        if sec == "contact":
            ov["contact"] = {**ov.get("contact", {}), "clearance": 1e-4}
        m = _model(**ov)
        sim, ok, energy = _run(m, 0.3)
        assert ok, f"{key} x{factor}: diverged"
        e = np.array(energy[10:])  # after the kick
        assert np.all(np.isfinite(e))
        assert e.max() <= 1.01 * e[0] + 1e-9, f"{key} x{factor}: energy grew"


def test_rk4_trajectory_converges_at_fourth_order():
    """Strain and lateral deflection over 0.1 s vs the internal step: fitted slope ~ 4."""
    m = _model()
    names = ["strain1_C", "body26_radial_deflection"]
    idx = [m.output_names.index(k) for k in names]

    def run(max_step):
        sim = PlantSimulator(m, max_step=max_step)
        rows = []
        for k in range(100):
            assert sim.do_step(k * H, H).ok
            rows.append(sim.outputs()[idx].copy())
        return np.array(rows)

    h0 = m.stable_step()
    ref = run(h0 / 32)
    steps = [h0, h0 / 2, h0 / 4]
    errs = [np.abs(run(h) - ref).max(axis=0).max() / np.abs(ref).max() for h in steps]
    dts = [H / math.ceil(H / h - 1e-9) for h in steps]
    slope = np.polyfit(np.log(dts), np.log(errs), 1)[0]
    assert 3.5 < slope < 4.8, (dts, errs)
