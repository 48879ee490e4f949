"""The designed controllers as scenes (``[controller] kind = "state_space"``): the shipped
scenes control_predictor and control_lqg are stable with the full linearized plant (closed-loop
eigenvalues); through the FMUs they equal the in-process engine bit for bit and agree with the
linear model below the contact threshold (the growth rate of a loop run at another delay than
designed for, and the decay at the design delay); a state-space scene that does not fit is
refused in one line (the configuration, the builder)."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from drillcosim.controller.state_space import load_state_space
from drillcosim.cosim.master.interface import InterfaceError
from drillcosim.cosim.scenario.build import build_system
from drillcosim.cosim.scenario.config import ConfigError, load_config
from drillcosim.cosim.scenario.summary import span_info
from drillcosim.cosim.study.control_design import LoopPlant, growth_rate
from drillcosim.cosim.study.point import PointOptions, metrics, simulate_point
from drillcosim.plant.scene import scenes_dir

pytestmark = [pytest.mark.needs_cc]


ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def predictor_plant() -> LoopPlant:
    return LoopPlant.from_scene(load_config("control_predictor"))


@pytest.mark.parametrize("scene", ["control_predictor", "control_lqg"])
def test_shipped_designs_are_stable_with_the_full_linearized_plant(scene):
    """The closed loop of the scene's full linearization (240 states, not the 112-state design
    model) with its controller at its delay has every eigenvalue inside the unit circle, and
    the growth rate the scene's description states."""
    config = load_config(scene)
    ss = config.controller
    assert ss is not None and ss.params.n_states == 120
    assert config.controller.enabled and config.cosim.actuator_delay == 5e-4
    plant = LoopPlant.from_scene(config)
    assert plant.A.shape[0] == 240
    rate = growth_rate(plant, ss.params, config.cosim.actuator_delay)
    assert rate < 0
    assert f"{rate:+.3g} 1/s" in config.scene.description


def _run(config, engine, fmu_dir=None):
    opts = PointOptions()
    data, reason = simulate_point(config, opts, engine, fmu_dir)
    spans = {b: str(v["span"]) for b, v in span_info(config.scene).items()}
    return data, reason, metrics(data, spans, config.n_sites, opts, bool(reason))


def test_predictor_cosimulation_agrees_with_the_linear_model(project_fmus, predictor_plant):
    """control_predictor (designed for 0.5 ms) run at 1 ms through the FMUs, at the rotary
    speed of the linearization from the start: the strain envelope grows at the predicted
    rate (5.97 1/s, docs/control_design.md) within 15 %, the deflection stays below a quarter
    of the clearance (no contact: the linear regime); the in-process engine gives the same
    bits."""
    config = load_config("control_predictor", {"cosim.actuator_delay": 1e-3,
                                               "cosim.stop_time": 1.5,
                                               "top_drive.ramp_time": 0.0})
    predicted = growth_rate(predictor_plant, config.controller.params, 1e-3)
    # the value docs/control_design.md reports (the predictor's row at 1 ms of delay)
    table = (ROOT / "docs" / "control_design.md").read_text().split(
        "predictor and LQG designed for 0.5 ms, run at the delay shown", 1)[1]
    row = next(ln for ln in table.splitlines() if ln.startswith("| 1 |")).split("|")
    assert row[5].strip() == f"{predicted:+.2f}", row
    fmu_dir = project_fmus["DrillstringPlant"].parent
    data, reason, m = _run(config, "fmu", fmu_dir)
    assert reason == ""
    assert m["growth_rate"] == pytest.approx(predicted, rel=0.15)
    clearance = config.scene.plant.contact.clearance
    assert m["peak_deflection_long"] < 0.25 * clearance
    assert m["peak_deflection_short"] < 0.25 * clearance
    contact = [c for c in data.dtype.names if c.endswith("contact_force")]
    assert contact and all(np.abs(data[c]).max() == 0.0 for c in contact)
    same, reason_in, _ = _run(config, "inprocess")
    assert reason_in == ""
    for c in data.dtype.names:
        assert np.array_equal(data[c], same[c]), c


@pytest.mark.parametrize("scene", ["control_predictor", "control_lqg"])
def test_design_delay_decays_as_predicted(scene):
    """At the delay designed for (0.5 ms) the linear model is stable and so is the
    co-simulation: the high-passed strain envelope decays."""
    config = load_config(scene, {"cosim.stop_time": 1.5, "top_drive.ramp_time": 0.0})
    assert growth_rate(LoopPlant.from_scene(config), config.controller.params, 5e-4) < 0
    _data, reason, m = _run(config, "inprocess")
    assert reason == "" and m["growth_rate"] < -0.5


# -- a scene that does not fit: one line ------------------------------------------------------
def _scene(tmp_path, matrices: dict | None, controller: str = "", cosim: str = "") -> str:
    if matrices is not None:
        (tmp_path / "m.json").write_text(json.dumps(matrices))
    path = tmp_path / "s.toml"
    path.write_text('extends = "paper_calibrated_closed_loop"\n\n[controller]\nenabled = true\n'
                    f'kind = "state_space"\nmatrices = "m.json"\n{controller}\n'
                    f"[cosim]\nstop_time = 0.01\n{cosim}\n")
    return str(path)


@pytest.fixture(scope="module")
def matrices() -> dict:
    return load_state_space(scenes_dir() / "control_predictor.json").to_mapping()


def test_state_space_scene_runs_and_reports_its_controller(tmp_path, matrices):
    config = load_config(_scene(tmp_path, matrices))
    assert config.controller.params.n_states == 120
    # the P law's keys of the scene it extends are not read; its enabled flag is
    assert config.controller.enabled and config.controller.set_keys == ()
    built = build_system(config, "inprocess")
    assert "controller.actuator1_force_C" in built.outputs


