"""Controller designs on the linearized plant (cosim/study/control_design): the closed loop of
a state-space controller (the P law equals the stability module's LoopModel), the LQR gain
against scipy's DARE, the Kalman filter against scipy's filter DARE, the separation principle,
the Smith predictor's nominal loop = the undelayed P law, the closed-loop matrix against a
time-stepped loop of the law, and the design command."""

from __future__ import annotations

import math

import numpy as np
import pytest
import scipy.linalg

from drillcosim.controller.state_space import Signal, StateSpaceController, StateSpaceParams
from drillcosim.cosim.cli import main
from drillcosim.cosim.study.control_design import (
    LoopPlant,
    LqgWeights,
    closed_loop_matrix,
    design_on_plant,
    growth_rate,
    loop_spectral_radius,
)
from drillcosim.cosim.study.control_design.lqg import lqg_gains
from drillcosim.cosim.study.control_design.predictor import gain_matrix
from drillcosim.cosim.study.stability import LoopModel

SCENE = "paper_calibrated_closed_loop"
H = 2.5e-4


@pytest.fixture(scope="module")
def plant() -> LoopPlant:
    return LoopPlant.from_scene(SCENE, joints=(11, 26))


def p_law(plant: LoopPlant, gain: float) -> StateSpaceParams:
    s, f = plant.signals
    return StateSpaceParams([], [], [], gain_matrix(gain, plant.n_sites),
                            [Signal(x) for x in s], [Signal(x, "N") for x in f], H)


@pytest.mark.parametrize("gain, delay", [(1e9, 0.0), (1e9, 1.3e-4), (1e9, 2.5e-4), (1e8, 5e-4),
                                         (3e8, 1.1e-3)])
def test_p_law_closed_loop_equals_loop_model(plant, gain, delay):
    lm = LoopModel(plant.A, plant.B, plant.C, algorithm=plant.algorithm, order=plant.order,
                   coupling=plant.coupling, dropped=plant.dropped)
    assert growth_rate(plant, p_law(plant, gain), delay) == pytest.approx(
        lm.growth_rate(gain, delay, H), rel=1e-9, abs=1e-9)


@pytest.fixture(scope="module")
def lqg(plant):
    return lqg_gains(plant, H, 5e-4, LqgWeights())


def test_lqr_gain_is_the_dare_solution(lqg):
    g = lqg
    S = scipy.linalg.solve_discrete_are(g.Az, g.Bz, g.Q, g.R)
    K = np.linalg.solve(g.R + g.Bz.T @ S @ g.Bz, g.Bz.T @ S @ g.Az)
    np.testing.assert_allclose(g.K, K, rtol=1e-6, atol=1e-9 * np.abs(K).max())
    np.testing.assert_allclose(g.S, S, rtol=1e-6, atol=1e-9 * np.abs(S).max())
    # and the Riccati equation itself holds (independent of any solver: slycot's SB02MD,
    # python-control's other backend, leaves a residual of 7e-7 here)
    A, B = g.Az, g.Bz
    Kg = np.linalg.solve(g.R + B.T @ g.S @ B, B.T @ g.S @ A)
    residual = A.T @ g.S @ A - g.S - A.T @ g.S @ B @ Kg + g.Q
    assert np.abs(residual).max() <= 1e-10 * np.abs(g.S).max()


def test_kalman_filter_is_the_filter_dare_solution(lqg):
    g = lqg
    P = scipy.linalg.solve_discrete_are(g.Az.T, g.Cz.T, g.Gz @ g.W @ g.Gz.T, g.V)
    np.testing.assert_allclose(g.P, P, rtol=1e-6, atol=1e-9 * np.abs(P).max())
    np.testing.assert_allclose(g.L, g.Az @ g.M, rtol=1e-6, atol=1e-9 * np.abs(g.L).max())
    # the delay line is known exactly: the filter never corrects it
    n = g.Az.shape[0] - 2 * 4          # 0.5 ms = 2 steps x 4 forces at the end of the state
    assert np.abs(g.M[n:]).max() <= 1e-9 * np.abs(g.M).max()


def test_lqg_closed_loop_separates(plant, lqg):
    """On the design plant the LQG loop's eigenvalues are the regulator's and the filter's."""
    d = design_on_plant("lqg", plant, H, 5e-4, max_frequency=math.inf)
    rho = loop_spectral_radius(plant, d.controller, 5e-4)
    expect = max(np.abs(lqg.E_lqr).max(), np.abs(lqg.E_kf).max(),
                 np.abs(np.exp(plant.dropped * H)).max())
    assert rho == pytest.approx(expect, abs=1e-9)
    assert d.stable and d.growth_rate == pytest.approx(math.log(expect) / H, abs=1e-3)
    assert d.controller.n_states == plant.A.shape[0] + 2 * 4     # plant + 2 steps x 4 forces


def test_predictor_loop_is_the_undelayed_p_law(plant):
    """The Smith predictor at 0.5 ms and gain 1e9, where the P law diverges (+6 1/s), has the
    undelayed P loop's growth rate; a predictor for the wrong delay does not."""
    lm = LoopModel(plant.A, plant.B, plant.C, algorithm=plant.algorithm, order=plant.order,
                   dropped=plant.dropped)
    assert lm.growth_rate(1e9, 5e-4, H) > 5
    d = design_on_plant("predictor", plant, H, 5e-4, gain=1e9, max_frequency=math.inf)
    assert d.growth_rate == pytest.approx(lm.growth_rate(1e9, 0.0, H), abs=1e-6)
    assert growth_rate(plant, d.controller, 7.5e-4) > 1     # designed for 0.5 ms, run at 0.75


