"""The PD strain law (``controller/pd_strain.py``, ``[controller] kind = "pd"``) against two
other implementations and against the P law.

* scipy: ``cont2discrete`` (zero-order hold) of ``k_p + k_d s / (T_f s + 1)`` and ``dlsim``
  (an independent discretisation and simulation): equal to rounding;
* the project's state-space law (``controller/state_space.py``) with scipy's matrices, per
  channel: equal to rounding (BLAS products);
* ``derivative_gain = 0`` is the P law bit for bit (limits, lag, switch-on, compressive-only);
* through the co-simulation: with a 1 ms actuator delay the paper's P law (gain 1e9) diverges,
  the PD law with ``k_d = 1e6`` N s per strain stays at the undelayed loop's growth rate.
"""

from __future__ import annotations

import numpy as np
import pytest
import scipy.signal as sig

from drillcosim.controller import ControllerParams, StrainController
from drillcosim.controller.pd_strain import PDControllerParams, PDStrainController
from drillcosim.controller.state_space import Signal, StateSpaceController, StateSpaceParams
from drillcosim.cosim.scenario.config import load_config
from drillcosim.cosim.study.point import measure_point

KP, KD, TF, H = 1e8, 2e5, 2e-3, 2.5e-4


def _strains(n: int = 400, channels: int = 4, seed: int = 1) -> np.ndarray:
    eps = np.random.default_rng(seed).normal(0.0, 1e-5, (n, channels))
    eps[0] = 0.0  # the filter starts at the first strain: zero, as scipy's zero state
    return eps


def _zoh() -> tuple:
    """scipy's zero-order-hold equivalent of k_p + k_d s / (T_f s + 1)."""
    a, b, c, d, _ = sig.cont2discrete(sig.tf2ss([KP * TF + KD, KP], [TF, 1.0]), H, method="zoh")
    return a, b, c, d


def test_pd_law_is_scipys_zero_order_hold_discretisation() -> None:
    eps = _strains()
    law = PDStrainController(PDControllerParams(gain=KP, derivative_gain=KD,
                                                derivative_time_constant=TF))
    out = np.array([law.step(k * H, H, e) for k, e in enumerate(eps)])
    a, b, c, d = _zoh()
    ref = np.column_stack([sig.dlsim((a, b, c, d, H), eps[:, j])[1][:, 0] for j in range(4)])
    assert np.max(np.abs(out - ref)) <= 1e-12 * np.max(np.abs(ref))
    assert np.max(np.abs(out - KP * eps)) > 0.5 * np.max(np.abs(KP * eps))  # the D term acts


def test_pd_law_equals_the_state_space_law_with_scipys_matrices() -> None:
    eps = _strains(seed=2)
    a, b, c, d = _zoh()
    n = 4  # one filter per channel: block-diagonal matrices
    eye = np.eye(n)
    ss = StateSpaceParams(np.kron(eye, a), np.kron(eye, b), np.kron(eye, c), np.kron(eye, d),
                          [Signal(f"y{i}") for i in range(n)],
                          [Signal(f"u{i}", "N") for i in range(n)], H, "PD via scipy")
    other = StateSpaceController(ss)
    law = PDStrainController(PDControllerParams(gain=KP, derivative_gain=KD,
                                                derivative_time_constant=TF))
    out = np.array([law.step(k * H, H, e) for k, e in enumerate(eps)])
    ref = np.array([other.step(k * H, H, e) for k, e in enumerate(eps)])
    assert np.max(np.abs(out - ref)) <= 1e-12 * np.max(np.abs(ref))


@pytest.mark.parametrize("extra", [
    {}, {"lag_time_constant": 3e-3, "switch_on_time": 0.02, "symmetric_force_limit": 800.0},
    {"mode": "compressive_only", "force_limit": 500.0}])
def test_zero_derivative_gain_is_the_p_law_bit_for_bit(extra) -> None:
    eps = _strains(300, seed=3)
    eps[0] = 1e-6  # the filter's start is invisible with k_d = 0
    pd = PDStrainController(PDControllerParams(gain=KP, derivative_gain=0.0, **extra))
    p = StrainController(ControllerParams(gain=KP, **extra))
    for k, e in enumerate(eps):
        h = H if k < 200 else 2 * H  # a new step: new decay factors
        a, b = pd.step(k * H, h, e), p.step(k * H, h, e)
        assert a.tobytes() == b.tobytes(), k


def test_state_restores_bit_for_bit_and_bad_input_leaves_it() -> None:
    law = PDStrainController(PDControllerParams(gain=KP, derivative_gain=KD,
                                                lag_time_constant=1e-3))
    eps = _strains(100, seed=4)
    for k in range(50):
        law.step(k * H, H, eps[k])
    saved = law.get_state()
    assert saved.shape == (9,) and saved[-1] == 1.0  # forces, filter states, started
    first = [law.step(k * H, H, eps[k]) for k in range(50, 100)]
    law.set_state(saved)
    with pytest.raises(ValueError, match="strain1_E"):
        law.step(50 * H, H, np.array([0.0, np.nan, 0.0, 0.0]))
    again = [law.step(k * H, H, eps[k]) for k in range(50, 100)]
    assert np.array_equal(first, again)
    with pytest.raises(ValueError, match="gain_matrix"):
        PDControllerParams(gain_matrix=((1.0, 0.5), (0.5, 1.0)))
    with pytest.raises(ValueError, match="derivative_time_constant = 0.0 is out of range"):
        PDControllerParams(derivative_time_constant=0.0)


def test_derivative_term_keeps_the_delayed_paper_loop_stable() -> None:
    """paper_closed_loop at its 0.25 ms step with a 1 ms actuator delay, 3 s: the P law
    diverges; the PD law (k_d = 1e6 N s per strain, T_f = one step) grows like the loop
    without delay (~0.9 /s, the forced whirl's build-up; tests/test_sweep.py)."""
    over = {"controller.kind": "pd", "controller.derivative_time_constant": 2.5e-4}
    rows = {kd: measure_point("paper_closed_loop", 1e9, 1e-3, 2.5e-4, 3.0, "inprocess",
                              overrides={**over, "controller.derivative_gain": kd})
            for kd in (0.0, 1e6)}
    assert rows[0.0]["status"] == "diverged"
    assert rows[1e6]["status"] == "ok" and rows[1e6]["growth_rate"] < 1.5
    assert rows[1e6]["peak_force"] < 1e4


def test_the_pd_scene() -> None:
    config = load_config("paper_delay_pd")
    assert config.controller.kind == "pd" and config.controller.enabled
    assert config.controller.params.derivative_gain == 1e6
    assert config.cosim.actuator_delay == 1e-3
