"""The linear prediction of a sweep: fast (frequency-response critical gains, a linearization
cached by content), the same numbers as the straightforward computation, and compared with each
verdict in the table and on the maps."""

from __future__ import annotations

import math

import numpy as np
import pytest
import scipy.linalg

from drillcosim.cosim.scenario.config import load_config
from drillcosim.cosim.study.boundary import (
    StepResponse,
    critical_gains,
    frequency_critical_gain,
    loop_timing,
)
from drillcosim.cosim.study.stability import (
    LoopModel,
    closed_loop_matrix,
    discretize,
    loop_weights,
    reduce_loop,
)

SCENE = "paper_closed_loop"


@pytest.fixture(scope="module")
def drill() -> LoopModel:
    return LoopModel.from_scene(SCENE)


# --- the frequency response ------------------------------------------------------------------
@pytest.mark.parametrize("method", ["zoh", "rk4"])
def test_the_modal_transfer_matrix_is_the_discrete_plants(drill, method) -> None:
    """P(z) = C (zI - Ad)^-1 Bd from the modes equals the solve with discretize's matrices."""
    lm = LoopModel(drill.A, drill.B, drill.C, method=method, max_step=1e-4)
    h = 2.5e-4
    Ad, Bd = discretize(lm.A, lm.B, h, method, 1e-4)
    response = StepResponse(lm, h)
    theta = np.array([0.0, 0.02, 0.3, 2.0, math.pi])
    for th, P in zip(theta, response.transfer(theta)):
        z = np.exp(1j * th)
        ref = lm.C @ np.linalg.solve(z * np.eye(len(Ad)) - Ad, Bd)
        assert np.max(np.abs(P - ref)) <= 1e-8 * np.max(np.abs(ref)), th


@pytest.mark.parametrize("settings,step,delays", [
    ({}, 2.5e-4, [0.0, 1e-4, 5e-4]),
    ({}, 1e-4, [3e-4]),
    ({"algorithm": "jacobi", "coupling": "linear", "sensor_delay": 3e-4}, 2.5e-4,
     [0.0, 1.3e-4]),
    ({"lag_time_constant": 1e-3}, 2.5e-4, [0.0, 2e-4]),
    ({"method": "rk4", "max_step": 1e-4}, 2.5e-4, [0.0, 1e-4]),
])
def test_frequency_critical_gains_equal_the_bisection(drill, settings, step, delays) -> None:
    """The crossing from the frequency response lies inside the scan-and-bisection's bracket
    (rtol 1e-5) of the closed-loop matrix, for Gauss-Seidel and Jacobi timing, linear
    coupling, fractional and sensor delays, a lagged controller and the RK4 plant map; and
    critical_gains returns it."""
    from threadpoolctl import threadpool_limits

    lm = LoopModel(drill.A, drill.B, drill.C, dropped=drill.dropped, **settings)
    response = StepResponse(lm, step)
    fast = critical_gains(lm, step, delays, gain_min=1e5, gain_max=1e12, rtol=1e-3)
    for d, k_fast in zip(delays, fast):
        exact = frequency_critical_gain(response, *loop_timing(lm, d, step))
        with threadpool_limits(1):
            k_bisect = lm.critical_gain(step, d, gain_min=1e7, gain_max=1e11, per_decade=1,
                                        rtol=1e-5)
        assert exact == pytest.approx(k_bisect, rel=1e-5), d
        assert k_fast == exact, d


def test_a_marginal_open_loop_falls_back_to_the_bisection() -> None:
    """An integrator plant (pole on the unit circle): the Levin & May bound, by the bisection."""
    lm = LoopModel(np.zeros((1, 1)), np.ones((1, 1)), -np.ones((1, 1)))
    H = 0.01
    got = critical_gains(lm, H, [0.0, 2 * H], gain_min=1e-2, gain_max=1e4, rtol=1e-9)
    bound = [2.0, 2.0 * math.cos(2 * math.pi / 5)]
    assert [k * H for k in got] == pytest.approx(bound, rel=1e-7)


# --- same numbers -----------------------------------------------------------------------------
def _fresh_rates(points: list[tuple[float, float]], step: float) -> dict:
    """Growth rates computed as before this change: linearize, reduce, discretize, close the
    loop, eigenvalues; nothing cached."""
    from threadpoolctl import threadpool_limits

    from drillcosim.analysis.linearize import linearize

    config = load_config(SCENE)
    lin = linearize(config.scene.plant, "full3d")
    A, B, C, dropped = reduce_loop(lin.A, lin.B, lin.C)
    st = config.cosim
    Ad, Bd = discretize(A, B, step)
    out = {}
    for gain, delay in points:
        w = loop_weights(delay / step, st.sensor_delay / step, st.algorithm, st.order,
                         st.coupling)
        with threadpool_limits(1):
            ev = scipy.linalg.eigvals(closed_loop_matrix(Ad, Bd, C, gain, w))
        rho = float(np.max(np.abs(ev)))
        if dropped.size:
            rho = max(rho, float(np.max(np.abs(np.exp(dropped * step)))))
        out[(gain, delay)] = math.log(rho) / step
    return out


