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
Two channels per actuator site, always in this order (:func:`channels`): site 1 axis C,
site 1 axis E, site 2 axis C, ... The default is two sites (:data:`CHANNELS`: site 1 = long
span, site 2 = short span, the paper's layout); ``StrainController(params, n_sites=4)`` serves
four.

SISO and MIMO
-------------
Without ``params.gain_matrix`` every channel has its own P law, ``F = gain * strain``. With a
matrix M (n_sites x n_sites, relative gains [1]) each axis couples the sites:

    F_axis = gain * (M @ strain_axis),    axis = C, E,

row i of M giving the force of site i from the strains of every site j (the gain matrix is
``G = gain * M`` [N per unit strain]). Saturation, switch-on and lag act on each channel's
force afterwards, as in the SISO law.

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
from collections.abc import Mapping
from typing import Any, ClassVar

import numpy as np

from .acceleration import FALLBACK, OK, REFUSED, compiled_law
from .law import Law
from .params import ControllerParams
from .ports import AXES, Port, gain_matrix_entry, parameter, strain, strain_site_ports

__all__ = ["AXES", "CHANNELS", "N_CHANNELS", "SWITCH_TIME_RTOL", "StrainController", "channels",
           "strain_core"]


def channels(n_sites: int) -> tuple[str, ...]:
    """Channel names in array order for ``n_sites`` sites: the strain inputs ``strain1_C,
    strain1_E, strain2_C, ...``."""
    return tuple(strain(s, a) for s in range(1, n_sites + 1) for a in AXES)


#: Channel names of the default two-site controller.
CHANNELS: tuple[str, ...] = channels(2)
N_CHANNELS = len(CHANNELS)
#: Relative tolerance on the switch-on comparison, so that a time accumulated
#: in floating point (e.g. ``25000 * 1e-3``) that lands a few ulp below
#: ``switch_on_time`` still counts as "switched on".
SWITCH_TIME_RTOL = 1e-12


class StrainController(Law):
    """Proportional strain-feedback controller, two channels (C, E) per actuator site.

    Parameters
    ----------
    params : ControllerParams, optional
        Controller parameters; defaults to ``ControllerParams()``.
    n_sites : int
        Actuator sites served (default 2); ``params.gain_matrix``, if any, must be
        ``n_sites x n_sites``.

    Notes
    -----
    The only state is the actuator force vector (2 n_sites,) [N] (the lag state),
    available through :meth:`get_state` / :meth:`set_state`. A call that fails
    validation (NaN strain, bad time step) raises ``ValueError`` and leaves the
    state unchanged.
    """

    KIND = "proportional"
    TABLE = "controller"
    FMU = "StrainController"
    DESCRIPTION = ("Proportional strain-feedback controller for lateral drillstring vibration "
                   "(sites x gauges C/E); F = gain*strain, F > 0 = compressive at D / tensile at "
                   "C; saturation, switch-on time, first-order actuator lag")
    PARAMS = ControllerParams
    COMPILED = ("strain_core", (1, 2, 1, 1, 1, 1))
    #: The default FMU's sites, as the paper names them.
    SITE_NAMES: ClassVar[dict[int, str]] = {1: "site 1 (long span)", 2: "site 2 (short span)"}

    # ------------------------------------------------------------------ interface
    @classmethod
    def layout_for(cls, params: ControllerParams, n_sites: int) -> dict[str, Any]:
        """``n_sites`` and the relative gain matrix's start (None: the default FMU's, which
        has no matrix parameters: two sites, no matrix; else the matrix or the identity)."""
        m = params.gain_matrix
        if n_sites == 2 and not m:
            return {"n_sites": 2, "gain_matrix": None}
        matrix = [list(row) for row in m] or [[float(i == j) for j in range(n_sites)]
                                              for i in range(n_sites)]
        return {"n_sites": n_sites, "gain_matrix": matrix}

    @classmethod
    def io_ports(cls, layout: Mapping[str, Any]) -> tuple[Port, ...]:
        """The strains and forces of ``layout["n_sites"]`` sites (the paper's two sites named
        by their spans, where the layout has no matrix)."""
        n = int(layout["n_sites"])
        paper = n == 2 and layout.get("gain_matrix") is None
        return strain_site_ports(n, cls.SITE_NAMES if paper else None)

    @classmethod
    def parameter_ports(cls, layout: Mapping[str, Any]) -> tuple[Port, ...]:
        """The P law's fields, then (a layout with a matrix) the relative gains
        ``gain_matrix_<i>_<j>`` [1], row by row, starting at the layout's matrix."""
        out = list(super().parameter_ports(layout))
        for i, row in enumerate(layout.get("gain_matrix") or (), start=1):
            for j, start in enumerate(row, start=1):
                out.append(parameter(
                    gain_matrix_entry(i, j), "1",
                    f"Relative gain from the strain of site {j} to the force of site {i}, both "
                    f"axes: F_axis = gain * M @ strain_axis; identity = one P law per channel",
                    float(start)))
        return tuple(out)

    @classmethod
    def encode(cls, params: ControllerParams, layout: Mapping[str, Any]) -> dict[str, Any]:
        out = super().encode(params, layout)
        out.pop("gain_matrix", None)
        n = int(layout["n_sites"])
        if layout.get("gain_matrix") is not None:
            m = params.gain_matrix or tuple(tuple(float(i == j) for j in range(n))
                                            for i in range(n))
            out.update({gain_matrix_entry(i, j): float(m[i - 1][j - 1])
                        for i in range(1, n + 1) for j in range(1, n + 1)})
        return out

    @classmethod
    def decode(cls, values: Mapping[str, Any], layout: Mapping[str, Any], base: Any = None
               ) -> ControllerParams:
        params = super().decode(values, layout)
        if layout.get("gain_matrix") is None:
            return params
        n = int(layout["n_sites"])
        matrix = tuple(tuple(values[gain_matrix_entry(i, j)] for j in range(1, n + 1))
                       for i in range(1, n + 1))
        return ControllerParams(**{**_fields(params), "gain_matrix": matrix})

    @classmethod
    def create(cls, params: ControllerParams, layout: Mapping[str, Any]) -> StrainController:
        return cls(params, int(layout["n_sites"]))

    def __init__(self, params: ControllerParams | None = None, n_sites: int = 2) -> None:
        if isinstance(n_sites, bool) or not isinstance(n_sites, int) or n_sites < 1:
            raise ValueError(f"n_sites = {n_sites!r} is not allowed; allowed: an integer >= 1")
        self.n_sites = n_sites
        #: channel names in array order (:func:`channels`)
        self.channels = channels(n_sites)
        self.n_channels = len(self.channels)
        self._matrix: np.ndarray | None = None
        self._params = ControllerParams()
        self.params = ControllerParams() if params is None else params
        self._force = np.zeros(self.n_channels)
        #: [dt, exp(-dt / T)]: the lag's decay factor and the step [s] it is valid for
        self._decay = np.array([math.nan, 0.0])

    # ------------------------------------------------------------------ params
    def _check_params(self, params: object) -> None:
        if not isinstance(params, ControllerParams):
            raise TypeError(f"params must be a ControllerParams, got {type(params).__name__}")
        m = params.gain_matrix
        if m and len(m) != self.n_sites:
            raise ValueError(f"gain_matrix is {len(m)} x {len(m)}; this controller serves "
                             f"{self.n_sites} sites: allowed an {self.n_sites} x {self.n_sites} "
                             "matrix")

    @property
    def params(self) -> ControllerParams:
        """ControllerParams: current parameters; assigning keeps the lag state."""
        return self._params

    @params.setter
    def params(self, params: ControllerParams) -> None:
        self._check_params(params)
        self._params = params
        self._matrix = np.array(params.gain_matrix, dtype=float) if params.gain_matrix else None
        if hasattr(self, "_decay"):
            self._decay[0] = math.nan

    # ------------------------------------------------------------------- state
    def reset(self) -> None:
        """Set the actuator forces (lag state) to zero."""
        self._force[:] = 0.0

    def get_state(self) -> np.ndarray:
        """Return a copy of the controller state.

        Returns
        -------
        numpy.ndarray, shape (2 n_sites,)
            Actuator forces [N] at the end of the last step (the lag state).
        """
        return self._force.copy()

    def set_state(self, state: np.ndarray) -> None:
        """Restore a state obtained from :meth:`get_state`.

        Parameters
        ----------
        state : array_like, shape (2 n_sites,)
            Actuator forces [N]; must be finite.

        Raises
        ------
        ValueError
            If the shape is wrong or a value is not finite.
        """
        arr = np.asarray(state, dtype=float)
        if arr.shape != (self.n_channels,):
            raise ValueError(f"state must have shape ({self.n_channels},), got {arr.shape}")
        if not np.all(np.isfinite(arr)):
            raise ValueError(f"state must be finite, got {arr.tolist()}")
        self._force[:] = arr

    @property
    def forces(self) -> np.ndarray:
        """numpy.ndarray, shape (2 n_sites,): copy of the current actuator forces [N]."""
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
        strains : array_like, shape (2 n_sites,)
            Strains [1] in channel order :attr:`channels`; must be finite.

        Returns
        -------
        numpy.ndarray, shape (2 n_sites,)
            ``clip(gain * strains, lower_limit, upper_limit)`` [N] (with a gain matrix M,
            ``gain * (M @ strain_axis)`` per axis before the clip), or zeros when the
            controller is not active at ``t``.

        Raises
        ------
        ValueError
            If ``strains`` has the wrong shape or a non-finite entry.
        """
        eps = self._check_strains(strains)
        if not self.is_active(t):
            return np.zeros(self.n_channels)
        p = self._params
        M = self._matrix
        if M is None:
            u = p.gain * eps
        else:  # rows of X are sites, columns the axes C, E; the sum over j in order (no BLAS,
            # whose summation order is its own: the compiled step gives the same bits)
            X = eps.reshape(self.n_sites, len(AXES))
            acc = M[:, :1] * X[0]
            for j in range(1, self.n_sites):
                acc = acc + M[:, j:j + 1] * X[j]
            u = p.gain * acc.ravel()
        return np.clip(u, p.lower_limit, p.upper_limit)

    def step(self, t: float, dt: float, strains: np.ndarray) -> np.ndarray:
        """Advance the controller over ``[t, t + dt]``.

        Parameters
        ----------
        t : float
            Start of the step [s] (time at which the strains were sampled).
        dt : float
            Step size [s], ``dt >= 0`` and finite.
        strains : array_like, shape (2 n_sites,)
            Strains [1] in channel order :attr:`channels`, held over the step.

        Returns
        -------
        numpy.ndarray, shape (2 n_sites,)
            Actuator forces [N] at ``t + dt`` (a copy; also the new state).

        Raises
        ------
        ValueError
            If ``t`` or ``dt`` is not finite, ``dt < 0``, or ``strains`` has the
            wrong shape or a non-finite entry. The state is left unchanged.
        """
        _check_step(t, dt)
        return self._actuate(self.command(t, strains), dt)

    def _actuate(self, u: np.ndarray, dt: float) -> np.ndarray:
        """The actuator forces after ``dt`` [s] of the saturated command ``u`` [N] (the lag),
        a copy of the new state."""
        tau = self._params.lag_time_constant
        if tau == 0.0:
            self._force[:] = u
        else:
            decay = self._decay
            if dt != decay[0]:
                decay[:] = dt, math.exp(-dt / tau)
            # exact solution of tau dF/dt = u - F with u held over the step
            self._force[:] = u + (self._force - u) * decay[1]
        return self._force.copy()

    def initial_outputs(self) -> np.ndarray:
        """The actuator forces (the lag state) [N]."""
        return self.forces

    def advance(self, t: float, h: float, inputs: np.ndarray, outputs: np.ndarray) -> None:
        """:meth:`step` with the strains ``inputs``, the forces written into ``outputs``."""
        outputs[:] = self.step(t, h, inputs)

    def compiled_step(self, inputs: np.ndarray, outputs: np.ndarray) -> Any:
        """This law's compiled step (:class:`controller.compiled.CompiledLaw`, core
        :func:`strain_core`) reading the strains from ``inputs`` and writing the forces into
        ``outputs`` (float64 buffers, shape (2 n_sites,)); None without numba or with compiled
        steps switched off."""
        def pack() -> tuple[object, list[np.ndarray]]:
            p = self._params
            params = np.array([p.gain, p.lower_limit, p.upper_limit, p.switch_on_time,
                               float(p.enabled), p.lag_time_constant, SWITCH_TIME_RTOL])
            matrix = self._matrix if self._matrix is not None else np.zeros((0, 0))
            return p, [params, matrix, self._decay, self._force, inputs, outputs]

        return compiled_law(self.KIND, pack)

    def _check_strains(self, strains: np.ndarray) -> np.ndarray:
        eps = np.asarray(strains, dtype=float)
        if eps.shape != (self.n_channels,):
            raise ValueError(f"strains must have shape ({self.n_channels},), got {eps.shape}")
        if not np.all(np.isfinite(eps)):
            bad = [self.channels[i] for i in np.flatnonzero(~np.isfinite(eps))]
            raise ValueError(f"non-finite strain in channel(s) {', '.join(bad)}: {eps.tolist()}")
        return eps


def _check_step(t: float, dt: float) -> None:
    """ValueError unless ``t`` and ``dt`` are finite and ``dt >= 0``."""
    if not (math.isfinite(t) and math.isfinite(dt) and dt >= 0.0):
        raise ValueError(f"need finite t and finite dt >= 0, got t = {t!r}, dt = {dt!r}")


def _fields(params: ControllerParams) -> dict[str, Any]:
    return {name: getattr(params, name) for name in params.__dataclass_fields__}


# ------------------------------------------------------------------------ compiled core
# slots of the strain law's params array (the switch-on tolerance is passed in: the compiled
# entry is keyed on this package's sources, but a number in the array needs no recompilation)
P_GAIN, P_LOWER, P_UPPER, P_SWITCH_ON, P_ENABLED, P_TAU, P_RTOL = range(7)


def strain_core(t, dt, params, matrix, decay, force, inputs, outputs):
    """:meth:`controller.StrainController.step` on the buffers (see the module docstring)."""
    if not (math.isfinite(t) and math.isfinite(dt) and dt >= 0.0):
        return REFUSED
    nch = force.size
    for i in range(nch):
        if not math.isfinite(inputs[i]):
            return REFUSED
    tau = params[P_TAU]
    if tau != 0.0 and dt != decay[0]:
        return FALLBACK  # the Python law computes exp(-dt / tau) and keeps it in `decay`
    t_on = params[P_SWITCH_ON]
    active = params[P_ENABLED] != 0.0 and t >= t_on - params[P_RTOL] * max(1.0, abs(t_on))
    gain = params[P_GAIN]
    lower = params[P_LOWER]
    upper = params[P_UPPER]
    n = matrix.shape[0]
    for i in range(nch):
        u = 0.0
        if active:
            if n == 0:
                v = gain * inputs[i]
            else:  # site s, axis a: sum over the sites j in order, as the Python law
                s = i // 2
                a = i - 2 * s
                acc = matrix[s, 0] * inputs[a]
                for j in range(1, n):
                    acc = acc + matrix[s, j] * inputs[2 * j + a]
                v = gain * acc
            v = lower if v < lower else v  # numpy's clip keeps v when equal to a limit
            u = upper if v > upper else v
        if tau == 0.0:
            force[i] = u
        else:
            force[i] = u + (force[i] - u) * decay[1]
        outputs[i] = force[i]
    return OK
