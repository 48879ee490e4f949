"""Continuous-time strain feedback: the control law inside the right-hand side (no sampling).

The co-simulation samples the strains every communication step ``H`` and holds the actuator
forces (zero-order hold); :class:`ClosedLoopSimulator` removes both. It integrates

    dy/dt = f(t, y, u(t)),   u(t) = u_ext + F(t),
    F(t) = sat(K eps(y(t - tau))) while t - tau >= t_on (else 0)        (no lag)
    T dG/dt = sat(K eps(y(t))) [t >= t_on] - G,   F(t) = G(t - tau)     (lag T > 0)

with ``eps`` the gauge strains of every site and axis (C, E), the law of
``controller/strain_feedback.py`` (P per site and axis, saturation to ``[lower, upper]``, switch-on
time, optional first-order lag) evaluated at every stage of the integrator, and an optional pure
actuator delay ``tau`` [s]. Before ``t = tau`` the delayed force is 0 (the history before the
start holds no controller output, as the master's delay lines start at 0).

Delay-differential equation (``tau > 0``): RK4 with internal step ``dt <= tau``, so every stage's
delayed time ``t - tau`` lies at or before the current step's start, where the solution is known.
Past steps are kept (time, the components the law reads, their derivatives, the switch flag) in a
ring buffer on the internal step grid and evaluated at the delayed stage times by a continuous
extension: **cubic Hermite** (default; values and derivatives at both ends of the step, local
error O(dt^4)) keeps RK4's global order 4 (Bellen & Zennaro, *Numerical Methods for Delay
Differential Equations*, 2003, sec. 3.3: a continuous extension of uniform order ``q`` gives
global order ``min(p, q + 1)``); ``"linear"`` interpolation (order 1) would lower it to 2. Both
are selectable so that the tests can measure the orders (``tests/test_continuous_reference.py``).

Discontinuities are integration breakpoints: the model's own (loads, end of the speed ramp), the
switch-on time ``t_on``, and ``tau`` and ``t_on + tau`` where the delayed force jumps. The switch
state is decided once a step at its midpoint (as the step loads, ``kernels.set_load_modes``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from numba import njit

from drillcosim.plant.integrators import _all_finite, next_breakpoint, stable_step
from drillcosim.plant.kernels import (
    IP_NA,
    cardan,
    gauge_strains,
    relative_rotation,
    rhs,
    set_load_modes,
)
from drillcosim.plant.layout import GAUGE_R, HALF
from drillcosim.plant.model import DrillstringModel
from drillcosim.plant.params import _check_range
from drillcosim.plant.signals import site_channels, strain
from drillcosim.plant.simulator import PlantSimulator
from drillcosim.plant.step_result import StepResult

__all__ = ["INTERPOLATIONS", "StrainLaw", "ClosedLoopRun", "ClosedLoopSimulator"]

#: Continuous extensions of the history for the delayed term: name -> polynomial order.
INTERPOLATIONS = {"hermite": 3, "linear": 1}

# law vector (float64): gain [N], lower and upper force limits [N], switch-on time [s],
# lag time constant [s] (0 = none), delay [s], enabled (0/1)
LW_GAIN = 0
LW_LO = 1
LW_HI = 2
LW_TON = 3
LW_LAG = 4
LW_TAU = 5
LW_ON = 6
NLW = 7

CL_OK = 0
CL_NONFINITE = -1
CL_HISTORY_FULL = -2  # the ring buffer would drop a step still needed: grow it and resume
CL_HISTORY_MISSING = -3  # a delayed time outside the kept history (internal error)

# ring meta (int64): index of the newest entry, number of entries
RG_HEAD = 0
RG_COUNT = 1


@dataclass(frozen=True)
class StrainLaw:
    """The strain-feedback law of ``controller/strain_feedback.py``, in continuous time.

    Attributes
    ----------
    gain : float
        K [N per unit strain], ``F = K eps`` (> 0 opposes the strain, as the controller FMU).
    lower_limit, upper_limit : float
        Saturation [N]; ``-inf`` / ``inf`` for none (``compressive_only``: 0 and force_limit).
    switch_on_time : float
        t_on [s]: the command is 0 before it.
    lag_time_constant : float
        T [s] of the first-order actuator lag (0 = none).
    delay : float
        Pure actuator delay tau [s] (0 = none).
    enabled : bool
        False: open loop (F = 0).
    """

    gain: float
    lower_limit: float = -math.inf
    upper_limit: float = math.inf
    switch_on_time: float = 0.0
    lag_time_constant: float = 0.0
    delay: float = 0.0
    enabled: bool = True

    def __post_init__(self) -> None:
        o = "law"
        _check_range(o, "gain", self.gain, 0.0, 1e15, unit="N per unit strain")
        _check_range(o, "lower_limit", self.lower_limit, None, 0.0, unit="N", allow_inf=True)
        _check_range(o, "upper_limit", self.upper_limit, 0.0, None, unit="N", allow_inf=True)
        _check_range(o, "switch_on_time", self.switch_on_time, 0.0, 1e9, unit="s")
        _check_range(o, "lag_time_constant", self.lag_time_constant, 0.0, 1e6, unit="s")
        _check_range(o, "delay", self.delay, 0.0, 10.0, unit="s")
        if not isinstance(self.enabled, (bool, np.bool_)):
            raise ValueError(f"law.enabled = {self.enabled!r} is not allowed: true or false")

    @classmethod
    def from_controller(cls, params: Any, delay: float = 0.0) -> StrainLaw:
        """The law of a ``controller.ControllerParams`` (duck-typed: gain, lower_limit,
        upper_limit, switch_on_time, lag_time_constant, enabled) with an actuator delay [s]."""
        return cls(gain=float(params.gain), lower_limit=float(params.lower_limit),
                   upper_limit=float(params.upper_limit),
                   switch_on_time=float(params.switch_on_time),
                   lag_time_constant=float(params.lag_time_constant), delay=float(delay),
                   enabled=bool(params.enabled))

    def vector(self) -> np.ndarray:
        """The law as the kernels' float vector (``LW_*`` indices)."""
        v = np.zeros(NLW)
        v[LW_GAIN] = self.gain
        v[LW_LO] = self.lower_limit
        v[LW_HI] = self.upper_limit
        v[LW_TON] = self.switch_on_time
        v[LW_LAG] = self.lag_time_constant
        v[LW_TAU] = self.delay
        v[LW_ON] = 1.0 if self.enabled else 0.0
        return v