def test_point_predictions_equal_a_fresh_linearization() -> None:
    """The 12 points of gains 1e6, 1e8, 1e9 x delays 0-200 us: the sweep's predicted growth
    rates (cached linearization, the loop model kept per process) equal the uncached
    computation to 1e-9 1/s."""
    from drillcosim.cosim.study.point import point_config
    from drillcosim.cosim.study.prediction import point_prediction

    points = [(g, d) for g in (1e6, 1e8, 1e9) for d in (0.0, 5e-5, 1e-4, 2e-4)]
    fresh = _fresh_rates(points, 2.5e-4)
    for gain, delay in points:
        rate, note = point_prediction(point_config(SCENE, gain, delay, 2.5e-4, 6.0, False, None))
        assert note == ""
        assert rate == pytest.approx(fresh[(gain, delay)], abs=1e-9), (gain, delay)
    # the slow-growth point: gain 1e9, delay 100 us grows slowly
    assert 0.0 < fresh[(1e9, 1e-4)] < 0.5


def test_the_linearization_is_cached_by_content(tmp_path, monkeypatch) -> None:
    """First call computes and stores; the second reads the same arrays bit for bit; another
    parameter is another entry; a damaged file is computed again."""
    from drillcosim.cosim.study.stability import coupled_plant

    monkeypatch.setenv("DRILLCOSIM_CACHE", str(tmp_path))
    scene = load_config(SCENE).scene
    first = coupled_plant(scene)
    files = sorted((tmp_path / "loop_models").glob("*.npz"))
    assert len(files) == 1
    again = coupled_plant(scene)
    for a, b in zip(first[:4], again[:4]):
        assert a.tobytes() == b.tobytes()
    assert first[4] == again[4]
    files[0].write_bytes(files[0].read_bytes()[:100])           # cut short
    repaired = coupled_plant(scene)
    assert repaired[0].tobytes() == first[0].tobytes()
    other = load_config(SCENE, {"contact.clearance": 0.03}).scene
    assert other.plant != scene.plant
    coupled_plant(other)
    assert len(list((tmp_path / "loop_models").glob("*.npz"))) == 2


def test_the_high_pass_equals_scipys() -> None:
    """The sweep's compiled biquad cascade and cached Butterworth design equal scipy.signal's
    sosfilt and butter bit for bit."""
    from scipy.signal import butter
    from scipy.signal import sosfilt as scipy_sosfilt

    from drillcosim.cosim.study.highpass import butter_highpass, sosfilt

    rng = np.random.default_rng(3)
    x = rng.standard_normal(20001) * np.exp(np.linspace(0.0, 4.0, 20001))
    for cutoff in (0.0318, 0.2, 0.6):
        sos = butter_highpass(4, cutoff)
        assert np.array_equal(sos, butter(4, cutoff, "highpass", output="sos"))
        assert np.array_equal(sosfilt(sos, x), scipy_sosfilt(sos, x))


# --- verdict against prediction -----------------------------------------------------------------
def _row(**kw):
    row = {"kind": "closed_loop", "status": "ok", "end_time": 6.0, "min_stop_time": 4.0,
           "contact_time": 0.0, "predicted_growth_rate": math.nan, "prediction_note": ""}
    row.update(kw)
    return row


def test_agreement_rules() -> None:
    from drillcosim.cosim.study.verdict import GROWTH_MARGIN, compare_with_prediction

    assert compare_with_prediction(_row(predicted_growth_rate=-0.2), "stable", 0.0) == (1.0, "")
    assert compare_with_prediction(_row(predicted_growth_rate=3.0), "unstable", 2.9)[0] == 1.0
    agrees, note = compare_with_prediction(_row(predicted_growth_rate=0.39), "stable", 0.1)
    assert agrees == 0.0 and note.startswith("below the margin") and "+0.39" in note
    assert f"{GROWTH_MARGIN:g} 1/s" in note
    agrees, note = compare_with_prediction(_row(predicted_growth_rate=-0.2, contact_time=1.5,
                                                status="diverged"), "unstable", math.nan)
    assert agrees == 0.0 and note.startswith("wall contact") and "1.5 s" in note
    agrees, note = compare_with_prediction(_row(predicted_growth_rate=-0.2), "unstable", 2.0)
    assert agrees == 0.0 and note.startswith("unexplained")
    agrees, note = compare_with_prediction(_row(predicted_growth_rate=3.0, end_time=1.0),
                                           "undecided", math.nan)
    assert math.isnan(agrees) and note.startswith("too short to judge")
    agrees, note = compare_with_prediction(
        _row(prediction_note="prediction unavailable: a state-space controller"), "stable", 0.0)
    assert math.isnan(agrees) and note.endswith("a state-space controller")
    assert math.isnan(compare_with_prediction(_row(predicted_growth_rate=1.0), "error",
                                              math.nan)[0])


