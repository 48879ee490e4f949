"""The conclusion study's pieces: N actuator sites per span in process, the calibrated scenes.

Checked against independent things: the plant and controller FMUs of the two-site layout (bit
for bit), the controller law written out channel by channel, the span geometry, and the
committed calibration table (the calibrated scenes carry its best paper-consistent set).
"""

from __future__ import annotations

import csv
import math
from pathlib import Path

import numpy as np
import pytest

from drillcosim.controller import ControllerParams, StrainController
from drillcosim.cosim.scenario.config import load_config
from drillcosim.cosim.scenario.inprocess import LawSlave
from drillcosim.cosim.study.paper.calibration import PlantChoice, best_set, objective
from drillcosim.cosim.study.paper.conclusion import site_config, site_joints
from drillcosim.cosim.study.point import PointOptions, simulate_point

ROOT = Path(__file__).resolve().parents[1]
EXPERIMENTS = ("open_loop", "closed_loop", "restricted_actuator", "switch_on_25s", "severe")


@pytest.mark.parametrize("per_span", [1, 2, 3])
def test_site_joints_spread_over_each_span(per_span):
    plant = load_config("paper_calibrated_closed_loop").scene.plant
    joints = site_joints(plant, per_span)
    assert len(joints) == 2 * per_span
    assert list(joints) == sorted(set(joints))
    dx = plant.pipe.segment_length
    for k, (a, b) in enumerate(plant.spans()):
        own = joints[k * per_span:(k + 1) * per_span]
        # a joint below body j sits at j * dx from the top: inside its span, off the stabilizers
        assert all(a < j * dx < b for j in own), (own, a, b)
    if per_span == 1:  # the scenes' default: below each span's middle body (paper: 11, 26)
        assert joints == plant.actuator_joints == (11, 26)
    with pytest.raises(ValueError, match="per_span"):
        site_joints(plant, 0)


def test_controller_slave_serves_any_number_of_sites():
    params = ControllerParams(gain=1e9, mode="compressive_only", force_limit=5000.0)
    layout = StrainController.layout_for(params, 3)
    slave = LawSlave("controller", StrainController.create(params, layout),
                     StrainController.ports(layout))   # 6 channels
    assert slave.inputs == [f"strain{s}_{a}" for s in (1, 2, 3) for a in "CE"]
    assert slave.outputs == [f"actuator{s}_force_{a}" for s in (1, 2, 3) for a in "CE"]
    slave.instantiate(0.0, None)
    strains = np.array([2e-6, -3e-6, 1e-5, -1e-5, 4e-6, 0.0])
    slave.u[:] = strains
    assert slave.do_step(0.0, 1e-3) == 0
    lo, hi = params.lower_limit, params.upper_limit
    expected = [min(max(1e9 * e, lo), hi) for e in strains]     # the law, channel by channel
    np.testing.assert_array_equal(slave.y, expected)
    state = slave.get_state(1e-3)
    slave.u[:] = 0.0
    slave.do_step(1e-3, 1e-3)
    slave.set_state(state, 1e-3)
    np.testing.assert_array_equal(slave.y, expected)
    slave.u[2] = np.nan
    assert slave.do_step(2e-3, 1e-3) != 0 and "strain" in slave.take_problem()


def test_two_site_in_process_point_is_the_fmu_point_bit_for_bit(project_fmus):
    """The study's in-process engine on the calibrated two-site layout and the plant and
    controller FMUs of that layout: every recorded value is identical, with an actuator delay
    on the connections."""
    config = site_config("paper_calibrated_closed_loop", 1, 1e9, 5e-4, 2.5e-4, 0.3)
    fmu_dir = project_fmus["DrillstringPlant"].parent
    ref, reason_ref = simulate_point(config, PointOptions(), "fmu", fmu_dir)
    new, reason_new = simulate_point(config, PointOptions(), "inprocess")
    assert reason_ref == reason_new == ""
    assert new.dtype.names == ref.dtype.names
    assert len(new.dtype.names) >= 1 + 4 * 2 + 3 * 2 + 4   # time, 2 bodies, 2 sites, 4 forces
    for n in new.dtype.names:
        np.testing.assert_array_equal(new[n], ref[n], err_msg=n)
    assert np.max(np.abs(new["controller.actuator1_force_C"])) > 0


def test_six_sites_run_and_each_site_gets_its_own_force():
    base = site_config("paper_calibrated_closed_loop", 3, 1e9, 0.0, 2.5e-4, 0.2)
    config = load_config("paper_calibrated_closed_loop", {
        "actuators.joints": list(base.scene.plant.actuator_joints),
        "cosim.stop_time": 0.2, "cosim.output_interval": 2.5e-4})   # every step recorded
    assert config.n_sites == 6
    data, reason = simulate_point(config, PointOptions(), "inprocess")
    assert reason == ""
    for s in range(1, 7):
        f = data[f"controller.actuator{s}_force_C"]
        e = data[f"plant.strain{s}_C"]
        assert np.max(np.abs(f)) > 0
        # Gauss-Seidel, controller first: the force at t_k is the gain times the strain the
        # plant reported at t_k - H (the recorded strain of the previous point)
        np.testing.assert_allclose(f[1:], 1e9 * e[:-1], rtol=1e-12, atol=1e-9)


