"""``drillcosim run`` end to end on short runs of the real plant + controller FMUs.

Files (results.csv, summary.json, PNGs), exit codes (0 ok, 1 stopped early, 2 bad
input) and that a failing run never damages the files of an earlier one.
"""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest

import drillcosim
from drillcosim.cosim.cli import main
from drillcosim.cosim.master.errors import CosimError
from drillcosim.cosim.scenario.build import build_system
from drillcosim.cosim.scenario.config import load_config
from drillcosim.cosim.scenario.scene_fmus import ensure_recipes, recipe_named
from drillcosim.cosim.scenario.simulate import simulate
from drillcosim.cosim.scenario.summary import SUMMARY_KEYS

PNGS = ("orbit.png", "deflection_contact.png", "actuators.png")
#: Fixed co-simulation settings, so the tests do not follow tuning of the scene files.
COSIM = ["--set", "cosim.step=1e-3", "--set", 'cosim.algorithm="jacobi"',
         "--no-progress"]


@pytest.fixture(scope="module")
def fmu_dir() -> Path:
    """The plant and controller FMUs the CLI finds (built when stale): a broken build is an error
    of every test here, not a skip."""
    paths = ensure_recipes([recipe_named(n) for n in ("DrillstringPlant", "StrainController")])
    return paths["DrillstringPlant"].parent


@pytest.fixture(scope="module")
def good_run(fmu_dir, tmp_path_factory) -> tuple[Path, int]:
    out = tmp_path_factory.mktemp("run") / "closed"
    code = main(["run", "paper_closed_loop", "--stop-time", "0.2", "--out", str(out), *COSIM])
    return out, code


def _snapshot(folder: Path) -> dict[str, bytes]:
    return {p.name: p.read_bytes() for p in sorted(folder.iterdir()) if p.is_file()}


def test_run_writes_results_summary_and_plots(good_run) -> None:
    out, code = good_run
    assert code == 0
    header = (out / "results.csv").read_text().splitlines()[0].split(",")
    assert header[0] == "time" and "plant.body11_radial_deflection" in header
    assert "controller.actuator1_force_C" in header and "plant.actuator2_power" in header
    data = np.loadtxt(out / "results.csv", delimiter=",", skiprows=1)
    assert data.shape == (201, len(header))
    np.testing.assert_allclose(data[:, 0], np.arange(201) * 1e-3, atol=1e-12)
    assert np.all(np.isfinite(data))
    for name in PNGS:
        assert (out / name).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n", name
    assert not list(out.glob(".*")), "temporary files left behind"


def test_summary_has_the_documented_keys_and_units(good_run) -> None:
    out, _ = good_run
    s = json.loads((out / "summary.json").read_text())
    assert set(SUMMARY_KEYS) <= set(s)
    assert s["scene"] == "paper_closed_loop" and s["completed"] and s["diverged"] is None
    assert s["end_time_s"] == pytest.approx(0.2) and s["step_s"] == 1e-3
    assert s["wall_time_s"] > 0 and s["real_time_factor"] > 0
    assert s["steady_window_s"] == pytest.approx([0.2 * 2 / 3, 0.2])
    assert s["spans"]["body11"]["span"] == "long" and s["spans"]["body26"]["span"] == "short"
    for span in s["spans"].values():
        assert set(span) >= {"span_length_m", "peak_radial_deflection_m",
                             "steady_radial_deflection_mean_m",
                             "steady_radial_deflection_std_m", "peak_contact_force_N",
                             "contact_events", "contact_time_s"}
        assert 0 <= span["peak_radial_deflection_m"] < 0.02  # no contact in 0.2 s
        assert span["contact_events"] == 0 and span["contact_time_s"] == 0.0
    data = np.loadtxt(out / "results.csv", delimiter=",", skiprows=1)
    header = (out / "results.csv").read_text().splitlines()[0].split(",")
    r11 = data[:, header.index("plant.body11_radial_deflection")]
    assert s["spans"]["body11"]["peak_radial_deflection_m"] == pytest.approx(np.max(r11))
    for site in ("site1", "site2"):
        a = s["actuators"][site]
        assert set(a) >= {"peak_force_N", "peak_force_C_N", "peak_force_E_N", "peak_power_W",
                          "peak_abs_power_W", "steady_mean_power_W"}
    f1 = np.abs(data[:, [header.index("controller.actuator1_force_C"),
                         header.index("controller.actuator1_force_E")]])
    assert s["actuators"]["site1"]["peak_force_N"] == pytest.approx(f1.max())
    assert s["controller"]["gain"] == 1e9 and s["cosim"]["step"] == 1e-3