def test_benefit_needs_a_built_up_reference() -> None:
    from drillcosim.cosim.study.verdict import BENEFIT_RISE, benefit_note

    ref = {"status": "ok", "rms_rise_long": 4.53, "rms_rise_short": 1.2}
    note = benefit_note(ref)
    assert note.startswith("too short to judge the benefit") and "4.53x (long span)" in note
    assert "short span" not in note and f"> {BENEFIT_RISE:g}x" in note
    assert benefit_note({**ref, "rms_rise_long": 0.9}) == ""
    assert benefit_note(None) == "no completed open-loop reference"


def test_the_maps_state_the_rule_and_mark_what_differs(tmp_path) -> None:
    """A table like that 12-point sweep's: the legend says the rule in words; the point the
    prediction calls slowly unstable but the run stable gets a ring; a benefit of a reference
    still building up is grey; the growth figure draws the predicted curves."""
    from drillcosim.cosim.study.maps import DIFFERS, map_figures
    from drillcosim.cosim.study.table import ResultTable

    table = ResultTable(tmp_path)
    common = {"scene": SCENE, "engine": "inprocess", "step": 2.5e-4, "stop_time": 6.0,
              "status": "ok", "end_time": 6.0, "min_stop_time": 4.0, "growth_noise": 0.05,
              "rms_long": 0.001, "rms_short": 0.001, "contact_time": 0.0}
    key = "|".join((SCENE, "inprocess", "{}", "{:.12g}", "{:.12g}", "0.00025", "6"))
    table.append({**common, "key": key.format("open_loop", 0.0, 0.0), "kind": "open_loop",
                  "gain": 0.0, "delay": 0.0, "growth_rate": 0.7, "rms_rise_long": 4.5,
                  "rms_rise_short": 1.9})
    for gain, delay, growth, pred in ((1e8, 0.0, 0.7, -0.25), (1e9, 1e-4, 0.8, 0.39),
                                      (1e9, 2e-4, 1.6, 1.2)):
        table.append({**common, "key": key.format("closed_loop", gain, delay),
                      "kind": "closed_loop", "gain": gain, "delay": delay,
                      "growth_rate": growth, "predicted_growth_rate": pred})
    rows = {(r["gain"], r["delay"]): r for r in table.rows}
    assert rows[(1e9, 1e-4)]["verdict"] == "stable"
    assert rows[(1e9, 1e-4)]["agrees_with_prediction"] == 0.0
    assert rows[(1e9, 2e-4)]["agrees_with_prediction"] == 1.0
    assert rows[(1e8, 0.0)]["benefit_note"].startswith("too short to judge the benefit")
    figures = map_figures(tmp_path)
    stability = figures["stability_map"]
    legend = [t.get_text() for t in stability.legends[0].get_texts()]
    assert "stable: no envelope growth above 0.5 1/s (over open loop) within 6 s" in legend
    assert any(t.startswith("differs from the prediction: predicted growth below") for t in
               legend)
    ring = [c for c in stability.axes[0].collections
            if np.array_equal(c.get_edgecolor()[0][:3], _rgb(DIFFERS["below the margin"][0]))]
    assert len(ring) == 1 and np.allclose(ring[0].get_offsets(), [[0.1, 1e9]])
    benefit = figures["benefit_map"]
    assert "too short to judge the benefit" in benefit._suptitle.get_text()
    grey = [c for c in benefit.axes[0].collections if c.get_label().startswith("not judged")]
    assert len(grey) == 1 and len(grey[0].get_offsets()) == 2
    growth = figures["growth_rate"].axes[0]
    curves = [line for line in growth.lines if len(line.get_xdata()) > 5]
    assert len(curves) == 2                             # one predicted line per gain
    assert growth.get_legend() is not None


def _rgb(color: str):
    from matplotlib.colors import to_rgb

    return np.array(to_rgb(color))