# ------------------------------------------------------------------------------ compiled parts
@njit(cache=True)
def _site_strains(vals, off, na, rg, dx, R3, eps):
    """eps[2 s], eps[2 s + 1] = strains (C, E) of site s from the Cardan angles ``vals[off + 6 s:
    off + 6 s + 6]`` (body above, body below the joint)."""
    for s in range(na):
        o = off + 6 * s
        cardan(vals[o], vals[o + 1], vals[o + 2], R3[0])
        cardan(vals[o + 3], vals[o + 4], vals[o + 5], R3[1])
        relative_rotation(R3[0], R3[1], R3[2])
        ec, ee = gauge_strains(R3[2], rg, dx)
        eps[2 * s] = ec
        eps[2 * s + 1] = ee


@njit(cache=True)
def _command(lw, on, eps, c):
    """Saturated command [N] of channel c (0 while switched off)."""
    if on == 0.0:
        return 0.0
    f = lw[LW_GAIN] * eps[c]
    if f < lw[LW_LO]:
        return lw[LW_LO]
    if f > lw[LW_HI]:
        return lw[LW_HI]
    return f


@njit(cache=True)
def _gather(x, ic, v):
    for k in range(ic.size):
        v[k] = x[ic[k]]


@njit(cache=True)
def _delayed(s, side, ic_size, ht, hx, hf, hon, meta, interp, v):
    """Interpolate the history at time ``s`` into ``v``; returns (code, switch flag).

    ``side`` 0: the step with t_i <= s < t_i+1 (a stage at a step's start); 1: t_i < s <= t_i+1
    (a stage at a step's end), so that a jump at a step boundary is seen from the right side.
    """
    cap = ht.size
    count = meta[RG_COUNT]
    head = meta[RG_HEAD]
    first = head - count + 1
    # times computed along different paths (t0 + k dt vs t - tau) agree to rounding: a delayed
    # time within tol of a stored step time is that step time
    tol = 1e-12 * max(1.0, abs(s))
    # newest entry with t_i <= s (side 0) or t_i < s (side 1)
    i = count - 1
    while i >= 0:
        ti = ht[(first + i) % cap]
        if (side == 0 and ti <= s + tol) or (side == 1 and ti < s - tol):
            break
        i -= 1
    if i < 0:
        return CL_HISTORY_MISSING, 0.0
    j0 = (first + i) % cap
    if i == count - 1:  # at the newest point itself (dt == tau): only its value is needed
        if s > ht[j0] + tol:
            return CL_HISTORY_MISSING, 0.0
        for k in range(ic_size):
            v[k] = hx[j0, k]
        return CL_OK, hon[j0]
    j1 = (first + i + 1) % cap
    h = ht[j1] - ht[j0]
    th = (s - ht[j0]) / h
    if th <= 0.0:
        for k in range(ic_size):
            v[k] = hx[j0, k]
    elif th >= 1.0:
        for k in range(ic_size):
            v[k] = hx[j1, k]
    elif interp == 3:
        t2 = th * th
        t3 = t2 * th
        a0 = 2.0 * t3 - 3.0 * t2 + 1.0
        b0 = (t3 - 2.0 * t2 + th) * h
        a1 = -2.0 * t3 + 3.0 * t2
        b1 = (t3 - t2) * h
        for k in range(ic_size):
            v[k] = a0 * hx[j0, k] + b0 * hf[j0, k] + a1 * hx[j1, k] + b1 * hf[j1, k]
    else:
        for k in range(ic_size):
            v[k] = (1.0 - th) * hx[j0, k] + th * hx[j1, k]
    return CL_OK, hon[j0]


