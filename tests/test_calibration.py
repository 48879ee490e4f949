"""Calibration against the paper's Figs. 9-11 and the paper's experiments.

Checked against independent things: the lumped axial chain's closed-form statics (the hanging
string's weight on bit), the state layout by name (the ensemble perturbation), the objective's
definition term by term, a clean run vs a shuffled and a resumed one (order independence), the
scene-run path (``drillcosim run``'s summary) for member 0, and the committed confirm table
(``docs/paper_data``): ranked again, its best paper-consistent set is the one the calibrated
scenes carry and the docs report.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from drillcosim.cosim.scenario.config import load_config
from drillcosim.cosim.study.ensemble import ensemble_stat, lateral_perturbation
from drillcosim.cosim.study.paper.calibration import (
    RANGES,
    TARGETS,
    CalibrationTable,
    PlantChoice,
    best_set,
    calibration_points,
    coarse_sets,
    hanging_weight_on_bit,
    objective,
    rank,
    refine_sets,
)
from drillcosim.cosim.study.scene_stats import SceneTable, measure_scene
from drillcosim.cosim.study.sweep import execute_points
from drillcosim.plant import layout
from drillcosim.plant.model import DrillstringModel
from drillcosim.plant.simulator import PlantSimulator

ROOT = Path(__file__).resolve().parents[1]


def _model(scene: str = "paper_open_loop", **over) -> DrillstringModel:
    return DrillstringModel(load_config(scene, over or None).scene.plant, "full3d")


# -- ensemble ---------------------------------------------------------------------------------
def test_perturbation_moves_exactly_the_lateral_positions():
    m = _model()
    names = PlantSimulator(m)._state_names()      # the plant's own state names
    dy = lateral_perturbation(m, 1e-6, 2024, 3)
    moved = {names[i] for i in np.flatnonzero(dy)}
    assert moved == {n for n in names if n.endswith((".X", ".Y"))}
    assert np.array_equal(dy, lateral_perturbation(m, 1e-6, 2024, 3))     # reproducible
    assert not np.array_equal(dy, lateral_perturbation(m, 1e-6, 2024, 4))
    assert 0.5e-6 < float(np.std(dy[np.flatnonzero(dy)])) < 1.5e-6
    assert not np.any(lateral_perturbation(m, 1e-6, 2024, 0))              # member 0: none
    with pytest.raises(ValueError, match="eps"):
        lateral_perturbation(m, -1.0, 0, 1)


def test_ensemble_stat():
    e = ensemble_stat([1.0, 2.0, 3.0, math.nan])
    assert (e.mean, e.n) == (2.0, 3) and e.sd == pytest.approx(1.0)
    assert e.se == pytest.approx(1 / math.sqrt(3))
    assert ensemble_stat([5.0]).n == 1 and math.isnan(ensemble_stat([5.0]).sd)


# -- the hanging string -----------------------------------------------------------------------
@pytest.mark.parametrize("kt", [1e7, 2e7, 1e9])
def test_hanging_weight_on_bit_matches_the_lumped_chain_in_closed_form(kt):
    """Rock at the unloaded bit end: F_b (1/kb + 1/kt + (n-1)/ka) = W/kt + m g n (n-1)/(2 ka),
    with the model's effective top, joint and bit springs (static balance of the chain)."""
    m = _model(top_drive={"axial_stiffness": kt}, gravity=9.81)
    n, mg = m.n, m.derived.mass * 9.81
    ka, kt_eff, kb = m.p[layout.K_AX], m.p[layout.KT_AX], m.p[layout.KB_AX]
    expected = (n * mg / kt_eff + mg * n * (n - 1) / (2 * ka)) / (1 / kb + 1 / kt_eff
                                                                  + (n - 1) / ka)
    assert hanging_weight_on_bit(kt) == pytest.approx(expected, rel=1e-9)
    assert hanging_weight_on_bit(kt, gravity=0.0) == pytest.approx(0.0, abs=1e-3)


def test_a_softer_top_spring_puts_more_weight_on_the_bit():
    w = [hanging_weight_on_bit(kt) for kt in (1e9, 1e8, 2e7, 1e7)]
    assert w == sorted(w)
    assert w[0] == pytest.approx(0.5 * 48.7e3, rel=0.01)      # ~half the weight at 1e9 N/m


# -- objective and sets -----------------------------------------------------------------------
def _row(**kw):
    row = {"status": "ok", "long_peak_m": 0.015, "long_mean_m": 0.008, "long_band_m": 0.005,
           "long_contact_time_s": 1.0, "short_mean_m": 0.004}
    row.update(kw)
    return row


def test_objective_is_zero_at_the_paper_and_counts_each_term():
    assert objective(_row())["objective"] == 0.0
    assert objective(_row(long_peak_m=0.030))["objective"] == pytest.approx(1.0)
    assert objective(_row(long_mean_m=0.004, short_mean_m=0.002))["err_mean"] == -0.5
    assert objective(_row(long_band_m=0.0))["objective"] == pytest.approx(1.0)
    assert objective(_row(long_contact_time_s=0.0))["objective"] == 1.0
    assert objective(_row(short_mean_m=0.012))["short_excess"] == pytest.approx(0.5)
    assert math.isnan(objective(_row(status="diverged"))["objective"])
    assert set(TARGETS) == {"long_peak_m", "long_mean_m", "long_band_m"}