def test_calibrated_scenes_are_todays_with_the_confirmed_best_set():
    with open(ROOT / "docs" / "paper_data" / "calibration_confirm.csv") as fh:
        rows = list(csv.DictReader(fh))
    table = []
    for r in rows:
        d = {k: (float(v) if k not in ("key", "group", "scene", "engine", "overrides",
                                        "status", "reason") and v != "" else v)
             for k, v in r.items()}
        d.update(objective(d))
        table.append(d)
    best = best_set(table)
    p = load_config("paper_calibrated_open_loop").scene.plant
    assert best == PlantChoice(p.bit.weight_on_bit, p.top_drive.axial_stiffness,
                               p.damping.lateral_ratio, p.unbalance.body, p.gravity)
    for name in EXPERIMENTS:
        o = best.overrides()
        if name == "severe":
            o["top_drive.axial_stiffness"] = 2e7
        a, b = load_config(f"paper_calibrated_{name}"), load_config(f"paper_{name}", o)
        assert (a.scene.plant, a.controller, a.top_drive, a.cosim, a.scene.model) == (
            b.scene.plant, b.controller, b.top_drive, b.cosim, b.scene.model), name


def _row(per_span, gain, delay, rms, status="ok", growth=0.0, noise=0.01, contact=0.0):
    return {"key": f"{per_span}|{gain}|{delay}", "per_span": float(per_span), "gain": gain,
            "delay": delay, "status": status, "reason": "", "end_time": 30.0,
            "growth_rate": growth, "growth_noise": noise, "long_rms_m": rms,
            "short_rms_m": rms, "long_contact_time_s": contact, "short_contact_time_s": 0.0,
            "peak_force": 0.0, "peak_power": 0.0}


def test_conclusion_answer_needs_stability_in_both_and_the_benefit_against_both_references():
    from drillcosim.cosim.study.paper.conclusion_report import answer, conclusion_rows

    ref = _row(1, 0.0, 0.0, 0.010, contact=2.0)
    rows = [ref,
            _row(3, 1e8, 5e-4, 0.006),                   # 40 % cut, stable: the answer
            _row(2, 1e8, 5e-4, 0.008),                   # 20 % cut only
            _row(1, 2e8, 5e-4, 0.005),                   # predicted unstable
            _row(2, 2e8, 5e-4, 0.005, growth=0.9),       # grows 0.9 1/s faster than open loop
            _row(3, 2e8, 5e-4, math.nan, "diverged"),
            _row(3, 1e8, 2.5e-4, 0.001)]                 # another delay
    pred = [{"per_span": r["per_span"], "gain": r["gain"], "delay": r["delay"],
             "predicted_growth_rate": 1.0 if (r["per_span"], r["gain"]) == (1.0, 2e8) else -0.1,
             "critical_gain": 3e8} for r in rows[1:]]
    out, reference = conclusion_rows(rows, pred, {"long_rms_m": 0.0075})
    assert reference is ref and len(out) == len(rows) - 1
    best = next(r for r in out if (r["per_span"], r["gain"], r["delay"]) == (3.0, 1e8, 5e-4))
    assert best["benefit_long"] == pytest.approx(0.4)
    assert best["benefit_long_ensemble"] == pytest.approx(0.2)     # 1 - 6 / 7.5
    assert [(r["per_span"], r["gain"]) for r in answer(out)] == []  # 20 % vs the ensemble
    out, _ = conclusion_rows(rows, pred, {"long_rms_m": 0.012})
    assert [(r["per_span"], r["gain"]) for r in answer(out)] == [(3.0, 1e8)]
    grows = next(r for r in out if r["growth_rate"] == 0.9)
    assert grows["verdict"] == "unstable" and not grows["below_margin"]


def test_run_conclusion_resumes_and_writes_the_prediction_of_its_points(tmp_path):
    import json

    from drillcosim.cosim.study.paper.conclusion import SitePoint, run_conclusion

    pts = [SitePoint(1, 0.0, 0.0, stop_time=0.2), SitePoint(1, 1e9, 5e-4, stop_time=0.2)]
    rows = run_conclusion(tmp_path, workers=0, progress=False, points=pts)
    assert sorted(r["gain"] for r in rows) == [0.0, 1e9]
    assert all(r["status"] == "ok" and r["joints"] == "11 26" for r in rows)
    pred = json.loads((tmp_path / "prediction.json").read_text())
    (p,) = [p for p in pred if p["gain"] == 1e9 and p["delay"] == 5e-4]
    # gain 1e9 with 0.5 ms of delay is beyond the critical gain (docs/paper_comparison.md)
    assert p["predicted_growth_rate"] > 0 and p["critical_gain"] < 1e9
    before = (tmp_path / "results.csv").read_text()
    again = run_conclusion(tmp_path, workers=0, progress=False, points=pts)
    assert [r["key"] for r in again] == [r["key"] for r in rows]
    assert (tmp_path / "results.csv").read_text() == before


def test_member_ensembles_average_the_completed_members_against_the_open_loop_ones():
    from drillcosim.cosim.study.paper.conclusion_report import member_ensembles

    rows = [dict(_row(1, 0.0, 0.0, v), member=float(k)) for k, v in enumerate((0.010, 0.014))]
    rows += [dict(_row(3, 1e8, 5e-4, v), member=float(k)) for k, v in enumerate((0.003, 0.003))]
    rows.append(dict(_row(3, 1e8, 5e-4, math.nan, "diverged", growth=5.0), member=2.0))
    rows.append(_row(2, 1e8, 5e-4, 0.005))                     # one member: no ensemble
    ens = member_ensembles(rows)
    assert [(e["per_span"], e["gain"]) for e in ens] == [(1.0, 0.0), (3.0, 1e8)]
    e = ens[1]
    assert (e["members"], e["completed"]) == (3, 2)
    assert e["long_rms_m"] == pytest.approx(0.003) and e["max_growth_rate"] == 5.0
    assert e["benefit_long"] == pytest.approx(1 - 0.003 / 0.012)