@njit(cache=True)
def applied_forces(t, x, side, on, N, lw, p, ip, ic, ht, hx, hf, hon, meta, interp, v, R3, eps,
                   F):
    """F (2 n_act) = the actuator forces [N] the law applies at time ``t`` for state ``x``.

    ``on``: switch flag of the current step (tau = 0). Returns a status code (``CL_*``).
    """
    na = ip[IP_NA]
    M = 2 * na
    if lw[LW_ON] == 0.0:
        for c in range(M):
            F[c] = 0.0
        return CL_OK
    tau = lw[LW_TAU]
    lag = lw[LW_LAG] > 0.0
    rg = p[GAUGE_R]
    dx = 2.0 * p[HALF]
    if tau == 0.0:
        if lag:
            for c in range(M):
                F[c] = x[N + c]
            return CL_OK
        _gather(x, ic, v)
        _site_strains(v, 0, na, rg, dx, R3, eps)
        for c in range(M):
            F[c] = _command(lw, on, eps, c)
        return CL_OK
    s = t - tau
    tol = 1e-12 * max(1.0, abs(t))
    if s < -tol or (s <= tol and side == 1):  # before the start: no controller output yet
        for c in range(M):
            F[c] = 0.0
        return CL_OK
    code, on_s = _delayed(s, side, ic.size, ht, hx, hf, hon, meta, interp, v)
    if code != CL_OK:
        return code
    if lag:
        for c in range(M):
            F[c] = v[6 * na + c]
        return CL_OK
    _site_strains(v, 0, na, rg, dx, R3, eps)
    for c in range(M):
        F[c] = _command(lw, on_s, eps, c)
    return CL_OK


