"""PD strain feedback with a first-order filter on the derivative, one law per site and gauge.

The P law of ``strain_feedback.py`` plus a damping term: per channel (site s, gauge axis C or E)

    F = clip(k_p eps + k_d d, lower, upper),      D(s) = d / eps = s / (T_f s + 1),

``k_p`` = ``gain`` [N per unit strain], ``k_d`` = ``derivative_gain`` [N s per unit strain],
``T_f`` = ``derivative_time_constant`` [s] > 0 (the filter that makes the derivative proper and
keeps the sensor noise above 1/T_f out), then the actuator lag, switch-on time, limits and sign
convention of the P law (its module docstring). ``k_d = 0`` is the P law, bit for bit.

Why: a derivative of the bending strain is a damping force on the bending mode, where the P
law is a stiffness; a delay turns stiffness into negative damping at the mode's frequency
(docs/delay_study.md), and the derivative term buys phase back (+atan(w T_f) less the filter's
lag, at most +90 degrees).

Time discretisation
-------------------
The law is the step-invariant (zero-order-hold) equivalent of the continuous one, evaluated at
the sample: the filter is ``x' = (eps - x) / T_f`` with ``d = (eps - x) / T_f``, so with the
strain ``eps_k`` sampled at ``t`` and held over ``[t, t + h]``

    d_k = (eps_k - x_k) / T_f,      x_{k+1} = eps_k + (x_k - eps_k) exp(-h / T_f),

the command ``u_k = clip(k_p eps_k + k_d d_k)`` is held over the step and the force at ``t + h``
is the lag's answer to it, exactly as the P law's (``scipy.signal.cont2discrete(..., "zoh")``
of ``k_p + k_d s / (T_f s + 1)`` gives the same numbers: ``tests/test_pd_strain.py``). The
filter starts at the first strain it sees (no derivative kick at the first sample); it runs
whether the law acts or not, so the derivative is settled at the switch-on time.

The state is the actuator forces and the filter states with the flag "started" (:meth:`get_state`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .acceleration import FALLBACK, OK, REFUSED, compiled_law
from .law import setting
from .params import ControllerParams
from .strain_feedback import SWITCH_TIME_RTOL, StrainController, _check_step

__all__ = ["PDControllerParams", "PDStrainController", "pd_core"]


@dataclass(frozen=True)
class PDControllerParams(ControllerParams):
    """Parameters of the PD strain law: those of :class:`controller.ControllerParams` (``gain``
    is k_p) and the derivative's gain and filter; no gain matrix (one law per channel).

    Raises
    ------
    ValueError
        Any invalid value, naming the parameter and the allowed range.
    """

    gain_matrix: tuple = field(default=(), metadata={
        "unit": "1", "doc": "must be []: the PD law is one law per channel"})
    derivative_gain: float = setting(
        0.0, "N.s", "Derivative gain k_d, N s per unit strain: F += k_d d, d the filtered strain "
        "rate; >= 0 (0 = the P law)", range=(0.0, math.inf), open=(False, True))
    derivative_time_constant: float = setting(
        1e-3, "s", "Time constant T_f of the derivative's first-order filter s / (T_f s + 1); "
        "> 0", range=(0.0, math.inf), open=(True, True))

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.gain_matrix:
            raise ValueError(f"gain_matrix = {[list(r) for r in self.gain_matrix]!r} is not "
                             f"allowed: the PD law is one law per channel; allowed: []")


class PDStrainController(StrainController):
    """The PD strain law of the module docstring, two channels (C, E) per actuator site.

    Parameters
    ----------
    params : PDControllerParams, optional
    n_sites : int
        Actuator sites served (default 2).
    """

    KIND = "pd"
    FMU = "PDStrainController"
    DESCRIPTION = ("PD strain-feedback controller for lateral drillstring vibration (sites x "
                   "gauges C/E): F = gain*strain + derivative_gain*s/(T_f s + 1) strain, F > 0 "
                   "= compressive at D / tensile at C; saturation, switch-on time, first-order "
                   "actuator lag")
    PARAMS = PDControllerParams
    COMPILED = ("pd_core", (1, 1, 1, 1, 1, 1, 1))

    @classmethod
    def layout_for(cls, params: PDControllerParams, n_sites: int) -> dict[str, Any]:
        """``n_sites`` (the default FMU: two)."""
        return {"n_sites": n_sites}

    def __init__(self, params: PDControllerParams | None = None, n_sites: int = 2) -> None:
        super().__init__(PDControllerParams() if params is None else params, n_sites)
        #: the filter states x, then 1.0 once started (0.0: the next strains start them)
        self._filter = np.zeros(self.n_channels + 1)
        #: [dt, exp(-dt / T_f)]: the filter's decay factor and the step [s] it is valid for
        self._filter_decay = np.array([math.nan, 0.0])

    def _check_params(self, params: object) -> None:
        if not isinstance(params, PDControllerParams):
            raise TypeError(f"params must be a PDControllerParams, got {type(params).__name__}")
        super()._check_params(params)

    @StrainController.params.setter
    def params(self, params: PDControllerParams) -> None:
        StrainController.params.fset(self, params)
        if hasattr(self, "_filter_decay"):
            self._filter_decay[0] = math.nan

    # ------------------------------------------------------------------- state
    def reset(self) -> None:
        """Forces and filter to zero; the filter starts again at the next strains."""
        super().reset()
        self._filter[:] = 0.0

    def get_state(self) -> np.ndarray:
        """numpy.ndarray, shape (4 n_sites + 1,): a copy of the forces [N], the filter states
        [1] and the flag "started" (1.0 or 0.0)."""
        return np.concatenate([self._force, self._filter])

    def set_state(self, state: np.ndarray) -> None:
        """Restore :meth:`get_state` (ValueError for a wrong shape or a non-finite entry)."""
        arr = np.asarray(state, dtype=float)
        n = self.n_channels
        if arr.shape != (2 * n + 1,) or not np.all(np.isfinite(arr)):
            raise ValueError(f"state must be {2 * n + 1} finite numbers (forces, filter states, "
                             f"started), got {arr.tolist()}")
        self._force[:], self._filter[:] = arr[:n], arr[n:]

    # -------------------------------------------------------------------- law
    def step(self, t: float, dt: float, strains: np.ndarray) -> np.ndarray:
        """Advance over ``[t, t + dt]`` with ``strains`` held (module docstring); the forces
        at ``t + dt`` [N] (ValueError for a refused step, state unchanged)."""
        _check_step(t, dt)
        eps = self._check_strains(strains)
        p = self._params
        x = self._filter[:-1]
        if self._filter[-1] == 0.0:
            x[:] = eps
            self._filter[-1] = 1.0
        fd = self._filter_decay
        if dt != fd[0]:
            fd[:] = dt, math.exp(-dt / p.derivative_time_constant)
        rate = (eps - x) / p.derivative_time_constant
        if self.is_active(t):
            u = np.clip(p.gain * eps + p.derivative_gain * rate, p.lower_limit, p.upper_limit)
        else:
            u = np.zeros(self.n_channels)
        x[:] = eps + (x - eps) * fd[1]
        return self._actuate(u, dt)

    def compiled_step(self, inputs: np.ndarray, outputs: np.ndarray) -> Any:
        """The compiled step (core :func:`pd_core`) on ``inputs`` (strains) and ``outputs``
        (forces); None without numba or with compiled steps switched off."""
        def pack() -> tuple[object, list[np.ndarray]]:
            p = self._params
            params = np.array([p.gain, p.derivative_gain, p.derivative_time_constant,
                               p.lower_limit, p.upper_limit, p.switch_on_time, float(p.enabled),
                               p.lag_time_constant, SWITCH_TIME_RTOL])
            return p, [params, self._decay, self._filter_decay, self._force, self._filter,
                       inputs, outputs]

        return compiled_law(self.KIND, pack)


# ------------------------------------------------------------------------ compiled core
KP, KD, TF, LOWER, UPPER, SWITCH_ON, ENABLED, TAU, RTOL = range(9)


def pd_core(t, dt, params, decay, filter_decay, force, filt, inputs, outputs):
    """:meth:`PDStrainController.step` on the law's arrays (``filt``: states, then "started")."""
    if not (math.isfinite(t) and math.isfinite(dt) and dt >= 0.0):
        return REFUSED
    n = force.size
    for i in range(n):
        if not math.isfinite(inputs[i]):
            return REFUSED
    tau = params[TAU]
    if (tau != 0.0 and dt != decay[0]) or dt != filter_decay[0]:
        return FALLBACK  # the Python law computes the decay factors and keeps them
    if filt[n] == 0.0:
        for i in range(n):
            filt[i] = inputs[i]
        filt[n] = 1.0
    t_on = params[SWITCH_ON]
    active = params[ENABLED] != 0.0 and t >= t_on - params[RTOL] * max(1.0, abs(t_on))
    for i in range(n):
        eps = inputs[i]
        rate = (eps - filt[i]) / params[TF]
        u = 0.0
        if active:
            v = params[KP] * eps + params[KD] * rate
            v = params[LOWER] if v < params[LOWER] else v  # numpy's clip
            u = params[UPPER] if v > params[UPPER] else v
        filt[i] = eps + (filt[i] - eps) * filter_decay[1]
        force[i] = u if tau == 0.0 else u + (force[i] - u) * decay[1]
        outputs[i] = force[i]
    return OK