def test_sets_stay_in_their_ranges():
    sets = coarse_sets()
    assert len(sets) == len({s.label for s in sets}) == 240
    ref = refine_sets(PlantChoice(36e3, 1e9, 0.4, 30, 9.81))
    assert len(ref) == len({s.label for s in ref})
    for s in sets + ref:
        for name, (lo, hi, _, _) in RANGES.items():
            assert lo - 1e-6 <= getattr(s, name) <= hi * (1 + 1e-9)
    with pytest.raises(ValueError, match="weight_on_bit"):
        PlantChoice(60e3, 1e9, 0.4, 30, 9.81)


# -- the study tables -------------------------------------------------------------------------
TINY = [PlantChoice(36e3, 1e9, 0.4, 30, 9.81), PlantChoice(12e3, 1e8, 0.2, 26, 0.0)]


def _tiny_points():
    return calibration_points(TINY, 2, stop_time=0.5)


def _ranking(folder):
    return [(a["group"], a["objective"], a["long_peak_m"], a["members"])
            for a in rank(CalibrationTable(folder).rows)]


def test_tiny_calibration_is_order_independent_and_resumable(tmp_path):
    pts = _tiny_points()
    for name, order in (("a", pts), ("b", pts[::-1])):
        execute_points(order, CalibrationTable(tmp_path / name), measure_scene, workers=0,
                       progress=False)
    first = _ranking(tmp_path / "a")
    assert all(math.isfinite(j) for _, j, *_ in first)
    assert first == _ranking(tmp_path / "b")
    # resume: half the points, then all of them: only the missing ones run
    half = CalibrationTable(tmp_path / "c")
    assert execute_points(pts[:2], half, measure_scene, workers=0, progress=False) == 2
    assert execute_points(pts, CalibrationTable(tmp_path / "c"), measure_scene,
                          workers=0, progress=False) == 2
    assert _ranking(tmp_path / "c") == first
    rows = {r["key"]: r for r in CalibrationTable(tmp_path / "a").rows}
    for r in CalibrationTable(tmp_path / "c").rows:
        assert r["long_peak_m"] == rows[r["key"]]["long_peak_m"]
    # members differ (perturbed) but member 0 of a set is the unperturbed run
    assert len({r["long_p95_m"] for r in rows.values()}) == 4


def test_a_table_of_another_kind_is_refused(tmp_path):
    execute_points(_tiny_points()[:1], CalibrationTable(tmp_path), measure_scene, workers=0,
                   progress=False)
    with pytest.raises(ValueError, match="SceneTable of this version"):
        SceneTable(tmp_path)


def test_member_zero_is_the_run_of_drillcosim_run(project_fmus, tmp_path):
    """The scene path (the API's simulate: FMUs, Result.summary as summary.json has it) and the
    study path (in-process engine, run_statistics) give the same numbers for member 0."""
    from drillcosim import simulate

    fmu_dir = str(project_fmus["DrillstringPlant"].parent)
    s = simulate("paper_closed_loop", stop_time=0.5, fmu_dir=fmu_dir).summary
    row = measure_scene("paper_closed_loop", 0.5)
    assert row["long_peak_m"] == s["spans"]["body11"]["peak_radial_deflection_m"]
    assert row["short_mean_m"] == s["spans"]["body26"]["steady_radial_deflection_mean_m"]
    assert row["site1_peak_force_N"] == s["actuators"]["site1"]["peak_force_N"]
    assert row["site2_mean_power_W"] == s["actuators"]["site2"]["steady_mean_power_W"]
    fmu_row = measure_scene("paper_closed_loop", 0.5, "fmu", fmu_dir=fmu_dir)
    assert fmu_row["site1_peak_power_W"] == row["site1_peak_power_W"]
    with pytest.raises(ValueError, match="engine 'inprocess'"):
        measure_scene("paper_open_loop", 0.5, "fmu", member=1, fmu_dir=fmu_dir)


def test_calibrate_cli_errors_are_one_line(tmp_path, capsys):
    from drillcosim.cosim.cli import main

    assert main(["calibrate", "refine", "--out", str(tmp_path)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "run the 'coarse' stage first" in err[0]
    with pytest.raises(SystemExit) as exc:
        main(["calibrate", "bogus"])
    assert exc.value.code == 2


def test_overrides_json_is_canonical():
    p = _tiny_points()[0]
    assert json.loads(p.overrides) == TINY[0].overrides()
    assert p.overrides == json.dumps(TINY[0].overrides(), sort_keys=True)


@pytest.mark.parametrize("scene", ["paper_calibrated_open_loop", "paper_calibrated_closed_loop"])
def test_the_calibrated_scenes_hold_the_best_set_of_the_committed_table(scene, tmp_path):
    """docs/paper_data/calibration_confirm.csv (every member run of the confirm stage) ranked
    again: its best paper-consistent set is the one the calibrated scenes carry and
    docs/paper_comparison.md reports."""
    (tmp_path / "confirm").mkdir()
    (tmp_path / "confirm" / "results.csv").write_bytes(
        (ROOT / "docs" / "paper_data" / "calibration_confirm.csv").read_bytes())
    best = best_set(CalibrationTable(tmp_path / "confirm").rows)
    plant = load_config(scene).scene.plant
    assert plant.bit.weight_on_bit == best.weight_on_bit
    assert plant.top_drive.axial_stiffness == best.top_axial_stiffness
    assert plant.damping.lateral_ratio == best.lateral_ratio
    assert plant.unbalance.body == best.unbalance_body
    assert plant.gravity == best.gravity
    text = (ROOT / "docs" / "paper_comparison.md").read_text()
    assert (f"**Calibrated set: weight on bit {best.weight_on_bit / 1e3:.1f} kN, lateral damping "
            f"ratio {best.lateral_ratio:g}, unbalance at body {best.unbalance_body}") in text