@njit(cache=True)
def _stage(model, t, x, dx_out, side, on, N, p, ip, fp, u_ext, u_tot, wR, wF, wM, lw, ic, ht, hx,
           hf, hon, meta, interp, v, R3, eps, F):
    """dx_out = closed-loop derivative at (t, x); returns a status code."""
    code = applied_forces(t, x, side, on, N, lw, p, ip, ic, ht, hx, hf, hon, meta, interp, v, R3,
                          eps, F)
    if code != CL_OK:
        return code
    M = F.size
    for c in range(M):
        u_tot[c] = u_ext[c] + F[c]
    for c in range(M, u_ext.size):
        u_tot[c] = u_ext[c]
    rhs(model, t, x[:N], dx_out[:N], p, ip, fp, u_tot, wR, wF, wM)
    T = lw[LW_LAG]
    if T > 0.0:  # the controller's lag state is driven by the current strains
        _gather(x, ic, v)
        _site_strains(v, 0, ip[IP_NA], p[GAUGE_R], 2.0 * p[HALF], R3, eps)
        for c in range(M):
            dx_out[N + c] = (_command(lw, on, eps, c) - x[N + c]) / T
    return CL_OK


@njit(cache=True)
def _push(t, x, f, on, ic, ht, hx, hf, hon, meta):
    cap = ht.size
    head = (meta[RG_HEAD] + 1) % cap
    meta[RG_HEAD] = head
    meta[RG_COUNT] = min(meta[RG_COUNT] + 1, cap)
    ht[head] = t
    hon[head] = on
    for k in range(ic.size):
        hx[head, k] = x[ic[k]]
        hf[head, k] = f[ic[k]]


@njit(cache=True)
def advance_closed_loop(model, t0, x, n_steps, dt, N, p, ip, fp, u_ext, u_tot, wR, wF, wM, lw,
                        ic, ht, hx, hf, hon, meta, interp, k1, k2, k3, k4, xt, v, R3, eps, F):
    """RK4 with the law inside the right-hand side, ``n_steps`` steps of ``dt`` [s] from ``t0``.

    ``x`` (N + lag states) is advanced in place. With a delay, ``dt`` must be <= tau and every
    step is stored in the ring buffer (``ht``, ``hx``, ``hf``, ``hon``, ``meta``) before its later
    stages run. Returns ``(steps completed, code)``: on ``CL_HISTORY_FULL`` nothing of the
    failing step was done (the caller grows the ring and resumes).
    """
    L = x.size
    tau = lw[LW_TAU]
    cap = ht.size
    for s in range(n_steps):
        t = t0 + s * dt
        tm = t + 0.5 * dt
        if tau > 0.0 and meta[RG_COUNT] == cap:
            # the oldest step is dropped by the push: only if no delayed time reaches it
            second = ht[(meta[RG_HEAD] - cap + 2) % cap]
            if second >= t - tau:
                return s, CL_HISTORY_FULL
        set_load_modes(ip, fp, tm)
        on = 1.0 if tm >= lw[LW_TON] else 0.0
        code = _stage(model, t, x, k1, 0, on, N, p, ip, fp, u_ext, u_tot, wR, wF, wM, lw, ic, ht,
                      hx, hf, hon, meta, interp, v, R3, eps, F)
        if code != CL_OK:
            return s, code
        if tau > 0.0:
            _push(t, x, k1, on, ic, ht, hx, hf, hon, meta)
        for i in range(L):
            xt[i] = x[i] + 0.5 * dt * k1[i]
        code = _stage(model, tm, xt, k2, 0, on, N, p, ip, fp, u_ext, u_tot, wR, wF, wM, lw, ic,
                      ht, hx, hf, hon, meta, interp, v, R3, eps, F)
        if code != CL_OK:
            return s, code
        for i in range(L):
            xt[i] = x[i] + 0.5 * dt * k2[i]
        code = _stage(model, tm, xt, k3, 0, on, N, p, ip, fp, u_ext, u_tot, wR, wF, wM, lw, ic,
                      ht, hx, hf, hon, meta, interp, v, R3, eps, F)
        if code != CL_OK:
            return s, code
        for i in range(L):
            xt[i] = x[i] + dt * k3[i]
        code = _stage(model, t + dt, xt, k4, 1, on, N, p, ip, fp, u_ext, u_tot, wR, wF, wM, lw,
                      ic, ht, hx, hf, hon, meta, interp, v, R3, eps, F)
        if code != CL_OK:
            return s, code
        c = dt / 6.0
        for i in range(L):
            x[i] += c * (k1[i] + 2.0 * (k2[i] + k3[i]) + k4[i])
        if (s & 63) == 63 and not _all_finite(x):
            return s + 1, CL_NONFINITE
    if not _all_finite(x):
        return n_steps, CL_NONFINITE
    return n_steps, CL_OK