def test_bad_input_exits_2_in_one_line_and_keeps_files(good_run, capsys) -> None:
    out, _ = good_run
    before = _snapshot(out)
    capsys.readouterr()
    for argv in (["--set", "cosim.stepp=1"], ["--set", "controller.gian=1"],
                 ["--set", "nonsense"], ["--stop-time", "-1"], ["--delay", "-0.1"]):
        code = main(["run", "paper_closed_loop", "--out", str(out), *COSIM, *argv])
        err = capsys.readouterr().err
        assert code == 2, argv
        assert err.count("\n") == 1 and "Traceback" not in err, err
    assert main(["run", "no_such_scene", "--out", str(out), "--no-progress"]) == 2
    assert "not found" in capsys.readouterr().err
    assert _snapshot(out) == before


def test_failure_before_the_first_step_keeps_earlier_files(good_run, fmu_dir, capsys,
                                                           caplog) -> None:
    out, _ = good_run
    before = _snapshot(out)
    ss = build_system(load_config("paper_closed_loop", {"cosim.step": 1e-3}), "fmu",
                      fmu_dir=fmu_dir)
    plant = ss.system.fmu("plant")
    bad = dataclasses.replace(plant, parameters={**plant.parameters, "pipe.length": -1.0})
    ss = dataclasses.replace(ss, system=dataclasses.replace(
        ss.system, fmus=[bad, ss.system.fmu("controller")]))
    with pytest.raises(CosimError) as info, \
            caplog.at_level("DEBUG", "drillcosim.cosim.master.fmi_log"):
        simulate(ss, 0.1, csv_path=out / "results.csv")
    err = info.value
    # the plant FMU (native wrapper) refuses the parameter at initialization with fmi2Error;
    # the error names FMU and call and ends with the FMU's own message naming the parameter,
    # received through the FMI logger callback (nothing is printed)
    assert (err.fmu_name, err.call, err.status) == ("plant", "fmi2ExitInitializationMode", 3)
    assert "pipe.length = -1.0 is out of range" in err.fmu_message
    assert str(err).endswith(err.fmu_message) and "\n" not in str(err), str(err)
    assert capsys.readouterr().out == ""
    logged = [r.getMessage() for r in caplog.records]
    assert any("pipe.length = -1.0 is out of range" in m for m in logged), logged
    # FMI 2.0: no fmi2Terminate after fmi2Error (the wrapper would refuse it, logging the call)
    assert not any("fmi2Terminate" in m for m in logged), logged
    assert _snapshot(out) == before


def test_bad_plant_parameter_from_the_cli_exits_2_naming_it(good_run, capsys) -> None:
    out, _ = good_run
    before = _snapshot(out)
    capsys.readouterr()
    code = main(["run", "paper_closed_loop", "--out", str(out), *COSIM,
                 "--set", "contact.stiffness=-1"])
    err = capsys.readouterr().err
    assert code == 2
    assert err.count("\n") == 1 and "Traceback" not in err, err
    assert "contact.stiffness = -1 is out of range" in err, err
    assert _snapshot(out) == before


