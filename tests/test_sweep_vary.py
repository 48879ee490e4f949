"""Sweeps over any scene key (``--vary``), planned once into typed point configurations.

* ``sweep_spec`` validates the scene once and derives every point's configuration from it
  (``derive_config``); the points carry them, and running them reads no scene file again;
* ``drillcosim sweep`` plans the sweep once (the API runs the planned spec as it is);
* a point the user must fix (an unknown parameter of a foreign FMU, a value outside the range
  its modelDescription declares, a value a key cannot take) stops the sweep before any point
  runs: exit 2, nothing in the table;
* a sweep whose points failed exits 1 and prints the first reason.
"""

from __future__ import annotations

import json
import math

import pytest

from drillcosim.cosim.cli import main
from drillcosim.cosim.master.errors import UserError
from drillcosim.cosim.study import point as point_module
from drillcosim.cosim.study import sweep as sweep_module
from drillcosim.cosim.study.grid import loop_side
from drillcosim.cosim.study.sweep import execute_sweep, sweep_spec
from drillcosim.cosim.study.table import read_table

SCENE = "paper_closed_loop"


def test_points_carry_their_typed_configuration() -> None:
    spec = sweep_spec(SCENE, gains=[1e8, 1e9], delays=[0.0, 5e-4], stop_time=0.5,
                      engine="inprocess",
                      vary={"controller.lag_time_constant": [0.0, 1e-3], "gravity": [0.0, 9.81]})
    points = spec.points()
    opens = [p for p in points if p.kind == "open_loop"]
    closed = [p for p in points if p.kind == "closed_loop"]
    # references per plant-side value (gravity), not per controller-side one (the lag)
    assert len(opens) == 2 and len(closed) == 2 * 2 * 2 * 2
    assert loop_side("controller.lag_time_constant") and not loop_side("gravity")
    for p in closed:
        c, vary = p.config, dict(p.vary)
        assert c.controller.enabled and c.controller.params.gain == p.gain
        assert c.cosim.actuator_delay == p.delay and c.cosim.stop_time == 0.5
        assert c.controller.params.lag_time_constant == vary["controller.lag_time_constant"]
        assert c.scene.plant.gravity == vary["gravity"]
        assert c.controller.set_keys  # the law's keys the scene and the point set
    assert all(not p.config.controller.enabled for p in opens)
    keys = [p.key for p in points]
    assert len(set(keys)) == len(keys)
    # a closed-loop point finds the reference of its plant-side values
    from drillcosim.cosim.study.table import reference_key
    by_key = {p.key: p for p in opens}
    for p in closed:
        ref = by_key[reference_key(p.key)]
        assert dict(ref.vary) == {"gravity": dict(p.vary)["gravity"]}


def test_loop_points_keep_the_base_plant_and_equal_a_fresh_load(monkeypatch) -> None:
    """A point that changes only loop settings (delay, gain, the controllers' period) keeps
    the base configuration's plant (validated once per sweep) and is the configuration a fresh
    load of the same overrides gives; a plant-side value makes the plant anew."""
    from drillcosim.cosim.scenario import config as config_module

    base = config_module.load_config(SCENE, {"cosim.stop_time": 0.5})
    loop = {"cosim.actuator_delay": 5e-4, "controller.gain": 3e8, "cosim.step": 2.5e-4,
            "cosim.controller_sample_period": 5e-4, "controller.lag_time_constant": 1e-3}
    fresh = config_module.load_config(SCENE, {"cosim.stop_time": 0.5, **loop})
    made = []
    real = config_module.scene_from_dict
    monkeypatch.setattr(config_module, "scene_from_dict",
                        lambda *a, **k: made.append(1) or real(*a, **k))
    derived = config_module.derive_config(base, loop)
    assert not made and derived.scene is base.scene
    assert repr(derived) == repr(fresh) and derived.overrides == fresh.overrides
    # the strain controller switched off (the plant model's choice reads it), a plant key
    for over in ({"controller.enabled": False}, {"gravity": 0.0}):
        other = config_module.derive_config(base, over)
        assert made and repr(other) == repr(config_module.load_config(
            SCENE, {"cosim.stop_time": 0.5, **over}))
        made.clear()


def test_running_the_points_reads_no_scene_again(tmp_path, monkeypatch) -> None:
    spec = sweep_spec(SCENE, delays=[0.0], stop_time=0.05, engine="inprocess",
                      vary={"controller.gain": [1e8]}, options={"highpass": 0.0})

    def refuse(*args, **kwargs):
        raise AssertionError("a sweep point loaded its configuration again")

    monkeypatch.setattr(point_module, "load_config", refuse)
    out = execute_sweep(spec, tmp_path, workers=0, progress=False)
    assert out.n_errors == 0 and out.n_run == 2
    meta = json.loads((tmp_path / "sweep.json").read_text())
    assert meta["vary"] == [] and meta["components"]["controller"]["law"] == "proportional"