# ------------------------------------------------------------------------------ Python driver
@dataclass(frozen=True)
class ClosedLoopRun:
    """Result of :meth:`ClosedLoopSimulator.run`.

    Attributes
    ----------
    time : numpy.ndarray, shape (k,)
        Output times [s].
    outputs : dict of str -> numpy.ndarray, shape (k,)
        Plant outputs (actuator power with the applied forces).
    forces : numpy.ndarray, shape (k, 2 n_sites)
        Applied actuator forces [N] (site 1 C, site 1 E, ...).
    result : StepResult
        ``ok`` or the divergence report (the samples stop there).
    """

    time: np.ndarray
    outputs: dict
    forces: np.ndarray
    result: StepResult


class ClosedLoopSimulator:
    """The plant with the strain law inside its right-hand side (continuous-time reference).

    Parameters
    ----------
    model : DrillstringModel
        A full 3D model with at least one actuator site.
    law : StrainLaw
    max_step : float, optional
        Largest internal RK4 step [s]; default the model's stable step. With a delay the step is
        also at most the delay.
    interpolation : {"hermite", "linear"}
        Continuous extension of the history for the delayed term (see the module docstring).

    Attributes
    ----------
    y : numpy.ndarray, shape (model.n_state,)
        The plant state (a view into the closed-loop state; set it before :meth:`run` to start
        elsewhere than the model's initial state).
    u_ext : numpy.ndarray, shape (model.n_inputs,)
        External inputs added to the law's forces (zero by default; the top-drive input, if any).
    """

    def __init__(self, model: DrillstringModel, law: StrainLaw, max_step: float | None = None,
                 interpolation: str = "hermite") -> None:
        if model.kind != "full3d" or model.n_sites == 0:
            raise ValueError("ClosedLoopSimulator needs model = 'full3d' with actuator sites "
                             f"(got {model.kind!r} with {model.n_sites} sites)")
        if not model.params.uniform or model.framed:
            raise ValueError("ClosedLoopSimulator serves the uniform pipe in a vertical hole (its "
                             "strains use the pipe's gauge radius and segment length); run a "
                             "string of sections or a curved hole through the co-simulation")
        if not isinstance(law, StrainLaw):
            raise TypeError(f"law must be a StrainLaw, got {type(law).__name__}")
        if interpolation not in INTERPOLATIONS:
            raise ValueError(f"interpolation = {interpolation!r} is not allowed: one of "
                             f"{', '.join(INTERPOLATIONS)}")
        self.model = model
        self.law = law
        self.interp = INTERPOLATIONS[interpolation]
        self._lw = law.vector()
        dt = stable_step(self._max_eigenvalue()) if max_step is None else float(max_step)
        if not (dt > 0.0 and math.isfinite(dt)):
            raise ValueError(f"max_step = {max_step!r} is not allowed: must be > 0 and finite (s)")
        if law.delay > 0.0:
            dt = min(dt, law.delay)
        self.max_step = dt
        N = model.n_state
        na = model.n_sites
        M = 2 * na
        self._N = N
        self._M = M
        lag = law.lag_time_constant > 0.0
        self.x = np.zeros(N + (M if lag else 0))
        self.x[:N] = model.initial_state()
        self.y = self.x[:N]
        self.u_ext = np.zeros(model.n_inputs)
        self._u_tot = np.zeros(model.n_inputs)
        comp = self._angle_indices()
        if lag:
            comp += [N + c for c in range(M)]
        self._ic = np.array(comp, dtype=np.int64)
        self._v = np.zeros(len(comp))
        self._R3 = np.zeros((3, 3, 3))
        self._eps = np.zeros(M)
        self._F = np.zeros(M)
        self._k = [np.zeros(self.x.size) for _ in range(5)]
        cap = (int(math.ceil(law.delay / dt)) + 4) if law.delay > 0.0 else 1
        self._ring(cap)
        bps = [*model.breakpoints.tolist()]
        if law.enabled:
            for b in (law.switch_on_time, law.delay, law.switch_on_time + law.delay):
                if b > 0.0:
                    bps.append(b)
        self.breakpoints = np.unique(np.array(bps, dtype=float))
        self.time = 0.0
        self._on = 0.0
        self._plant = PlantSimulator(model, max_step=self.max_step, method="rk4")
        self._plant.y = self.y  # the guards and their reports read the shared state

    def _max_eigenvalue(self) -> float:
        """Spectral radius [1/s] of the closed loop's Jacobian at the initial state (no delay,
        no saturation: the stiffest the law can make the loop), with the model's margins.

        ``J + K B E``: ``B`` = d(rhs)/d(forces) (exact: the rhs is linear in them), ``E`` =
        d(strains)/d(state) by central differences; with a lag, on ``[y, G]``.
        """
        m = self.model
        y0 = m.initial_state()
        J = m.initial_jacobian
        M = 2 * m.n_sites
        u0 = np.zeros(m.n_inputs)
        Bu = np.empty((m.n_state, M))
        for c in range(M):
            up, um = u0.copy(), u0.copy()
            up[c], um[c] = 1.0, -1.0
            Bu[:, c] = 0.5 * (m.rhs(0.0, y0, up) - m.rhs(0.0, y0, um))
        idx = [m.output_names.index(strain(s, a))
               for s, a in site_channels(range(1, m.n_sites + 1))]
        E = np.zeros((M, m.n_state))
        yp = y0.copy()
        for i in sorted(set(self._angle_indices())):
            h = 1e-7 * max(1.0, abs(y0[i]))
            yp[i] = y0[i] + h
            sp = m.outputs(0.0, yp, u0)[idx].copy()
            yp[i] = y0[i] - h
            sm = m.outputs(0.0, yp, u0)[idx].copy()
            yp[i] = y0[i]
            E[:, i] = (sp - sm) / (2.0 * h)
        K = self.law.gain if self.law.enabled else 0.0
        T = self.law.lag_time_constant
        if T <= 0.0:
            return m.spectral_radius_with_margins(J + K * Bu @ E)
        N = m.n_state
        Jc = np.zeros((N + M, N + M))
        Jc[:N, :N] = J
        Jc[:N, N:] = Bu
        Jc[N:, :N] = K / T * E
        Jc[N:, N:] = -np.eye(M) / T
        return m.spectral_radius_with_margins(Jc)

    def _angle_indices(self) -> list[int]:
        """State indices of the Cardan angles the gauges read (6 per site)."""
        oA = 3 * self.model.n
        out = []
        for j in self.model.sites:  # joint below body j (1-based): bodies j - 1 and j (0-based)
            out += [oA + 3 * (j - 1) + i for i in range(3)] + [oA + 3 * j + i for i in range(3)]
        return out

    def _ring(self, cap: int) -> None:
        """(Re)allocate the history ring with capacity ``cap``, keeping the stored steps."""
        nh = self._ic.size
        ht = np.zeros(cap)
        hx = np.zeros((cap, nh))
        hf = np.zeros((cap, nh))
        hon = np.zeros(cap)
        meta = np.zeros(2, dtype=np.int64)
        old = getattr(self, "_ht", None)
        if old is not None:
            count = int(self._meta[RG_COUNT])
            head = int(self._meta[RG_HEAD])
            order = [(head - count + 1 + i) % old.size for i in range(count)]
            ht[:count] = self._ht[order]
            hx[:count] = self._hx[order]
            hf[:count] = self._hf[order]
            hon[:count] = self._hon[order]
            meta[RG_COUNT] = count
            meta[RG_HEAD] = count - 1
        else:
            meta[RG_HEAD] = -1
        self._ht, self._hx, self._hf, self._hon, self._meta = ht, hx, hf, hon, meta

    def _advance(self, t0: float, n_steps: int, dt: float) -> int:
        m = self.model
        k1, k2, k3, k4, xt = self._k
        done = 0
        while True:
            s, code = advance_closed_loop(
                m.model_id, t0 + done * dt, self.x, n_steps - done, dt, self._N, m.p, m.ip, m.fp,
                self.u_ext, self._u_tot, m.wR, m.wF, m.wM, self._lw, self._ic, self._ht, self._hx,
                self._hf, self._hon, self._meta, self.interp, k1, k2, k3, k4, xt, self._v,
                self._R3, self._eps, self._F)
            done += int(s)
            if code == CL_HISTORY_FULL:
                self._ring(2 * self._ht.size)
                continue
            if code == CL_HISTORY_MISSING:
                raise RuntimeError(f"closed loop: delayed time {t0 + done * dt - self.law.delay!r}"
                                   " s is outside the kept history (internal error)")
            return done

    def advance_to(self, t1: float) -> StepResult:
        """Integrate from :attr:`time` to ``t1`` [s] (steps <= max_step, split at breakpoints)."""
        t = self.time
        while t < t1:
            te = next_breakpoint(t, t1, self.breakpoints)
            n_sub = max(1, math.ceil((te - t) / self.max_step - 1e-9))
            dt = (te - t) / n_sub
            done = self._advance(t, n_sub, dt)
            self._on = 1.0 if t + (done - 0.5) * dt >= self.law.switch_on_time else 0.0
            if done < n_sub:
                self.time = t + done * dt
                break
            t = te
            self.time = te
        self._plant.time = self.time
        return self._plant.check()

    def forces(self) -> np.ndarray:
        """Actuator forces [N] the law applies at the current time (left limit), shape (2 n_sites,)."""
        m = self.model
        code = applied_forces(self.time, self.x, 1, self._on, self._N, self._lw, m.p, m.ip,
                              self._ic, self._ht, self._hx, self._hf, self._hon, self._meta,
                              self.interp, self._v, self._R3, self._eps, self._F)
        if code != CL_OK:
            raise RuntimeError(f"closed loop: no history for the forces at t = {self.time!r} s")
        return self._F.copy()

    def outputs(self) -> np.ndarray:
        """Plant outputs at the current time with the applied forces (a reused view)."""
        F = self.forces()
        u = self._u_tot
        u[:] = self.u_ext
        u[:F.size] += F
        return self.model.outputs(self.time, self.y, u)

    def run(self, stop_time: float, output_interval: float,
            outputs: list[str] | None = None) -> ClosedLoopRun:
        """Integrate from :attr:`time` to ``stop_time`` [s], sampling every ``output_interval``.

        Returns
        -------
        ClosedLoopRun
        """
        names = outputs or self.model.output_names
        idx = [self.model.output_names.index(n) for n in names]
        n_out = int(round((stop_time - self.time) / output_interval))
        t0 = self.time
        ts, rows, frc = [self.time], [self.outputs()[idx].copy()], [self.forces()]
        res = StepResult(True)
        for k in range(1, n_out + 1):
            res = self.advance_to(t0 + k * output_interval)
            ts.append(self.time)
            rows.append(self.outputs()[idx].copy())
            frc.append(self.forces())
            if not res.ok:
                break
        arr = np.array(rows)
        return ClosedLoopRun(np.array(ts), {n: arr[:, i] for i, n in enumerate(names)},
                             np.array(frc), res)
