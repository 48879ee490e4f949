"""Proportional strain feedback with saturation, switch-on time and actuator lag.

Sign convention
---------------
Paper section 3.3: a positive (tensile) strain at gauge C makes the actuator pair
apply a *compressive* force at D (pushing the adjacent bodies apart there) and an
equal *tensile* force at C, i.e. a couple that opposes the bending. Here this is

    F = gain * strain,    F > 0  <=>  compressive at D / tensile at C,

so a positive force is the couple that reduces a positive strain. The same holds
for gauge E with actuator points E/F. In ``"compressive_only"`` mode the actuator
can only push: ``F`` is clipped to ``[0, force_limit]``. In ``"unrestricted"`` mode
``F`` is clipped to ``[-symmetric_force_limit, +symmetric_force_limit]`` (no clipping
with the default infinite limit).

Channels
--------
Four channels, always in this order (:data:`CHANNELS`):
site 1 (long span) axis C, site 1 axis E, site 2 (short span) axis C, site 2 axis E.

Time discretisation
-------------------
``step(t, dt, strains)`` holds the saturated command ``u`` constant over
``[t, t + dt]`` (zero-order hold) and returns the actuator force at ``t + dt``
from the exact solution of the first-order lag ``T dF/dt = u - F``:

    F(t + dt) = u + (F(t) - u) * exp(-dt / T),

and ``F(t + dt) = u`` for ``T = 0``. The command is zero while
``t < switch_on_time`` (and always when ``enabled`` is false).
"""

from __future__ import annotations

import math

import numpy as np

from .params import ControllerParams

__all__ = ["CHANNELS", "N_CHANNELS", "SWITCH_TIME_RTOL", "StrainController"]

#: Channel names in array order: (site, axis).
CHANNELS: tuple[str, ...] = ("site1_C", "site1_E", "site2_C", "site2_E")
N_CHANNELS = len(CHANNELS)
#: Relative tolerance on the switch-on comparison, so that a time accumulated
#: in floating point (e.g. ``25000 * 1e-3``) that lands a few ulp below
#: ``switch_on_time`` still counts as "switched on".
SWITCH_TIME_RTOL = 1e-12