def test_bad_values_are_refused_when_planned() -> None:
    with pytest.raises(UserError, match=r"actuator_delay = -0.001 must be >= 0"):
        sweep_spec(SCENE, delays=[0.0, -1e-3], stop_time=0.5)
    with pytest.raises(UserError, match="controller.gain.*given twice"):
        sweep_spec(SCENE, gains=[1e9], vary={"controller.gain": [1e8]})
    with pytest.raises(UserError, match="unknown key 'gian'"):
        sweep_spec(SCENE, vary={"controller.gian": [1.0]})
    with pytest.raises(UserError, match="stop_time"):
        sweep_spec(SCENE, steps=[1e-4, 3.5e-4], stop_time=6.0)


def test_the_cli_plans_once_and_runs_the_plan(tmp_path, monkeypatch, capsys) -> None:
    calls = []
    real = sweep_module.sweep_spec

    def counted(*args, **kwargs):
        calls.append(args)
        return real(*args, **kwargs)

    monkeypatch.setattr(sweep_module, "sweep_spec", counted)
    code = main(["sweep", SCENE, "--engine", "inprocess", "--vary",
                 "cosim.controller_sample_period=2.5e-4,5e-4", "--stop-time", "0.05",
                 "--workers", "0", "--no-progress", "--out", str(tmp_path)])
    assert code == 0 and len(calls) == 1
    rows = read_table(tmp_path)
    assert sorted(r["varied"] for r in rows if r["kind"] == "closed_loop") == [
        '{"cosim.controller_sample_period": 0.00025}', '{"cosim.controller_sample_period": 0.0005}']
    # the map of a --vary sweep: one cell per closed-loop point
    from drillcosim.cosim.study.vary_maps import axis_value, plot_vary_map

    png = plot_vary_map([tmp_path], "cosim.controller_sample_period", "delay",
                        tmp_path / "map.png", metric="growth_rate")
    assert png.stat().st_size > 1000
    assert sorted(axis_value(r, "cosim.controller_sample_period") for r in rows
                  if r["kind"] == "closed_loop") == [2.5e-4, 5e-4]


def test_a_point_the_user_must_fix_stops_the_sweep_before_any_runs(tmp_path, capsys) -> None:
    """The project's own controller FMU given as a file is a foreign FMU: its parameters are
    checked against its modelDescription (``gain`` declares min 0)."""
    from drillcosim.cosim.scenario.scene_fmus import default_fmu_dir, ensure_recipes
    from drillcosim.fmu_src.build import REGISTRY

    fmu = ensure_recipes([r for r in REGISTRY if r.name == "StrainController"])[
        "StrainController"]
    common = ["sweep", SCENE, "--controller-fmu", str(fmu), "--stop-time", "0.05",
              "--workers", "0", "--no-progress"]
    for vary, words in (("controller.parameters.gian=1,2", "has no variable 'gian'"),
                        ("controller.parameters.gain=1e8,-5", "outside its declared range")):
        out = tmp_path / vary.split("=")[0]
        assert main([*common, "--vary", vary, "--out", str(out)]) == 2
        err = capsys.readouterr().err
        assert words in err and "Traceback" not in err
        assert not (out / "results.csv").exists() or read_table(out) == []
    assert default_fmu_dir().is_dir()


def test_failed_points_exit_1_with_the_first_reason(tmp_path, capsys) -> None:
    """A NaN lag passes the interface check (the FMU judges NaN) and is refused by the FMU at
    initialization: every point is an error row, the sweep exits 1 naming the reason."""
    from drillcosim.cosim.scenario.scene_fmus import ensure_recipes
    from drillcosim.fmu_src.build import REGISTRY

    fmu = ensure_recipes([r for r in REGISTRY if r.name == "StrainController"])[
        "StrainController"]
    code = main(["sweep", SCENE, "--controller-fmu", str(fmu), "--stop-time", "0.05",
                 "--set", "controller.parameters.lag_time_constant=nan", "--gain", "1e8,1e9",
                 "--workers", "0", "--no-progress", "--out", str(tmp_path)])
    err = capsys.readouterr().err
    assert code == 1
    assert "point(s) failed; the first" in err and "lag_time_constant" in err
    rows = read_table(tmp_path)
    assert {r["status"] for r in rows if r["kind"] == "closed_loop"} == {"error"}
    assert all(math.isnan(r["growth_rate"]) for r in rows if r["status"] == "error")


def test_a_top_drive_sweep_over_timing_keys_enables_the_top_drive() -> None:
    """No gain axis, no controller axis: the closed-loop points enable the scene's controller
    (here the top drive's); a top-drive sweep has no open-loop references (the drive is the
    only source of torque)."""
    spec = sweep_spec("stick_slip_soft_torque", delays=[0.0, 0.05], stop_time=0.5,
                      engine="inprocess", vary={"cosim.controller_sample_period": [1e-3, 1e-2]})
    assert spec.table == "top_drive_controller" and not spec.open_loop
    points = spec.points()
    assert len(points) == 4 and {p.kind for p in points} == {"closed_loop"}
    for p in points:
        assert p.config.instances == ("plant", "top_drive_controller")
        assert p.config.cosim.controller_sample_period == dict(p.vary)[
            "cosim.controller_sample_period"]