def test_truncation_keeps_the_modes_below_the_cut(plant):
    """The truncated plant's eigenvalues are the full plant's below the cut (scipy eigvals of
    both), and its transfer function from forces to strains at 20 rad/s (the rotary speed)
    is the full plant's to 1 %: the dropped modes are the stiff ones above the gap."""
    full = np.linalg.eigvals(plant.A)
    small = plant.truncated(1000.0)
    kept = np.sort_complex(full[np.abs(full) <= 1000.0])
    np.testing.assert_allclose(np.sort_complex(np.linalg.eigvals(small.A)), kept,
                               rtol=1e-9, atol=1e-9)
    assert small.A.shape[0] == kept.size < plant.A.shape[0]
    s = 20j

    def tf(p):
        return p.C @ np.linalg.solve(s * np.eye(p.A.shape[0]) - p.A, p.B)

    G, Gs = tf(plant), tf(small)
    assert np.abs(Gs - G).max() <= 1e-2 * np.abs(G).max()


@pytest.mark.parametrize("kind, gain", [("lqg", None), ("predictor", 1e9)])
def test_truncated_design_judged_on_the_full_plant(plant, kind, gain):
    """A design on the truncated model (the default) has, with the full plant, the closed-loop
    growth the design model predicts; cut below the bending modes, it does not."""
    kw = {"gain": gain} if gain else {}
    d = design_on_plant(kind, plant, H, 5e-4, **kw)
    assert d.design_states == 112 and d.stable
    assert d.growth_rate == pytest.approx(d.design_growth_rate, abs=2e-3)
    assert d.growth_rate == pytest.approx(growth_rate(plant, d.controller, 5e-4), abs=1e-12)
    worse = design_on_plant(kind, plant, H, 5e-4, max_frequency=100.0, **kw)
    assert worse.design_growth_rate < 0 < worse.growth_rate


@pytest.mark.parametrize("kind, delay", [("lqg", 3e-4), ("predictor", 5e-4)])
def test_closed_loop_matrix_is_the_stepped_loop(plant, kind, delay):
    """The law (StateSpaceController.step) stepped against the sampled plant with the delay as
    the master's linear interpolation of past outputs equals powers of the closed-loop matrix."""
    d = design_on_plant(kind, plant, H, 0.0 if kind == "lqg" else delay, gain=1e9)
    T = closed_loop_matrix(plant, d.controller, delay)
    Ad, Bd = plant.discrete(H)
    law = StateSpaceController(d.controller)
    rng = np.random.default_rng(0)
    x = rng.normal(size=Ad.shape[0]) * 1e-6
    n_back, f = int(delay / H + 1e-9), delay / H - int(delay / H + 1e-9)
    history = [np.zeros(Bd.shape[1])] * (n_back + 2)
    z = np.concatenate([x, np.zeros(T.shape[0] - x.size)])
    for k in range(60):
        g = law.step(k * H, H, plant.C @ x)
        history = [g] + history[:-1]
        u = (1 - f) * history[n_back] + f * history[n_back + 1]     # order: controller first
        x = Ad @ x + Bd @ u
        z = T @ z
        np.testing.assert_allclose(z[:x.size], x, rtol=0, atol=1e-9 * np.abs(x).max())


def test_design_command(tmp_path, capsys):
    out = tmp_path / "ctl.toml"
    assert main(["design", "predictor", SCENE, "--sites", "1", "--delay", "5e-4", "--gain",
                 "1e9", "--out", str(out)]) == 0
    text = out.read_text()
    assert 'kind = "state_space"' in text and "joints = [11, 26]" in text
    assert "actuator_delay = 0.0005" in text and 'matrices = "ctl.json"' in text
    from drillcosim.controller.state_space import load_state_space

    c = load_state_space(tmp_path / "ctl.json")
    assert c.input_names == ("strain1_C", "strain1_E", "strain2_C", "strain2_E")
    assert "stable" in capsys.readouterr().out
    assert main(["design", "lqg", SCENE, "--force-scale", "0", "--out", str(out)]) == 2
    assert "force_scale = 0.0; allowed" in capsys.readouterr().err


@pytest.mark.parametrize("argv, message", [
    (["design", "lqg", SCENE, "--delay=-1e-3", "--out", "x.toml"], "delay = -0.001 s; allowed"),
    (["design", "predictor", SCENE, "--out", "x.txt"], "ending in .toml"),
    (["design", "lqg", "--out", "x.toml"], "give SCENE and --out"),
    (["design", "compare", SCENE], "takes no SCENE"),
    (["design", "lqg", "no_such_scene", "--out", "x.toml"], "no_such_scene"),
])
def test_bad_design_input_is_one_line(tmp_path, monkeypatch, capsys, argv, message):
    """Exit code 2, one line on stderr naming the parameter, no traceback, nothing written."""
    monkeypatch.chdir(tmp_path)
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert message in err and "Traceback" not in err and len(err.strip().splitlines()) == 1
    assert list(tmp_path.iterdir()) == []


def test_a_non_stabilizable_design_says_so(plant, monkeypatch):
    """python-control's LinAlgError of a Riccati equation without a stabilizing solution becomes
    one line naming the sites (this plant is stabilizable from every site, so the solver's
    failure is imitated)."""
    import control

    def fail(*args, **kwargs):
        raise np.linalg.LinAlgError("Failed to find a finite solution.")

    from drillcosim.cosim.master.errors import UserError

    monkeypatch.setattr(control, "dlqr", fail)
    with pytest.raises(UserError, match=r"LQR on joints \[11, 26\].*not stabilizable") as info:
        lqg_gains(plant, H, 5e-4, LqgWeights())
    assert "\n" not in str(info.value)