@pytest.mark.parametrize("change, where, message", [
    ({"inputs": 0}, "build", "input 'strain3_C' ([controller] matrices m.json) is no output of"),
    ({"sample_period": 3e-4}, "config", "sample period 0.0003 s does not divide"),
    ({"D": math.nan}, "config", r"D\[1, 1\] = nan"),
    ({"unit": "N"}, "build", "unit"),
])
def test_a_matrices_file_that_does_not_fit_is_one_line(tmp_path, matrices, change, where,
                                                        message):
    data = json.loads(json.dumps(matrices))
    if "inputs" in change:
        data["inputs"][0]["name"] = "strain3_C"
    if "sample_period" in change:
        data["sample_period"] = change["sample_period"]
    if "D" in change:
        data["D"][0][0] = None
    if "unit" in change:
        data["inputs"][1]["unit"] = "N"
    path = _scene(tmp_path, data)
    if where == "config":
        with pytest.raises(ConfigError, match=message) as info:
            load_config(path)
    else:
        with pytest.raises(InterfaceError) as info:
            build_system(load_config(path), "inprocess")
        assert message in str(info.value)
    assert all(len(line) < 400 for line in str(info.value).splitlines())
    if where == "config":
        assert "\n" not in str(info.value) and "[controller]" in str(info.value)


@pytest.mark.parametrize("controller, over, message", [
    ("", {"controller.gain": 1e8}, "controller.gain: not a key of a controller of kind"),
    ('kind = "state_spac"', None, "did you mean 'state_space'"),
    ("", {"controller.matrices": "missing.json"}, "cannot read"),
])
def test_bad_state_space_settings_are_one_line(tmp_path, matrices, controller, over, message):
    path = _scene(tmp_path, matrices)
    if controller:
        text = (tmp_path / "s.toml").read_text().replace('kind = "state_space"', controller)
        (tmp_path / "s.toml").write_text(text)
    with pytest.raises(ConfigError, match=message) as info:
        load_config(path, over)
    assert "\n" not in str(info.value)


# -- the comparison's linear-regime check (cosim.study.control_design.linear) ------------------
def _agree(simulated: float, predicted: float) -> bool:
    """The tolerance of the linear check: 0.5 1/s (the verdict's growth margin: a stable loop's
    fit reads -0.58..-0.77 1/s where the slowest predicted mode is -0.12 1/s) + 10 % (the
    largest relative miss of docs/control_design.md's table: P 1e9 at 2 ms, +22.6 vs +25.3 1/s,
    whose linear part lasts only 0.44 s)."""
    return abs(simulated - predicted) <= 0.5 + 0.1 * abs(predicted)


@pytest.mark.parametrize("family, delay, design_delay", [
    ("p1e9", 2.5e-4, None),        # unstable, slowest: +2.6 1/s
    ("p1e9", 1e-3, None),          # +13 1/s
    ("pred1e9", 1.5e-3, 5e-4),     # the predictor for 0.5 ms at 1.5 ms: +12.6 1/s
    ("pred1e9", 2e-3, None),       # the predictor for a known 2 ms: stable
    ("lqg3e-6", 2e-3, 5e-4),       # LQG for 0.5 ms at 2 ms: stable
])
def test_cosimulated_growth_rate_is_the_predicted_one(tmp_path_factory, family, delay,
                                                      design_delay):
    """The study's point through the master (in process; the FMUs give the same bits, above):
    an unstable loop grows at the rate of the full linearized plant's closed loop, a stable
    one does not grow, and the run stays linear (no contact) long enough to tell."""
    from drillcosim.cosim.study.control_design.linear import MIN_LINEAR, linear_point

    r = linear_point(family, delay, tmp_path_factory.getbasetemp() / "designs",
                     design_delay=design_delay)
    assert r["linear_until"] >= MIN_LINEAR and math.isfinite(r["simulated"])
    if r["predicted"] > 1.0:
        assert _agree(r["simulated"], r["predicted"]), r
    else:
        assert r["predicted"] < 0 and r["simulated"] < 0, r


def test_comparison_study_runs_and_reports(tmp_path):
    """The 30 s study's pipeline on three 2 s points (open loop, P 1e9 and the predictor at
    0.5 ms): one row per point, the P law's envelope grows faster than the open loop's by more
    than the verdict's margin and the prediction says unstable, the predictor's neither; the
    report names both and writes its figures."""
    from drillcosim.cosim.study.control_design.compare import ComparePoint, run_compare
    from drillcosim.cosim.study.control_design.compare_report import compare_rows, report

    pts = [ComparePoint("open", 1, 0.0, stop_time=2.0),
           ComparePoint("p1e9", 1, 5e-4, stop_time=2.0),
           ComparePoint("pred1e9", 1, 5e-4, stop_time=2.0)]
    rows = run_compare(tmp_path, workers=0, progress=False, points=pts)
    assert sorted(r["family"] for r in rows) == ["open", "p1e9", "pred1e9"]
    by = {r["family"]: r for r in compare_rows(rows)}
    assert by["p1e9"]["predicted_growth_rate"] > 1 and by["p1e9"]["verdict"] == "unstable"
    assert by["pred1e9"]["predicted_growth_rate"] < 0 and by["pred1e9"]["below_margin"]
    text = report(tmp_path)
    assert "| P 1e9 | 1 |" in text and "| predictor 1e9 | 1 |" in text
    assert (tmp_path / "report" / "control_growth.png").stat().st_size > 0