class StrainController:
    """Four-channel proportional strain-feedback controller.

    Parameters
    ----------
    params : ControllerParams, optional
        Controller parameters; defaults to ``ControllerParams()``.

    Notes
    -----
    The only state is the actuator force vector (4,) [N] (the lag state),
    available through :meth:`get_state` / :meth:`set_state`. A call that fails
    validation (NaN strain, bad time step) raises ``ValueError`` and leaves the
    state unchanged.
    """

    def __init__(self, params: ControllerParams | None = None) -> None:
        self._params = ControllerParams() if params is None else params
        self._check_params_type(self._params)
        self._force = np.zeros(N_CHANNELS)
        self._decay_dt = math.nan  # dt for which self._decay is valid
        self._decay = 0.0

    # ------------------------------------------------------------------ params
    @staticmethod
    def _check_params_type(params: object) -> None:
        if not isinstance(params, ControllerParams):
            raise TypeError(f"params must be a ControllerParams, got {type(params).__name__}")

    @property
    def params(self) -> ControllerParams:
        """ControllerParams: current parameters; assigning keeps the lag state."""
        return self._params

    @params.setter
    def params(self, params: ControllerParams) -> None:
        self._check_params_type(params)
        self._params = params
        self._decay_dt = math.nan

    # ------------------------------------------------------------------- state
    def reset(self) -> None:
        """Set the actuator forces (lag state) to zero."""
        self._force[:] = 0.0

    def get_state(self) -> np.ndarray:
        """Return a copy of the controller state.

        Returns
        -------
        numpy.ndarray, shape (4,)
            Actuator forces [N] at the end of the last step (the lag state).
        """
        return self._force.copy()

    def set_state(self, state: np.ndarray) -> None:
        """Restore a state obtained from :meth:`get_state`.

        Parameters
        ----------
        state : array_like, shape (4,)
            Actuator forces [N]; must be finite.

        Raises
        ------
        ValueError
            If the shape is wrong or a value is not finite.
        """
        arr = np.asarray(state, dtype=float)
        if arr.shape != (N_CHANNELS,):
            raise ValueError(f"state must have shape ({N_CHANNELS},), got {arr.shape}")
        if not np.all(np.isfinite(arr)):
            raise ValueError(f"state must be finite, got {arr.tolist()}")
        self._force[:] = arr

    @property
    def forces(self) -> np.ndarray:
        """numpy.ndarray, shape (4,): copy of the current actuator forces [N]."""
        return self._force.copy()

    # -------------------------------------------------------------------- law
    def is_active(self, t: float) -> bool:
        """Whether the controller acts at time ``t`` [s].

        Parameters
        ----------
        t : float
            Time [s].

        Returns
        -------
        bool
            ``enabled and t >= switch_on_time`` (up to :data:`SWITCH_TIME_RTOL`).
        """
        p = self._params
        if not p.enabled:
            return False
        t_on = p.switch_on_time
        return t >= t_on - SWITCH_TIME_RTOL * max(1.0, abs(t_on))

    def command(self, t: float, strains: np.ndarray) -> np.ndarray:
        """Saturated force command (before the lag) for the given strains.

        Parameters
        ----------
        t : float
            Time [s] at which the strains were sampled.
        strains : array_like, shape (4,)
            Strains [1] in channel order :data:`CHANNELS`; must be finite.

        Returns
        -------
        numpy.ndarray, shape (4,)
            ``clip(gain * strains, lower_limit, upper_limit)`` [N], or zeros
            when the controller is not active at ``t``.

        Raises
        ------
        ValueError
            If ``strains`` has the wrong shape or a non-finite entry.
        """
        eps = self._check_strains(strains)
        if not self.is_active(t):
            return np.zeros(N_CHANNELS)
        p = self._params
        u = p.gain * eps
        return np.clip(u, p.lower_limit, p.upper_limit)

    def step(self, t: float, dt: float, strains: np.ndarray) -> np.ndarray:
        """Advance the controller over ``[t, t + dt]``.

        Parameters
        ----------
        t : float
            Start of the step [s] (time at which the strains were sampled).
        dt : float
            Step size [s], ``dt >= 0`` and finite.
        strains : array_like, shape (4,)
            Strains [1] in channel order :data:`CHANNELS`, held over the step.

        Returns
        -------
        numpy.ndarray, shape (4,)
            Actuator forces [N] at ``t + dt`` (a copy; also the new state).

        Raises
        ------
        ValueError
            If ``t`` or ``dt`` is not finite, ``dt < 0``, or ``strains`` has the
            wrong shape or a non-finite entry. The state is left unchanged.
        """
        if not (math.isfinite(t) and math.isfinite(dt) and dt >= 0.0):
            raise ValueError(f"need finite t and finite dt >= 0, got t = {t!r}, dt = {dt!r}")
        u = self.command(t, strains)
        tau = self._params.lag_time_constant
        if tau == 0.0:
            self._force[:] = u
        else:
            if dt != self._decay_dt:
                self._decay = math.exp(-dt / tau)
                self._decay_dt = dt
            # exact solution of tau dF/dt = u - F with u held over the step
            self._force[:] = u + (self._force - u) * self._decay
        return self._force.copy()

    @staticmethod
    def _check_strains(strains: np.ndarray) -> np.ndarray:
        eps = np.asarray(strains, dtype=float)
        if eps.shape != (N_CHANNELS,):
            raise ValueError(f"strains must have shape ({N_CHANNELS},), got {eps.shape}")
        if not np.all(np.isfinite(eps)):
            bad = [CHANNELS[i] for i in np.flatnonzero(~np.isfinite(eps))]
            raise ValueError(f"non-finite strain in channel(s) {', '.join(bad)}: {eps.tolist()}")
        return eps