def test_parameter_refused_by_the_fmu_at_initialization_exits_2_naming_it(
        good_run, fmu_dir, capsys, monkeypatch) -> None:
    """The FMU's own check (not the scene's) rejects a parameter: one line, exit 2."""
    import drillcosim.api as api_module
    out, _ = good_run
    before = _snapshot(out)
    real = api_module.build_system

    def with_bad_plant_parameter(*args, **kwargs):
        ss = real(*args, **kwargs)
        plant = ss.system.fmu("plant")
        bad = dataclasses.replace(plant, parameters={**plant.parameters,
                                                     "contact.stiffness": -1.0})
        return dataclasses.replace(ss, system=dataclasses.replace(
            ss.system, fmus=[bad, ss.system.fmu("controller")]))

    monkeypatch.setattr(api_module, "build_system", with_bad_plant_parameter)
    capsys.readouterr()
    code = main(["run", "paper_closed_loop", "--out", str(out), *COSIM])
    err = capsys.readouterr().err
    assert code == 2
    assert err.count("\n") == 1 and "Traceback" not in err, err
    assert err.startswith("drillcosim run: error: FMU 'plant': fmi2ExitInitializationMode "
                          "failed"), err
    assert "contact.stiffness = -1.0 is out of range" in err, err
    assert _snapshot(out) == before


def test_diverging_run_exits_1_and_keeps_partial_results(fmu_dir, tmp_path, capsys) -> None:
    out = tmp_path / "diverging"
    # A huge gain with a 5 ms actuator delay: the loop blows up within a fraction of a second
    # and the plant discards the step (lateral deflection beyond its validity range).
    code = main(["run", "paper_closed_loop", "--stop-time", "1.0", "--gain", "1e14",
                 "--delay", "0.005", "--out", str(out), "--no-plots", *COSIM])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 1
    assert err and err[-1].startswith("run stopped at t = "), err
    s = json.loads((out / "summary.json").read_text())
    assert not s["completed"] and s["diverged"]["time_s"] < 1.0
    assert s["diverged"]["message"] and "\n" not in s["diverged"]["message"]
    data = np.loadtxt(out / "results.csv", delimiter=",", skiprows=1, ndmin=2)
    assert 1 < len(data) and data[-1, 0] == pytest.approx(s["end_time_s"])


def test_top_drive_controller_key_set_from_the_cli_reaches_that_controller(tmp_path,
                                                                          capsys) -> None:
    """``drillcosim run stick_slip_soft_torque --set top_drive_controller.p_gain=150``: once
    passed to the plant FMU ("plant ... has no variable 'top_drive_controller.p_gain'", exit
    2); the key belongs to the top-drive controller, and a lower P gain lets the bit stick
    longer in the same time (the stick-slip study's direction, docs/physics.md section 6)."""
    runs = {}
    for p_gain in (150, 1000):
        out = tmp_path / f"p{p_gain}"
        code = main(["run", "stick_slip_soft_torque", "--set",
                     f"top_drive_controller.p_gain={p_gain}", "--stop-time", "20",
                     "--out", str(out), "--no-plots", "--no-progress"])
        assert code == 0, capsys.readouterr().err
        runs[p_gain] = json.loads((out / "summary.json").read_text())
    assert runs[150]["top_drive_controller"]["p_gain"] == 150.0
    assert runs[1000]["top_drive_controller"]["p_gain"] == 1000.0
    severity = {p: s["torsional"]["stick_slip_severity"] for p, s in runs.items()}
    assert severity[150] > 10 * severity[1000], severity


def test_the_api_and_the_cli_give_identical_numbers(good_run) -> None:
    """``drillcosim run`` is a thin layer on ``drillcosim.simulate``: the same run, the same
    bits (results.csv holds 17 significant digits: the doubles themselves)."""
    out, _ = good_run
    res = drillcosim.simulate("paper_closed_loop", stop_time=0.2,
                              overrides={"cosim.step": 1e-3, "cosim.algorithm": "jacobi"})
    frame = res.to_pandas()
    header = (out / "results.csv").read_text().splitlines()[0].split(",")
    data = np.loadtxt(out / "results.csv", delimiter=",", skiprows=1)
    assert header == ["time", *frame.columns]
    np.testing.assert_array_equal(data[:, 0], frame.index.to_numpy())
    for j, name in enumerate(header[1:], start=1):
        np.testing.assert_array_equal(data[:, j], frame[name].to_numpy(), err_msg=name)
    summary = json.loads((out / "summary.json").read_text())
    assert summary["spans"] == json.loads(json.dumps(res.summary["spans"]))
    assert res.units["plant.body11_radial_deflection"] == "m"
    assert res.units["controller.actuator1_force_C"] == "N" and res.units["time"] == "s"
