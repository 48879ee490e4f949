"""Linear, discrete-time stability prediction of the sampled strain-feedback loop.

The plant is linearized about the straight string spinning with the top drive
(:func:`analysis.linearize.linearize`, top-drive frame, where gauges and actuators
are body-fixed and the loop is linear time-invariant)::

    dx/dt = A x + B u,    s = C x        (u: actuator forces [N], s: strains [1])

The co-simulation holds ``u`` constant over each communication step ``H``
(FMI 2: no input derivatives), so the plant over one step is exactly the
zero-order-hold discretization ``x_{k+1} = Ad x_k + Bd u_k`` (``method="zoh"``,
matrix exponential of the augmented matrix), or the map of the plant's own
internal integrator (``method="rk4"``: ``ceil(H / max_step)`` RK4 sub-steps on the
linear system; the two agree to many digits for the drillstring).

The controller (:class:`controller.StrainController`) samples the strains at
the communication points and outputs, after each step, ``F = a F_prev + (1 - a)
K c`` with ``a = exp(-H / T_lag)`` (``a = 0`` without actuator lag, ``F = K c``).

Loop timing: taken from the master, not restated here. With samples ``s_k = C x_k``
and ``G_k`` the controller output computed from ``s_k`` (lag filter applied),

    u_k = sum_l W_l G_{k-l}

where ``W`` (:func:`loop_weights`) is the convolution of

* the exchange timing of the algorithm (:func:`cosim.master.algorithms.newest_sample_tick`):
  a connection whose source has already stepped to ``t_k+1`` when the target steps over
  ``[t_k, t_k+1]`` (Gauss-Seidel, source first) sees one sample more recent. The
  controller's output at ``t_k+1`` comes from the strains it held over ``[t_k, t_k+1]``
  (no direct feedthrough), so the loop's own delay is ``1 - j_sensor - j_actuator`` steps
  (``j``: how far ahead of ``t_k`` the newest source sample is): Gauss-Seidel either
  order 0, Jacobi 1;
* each connection's delay line (:class:`cosim.master.delays.DelayLine`): its weights are
  the line's response to a unit sample (:func:`line_weights`), the transport delay
  ``tau = (n + f) H`` (the sample ``n`` steps back, interpolated with the one ``n + 1``
  back for ``0 < f < 1``) and, with ``coupling="linear"``, the extrapolation to the
  midpoint of the target's step (horizon ``1/2 - j`` source steps).

The closed loop is the discrete system on ``z_k = [x_k, G_{k-1}, ..., G_{k-D}]``;
it is stable iff the spectral radius of its matrix is < 1. ``ln(rho) / H`` is
the growth rate [1/s] of the slowest-decaying (or fastest-growing) mode.

Only single-rate loops (controller period = communication step) are modelled.
"""

from __future__ import annotations

import math
import sys
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import scipy.linalg

from drillcosim.analysis.linearize import linearize
from drillcosim.cosim.master.algorithms import newest_sample_tick
from drillcosim.cosim.master.delays import DelayLine
from drillcosim.cosim.master.system import ALGORITHMS
from drillcosim.cosim.scenario.cache import cached_arrays, source_hash
from drillcosim.cosim.scenario.config import ConfigError, SceneConfig, load_config

__all__ = [
    "LoopModel",
    "closed_loop_matrix",
    "coupled_plant",
    "discretize",
    "line_weights",
    "loop_delay_steps",
    "loop_weights",
    "modal_bases",
    "reduce_loop",
    "spectral_radius",
]

_EPS = 1e-9


def discretize(A: np.ndarray, B: np.ndarray, step: float, method: str = "zoh",
               max_step: float | None = None) -> tuple[np.ndarray, np.ndarray]:
    """One communication step of ``dx/dt = A x + B u`` with ``u`` held.

    Parameters
    ----------
    A : numpy.ndarray, shape (N, N)
        System matrix [1/s].
    B : numpy.ndarray, shape (N, M)
        Input matrix [state units / (input unit s)].
    step : float
        Communication step H [s], > 0.
    method : {"zoh", "rk4"}
        ``"zoh"``: exact (matrix exponential of ``[[A, B], [0, 0]] H``).
        ``"rk4"``: ``ceil(H / max_step)`` classical RK4 sub-steps.
    max_step : float, optional
        Largest RK4 sub-step [s] (required for ``"rk4"``).

    Returns
    -------
    Ad : numpy.ndarray, shape (N, N)
    Bd : numpy.ndarray, shape (N, M)
    """
    if not (step > 0 and math.isfinite(step)):
        raise ValueError(f"step: a finite number > 0 [s], got {step!r}")
    n, m = B.shape
    if method == "zoh":
        aug = np.zeros((n + m, n + m))
        aug[:n, :n] = A * step
        aug[:n, n:] = B * step
        e = scipy.linalg.expm(aug)
        return e[:n, :n], e[:n, n:]
    if method != "rk4":
        raise ValueError(f"method = {method!r}: 'zoh' or 'rk4'")
    if max_step is None or not max_step > 0:
        raise ValueError("method 'rk4' needs max_step > 0 [s]")
    n_sub = max(1, math.ceil(step / max_step - _EPS))
    h = step / n_sub
    eye = np.eye(n)
    z = h * A
    z2 = z @ z
    z3 = z2 @ z
    r = eye + z + z2 / 2 + z3 / 6 + z3 @ z / 24
    s = (eye + z / 2 + z2 / 6 + z3 / 24) @ (h * B)
    ad = eye
    bd = np.zeros_like(B, dtype=float)
    for _ in range(n_sub):
        bd = r @ bd + s
        ad = r @ ad
    return ad, bd


def _scalar_map(lam: np.ndarray, step: float, method: str, max_step: float | None
                ) -> np.ndarray:
    """One-step amplification of ``dx/dt = lam x`` (as :func:`discretize`)."""
    if method == "zoh":
        return np.exp(lam * step)
    n_sub = max(1, math.ceil(step / max_step - _EPS))
    z = lam * step / n_sub
    return (1 + z + z**2 / 2 + z**3 / 6 + z**4 / 24) ** n_sub


def line_weights(delay_steps: float, coupling: str = "zoh", horizon: float = 0.5
                 ) -> dict[int, float]:
    """Weights of past samples delivered by one connection: the master's DelayLine's response.

    Parameters
    ----------
    delay_steps : float
        Transport delay in source sample periods, >= 0.
    coupling : {"zoh", "linear"}
    horizon : float
        Linear coupling only: time from the newest source sample to the midpoint
        of the target's step [source periods].

    Returns
    -------
    dict of int -> float
        ``{j: w_j}``: the delivered value is ``sum_j w_j s[-j]``, ``s[0]`` the
        newest sample (zero weights left out).
    """
    if not (delay_steps >= 0 and math.isfinite(delay_steps)):
        raise ValueError(f"delay: a finite number >= 0, got {delay_steps!r} steps")
    if coupling not in ("zoh", "linear"):
        raise ValueError(f"coupling = {coupling!r}: 'zoh' or 'linear'")
    line = DelayLine(delay_steps, 1.0, coupling == "linear")
    out: dict[int, float] = {}
    for j in range(line.depth):      # a unit sample j exchanges before the newest one
        line.reset(0.0)
        line.push(1.0)
        for _ in range(j):
            line.push(0.0)
        w = line.value(horizon)
        if w != 0.0:
            out[j] = w
    return out


def _convolve(a: Mapping[int, float], b: Mapping[int, float]) -> dict[int, float]:
    out: dict[int, float] = {}
    for i, wa in a.items():
        for j, wb in b.items():
            out[i + j] = out.get(i + j, 0.0) + wa * wb
    return {k: w for k, w in out.items() if w != 0.0}


def _lead(algorithm: str, order: Sequence[str], source: str, target: str) -> int:
    """Steps the newest sample of ``source`` is ahead of the start of ``target``'s step."""
    first = tuple(order).index(source) < tuple(order).index(target)
    return newest_sample_tick(algorithm, first, 1, 0)


def loop_delay_steps(algorithm: str, order: Sequence[str] = ("plant", "controller")) -> int:
    """Inherent delay of the strain loop [communication steps] (Gauss-Seidel 0, Jacobi 1)."""
    return 1 - _lead(algorithm, order, "plant", "controller") \
        - _lead(algorithm, order, "controller", "plant")


def loop_weights(actuator_delay_steps: float, sensor_delay_steps: float = 0.0,
                 algorithm: str = "gauss_seidel",
                 order: Sequence[str] = ("plant", "controller"),
                 coupling: str = "zoh") -> dict[int, float]:
    """Weights ``W_l`` of ``u_k = sum_l W_l G_{k-l}`` for the master's loop timing.

    Parameters
    ----------
    actuator_delay_steps, sensor_delay_steps : float
        Transport delays [communication steps], >= 0 (fractional: linear
        interpolation between samples, as the master does).
    algorithm : {"gauss_seidel", "jacobi"}
    order : sequence of str
        Stepping order of ``"plant"`` and ``"controller"`` (Gauss-Seidel).
    coupling : {"zoh", "linear"}

    Returns
    -------
    dict of int -> float
    """
    if algorithm not in ALGORITHMS:
        raise ValueError(f"algorithm = {algorithm!r}: one of {', '.join(ALGORITHMS)}")
    j_act = _lead(algorithm, order, "controller", "plant")
    j_sen = _lead(algorithm, order, "plant", "controller")
    w = _convolve(line_weights(actuator_delay_steps, coupling, 0.5 - j_act),
                  line_weights(sensor_delay_steps, coupling, 0.5 - j_sen))
    m0 = loop_delay_steps(algorithm, order)
    return {k + m0: v for k, v in sorted(w.items())}


def closed_loop_matrix(Ad: np.ndarray, Bd: np.ndarray, C: np.ndarray, gain: float,
                       weights: Mapping[int, float], lag: float = 0.0) -> np.ndarray:
    """Matrix of the sampled closed loop on ``z_k = [x_k, G_{k-1}, ..., G_{k-D}]``.

    Parameters
    ----------
    Ad, Bd : numpy.ndarray
        Discrete plant, shapes (N, N) and (N, M).
    C : numpy.ndarray, shape (M, N)
        Sensor matrix (strains per state unit).
    gain : float
        Controller gain K: ``G = K s`` (positive feedback sign as in
        :class:`controller.StrainController`, ``F = gain * strain``).
    weights : mapping int -> float
        From :func:`loop_weights`.
    lag : float
        Controller lag factor ``a = exp(-H / T)`` in [0, 1) (0: no lag).

    Returns
    -------
    numpy.ndarray, shape (N + D M, N + D M)
    """
    n, m = Bd.shape
    d = max([j for j, w in weights.items() if w != 0.0] + [1 if lag else 0])
    w0 = weights.get(0, 0.0)
    kc = gain * (1.0 - lag) * C          # G_k = lag G_{k-1} + kc x_k
    if d == 0:
        return Ad + w0 * Bd @ kc
    size = n + d * m
    M = np.zeros((size, size))
    M[:n, :n] = Ad + w0 * Bd @ kc
    if lag:
        M[:n, n:n + m] += w0 * lag * Bd
    for j in range(1, d + 1):
        wj = weights.get(j, 0.0)
        if wj:
            M[:n, n + (j - 1) * m:n + j * m] += wj * Bd
    # new G_k in slot 1
    M[n:n + m, :n] = kc
    if lag:
        M[n:n + m, n:n + m] = lag * np.eye(m)
    for j in range(1, d):
        M[n + j * m:n + (j + 1) * m, n + (j - 1) * m:n + j * m] = np.eye(m)
    return M


def reduce_loop(A: np.ndarray, B: np.ndarray, C: np.ndarray, tol: float = 1e-10
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Drop the modes the loop cannot see or cannot move (exactly, up to ``tol``).

    A mode with ``|w^T B| |C v|`` below ``tol`` times the largest one (``v``,
    ``w`` right/left eigenvectors) is uncontrollable or unobservable: feedback
    leaves its eigenvalue where it is. For the drillstring these are the axial and
    torsional modes (decoupled from bending in the straight string): 360 -> 240
    states, ~3x faster eigenvalues.

    Parameters
    ----------
    A, B, C : numpy.ndarray
        Continuous plant, shapes (N, N), (N, M), (M, N).
    tol : float
        Relative coupling threshold.

    Returns
    -------
    Ar, Br, Cr : numpy.ndarray
        Real reduced plant on the invariant subspace of the kept modes.
    dropped : numpy.ndarray
        Continuous eigenvalues of the dropped modes [1/s] (unchanged by feedback).
    """
    lam, V = scipy.linalg.eig(A)
    W = np.linalg.inv(V)
    score = np.linalg.norm(W @ B, axis=1) * np.linalg.norm(C @ V, axis=0)
    keep = score > tol * score.max()
    if keep.all():
        return A, B, C, np.zeros(0, dtype=complex)
    qk, qd = modal_bases(lam, V, keep)
    T = np.hstack([qk, qd])
    r = qk.shape[1]
    Ti = np.linalg.inv(T)
    At = Ti @ A @ T
    keep = keep | _conjugates(lam, keep)
    return At[:r, :r], (Ti @ B)[:r], (C @ T)[:, :r], lam[~keep]


def _conjugates(lam: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """The conjugate partners of the modes in ``mask``."""
    out = np.zeros_like(mask)
    for i in np.flatnonzero(mask):
        if lam[i].imag != 0:
            out[int(np.argmin(np.abs(lam - lam[i].conj())))] = True
    return out


def modal_bases(lam: np.ndarray, V: np.ndarray, keep: np.ndarray
                ) -> tuple[np.ndarray, np.ndarray]:
    """Real bases of the invariant subspaces of the kept modes and of the others.

    Parameters
    ----------
    lam : numpy.ndarray, shape (N,)
        Eigenvalues.
    V : numpy.ndarray, shape (N, N)
        Right eigenvectors (columns).
    keep : numpy.ndarray of bool, shape (N,)
        The modes to keep; a kept mode's conjugate is kept with it.

    Returns
    -------
    qk, qd : numpy.ndarray, shapes (N, r), (N, N - r)
        ``[Re v, Im v]`` of each kept (other) complex pair, ``v`` of a real mode: with
        ``T = [qk, qd]``, ``T^-1 A T`` is block diagonal (the first ``r`` states the kept modes).
    """
    keep = keep | _conjugates(lam, keep)

    def real_basis(mask: np.ndarray) -> np.ndarray:
        cols = []
        for i in np.flatnonzero(mask):
            v = V[:, i]
            if abs(lam[i].imag) > 0 and lam[i].imag < 0:
                continue                  # the conjugate gives the same real span
            cols.append(v.real)
            if abs(lam[i].imag) > 0:
                cols.append(v.imag)
        return np.array(cols).T if cols else np.zeros((len(lam), 0))

    return real_basis(keep), real_basis(~keep)


def coupled_plant(scene: Any, cache: bool = True
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, float]:
    """The scene's plant linearized (full 3D, top-drive frame) and reduced to the loop's modes.

    One linearization per plant and operating point: the result is a function of the plant's
    parameters (the operating point is theirs: :func:`analysis.linearize.operating_params`) and
    of the code, kept on disk by content (:func:`cosim.scenario.cache.cached_arrays`, key: the
    parameters, the sources of ``plant/`` and of this module, numpy's and scipy's versions).

    Parameters
    ----------
    scene : Scene
        A loaded :class:`plant.scene.Scene`.
    cache : bool
        Read and write the on-disk cache (False: always compute).

    Returns
    -------
    A, B, C, dropped : numpy.ndarray
        As :func:`reduce_loop` returns them for :func:`analysis.linearize.linearize`'s
        ``A`` [1/s], ``B``, ``C``.
    stable_step : float
        The plant model's own stable RK4 step [s].
    """
    def compute() -> dict[str, np.ndarray]:
        lin = linearize(scene.plant, "full3d")
        A, B, C, dropped = reduce_loop(lin.A, lin.B, lin.C)
        return {"A": A, "B": B, "C": C, "dropped": dropped,
                "stable_step": np.float64(lin.model.stable_step())}

    if cache:
        import drillcosim.plant as plant_package

        code = source_hash(str(Path(plant_package.__file__).parent), __file__)
        got = cached_arrays("loop_models", {"plant": repr(scene.plant), "model": "full3d",
                                            "code": code}, compute)
    else:
        got = compute()
    return got["A"], got["B"], got["C"], got["dropped"], float(got["stable_step"])


def spectral_radius(M: np.ndarray) -> float:
    """Largest eigenvalue modulus of ``M`` (stable iff < 1)."""
    if M.size == 0:
        return 0.0
    return float(np.max(np.abs(scipy.linalg.eigvals(M, check_finite=False))))


@dataclass
class LoopModel:
    """Sampled strain-feedback loop of a linearized plant; caches discretizations.

    Parameters
    ----------
    A, B, C : numpy.ndarray
        Continuous plant ``dx/dt = A x + B u``, ``s = C x``.
    algorithm : {"gauss_seidel", "jacobi"}
    order : tuple of str
        Gauss-Seidel stepping order.
    coupling : {"zoh", "linear"}
    sensor_delay : float
        Transport delay of the strains [s] (the sweeps vary the actuator delay).
    lag_time_constant : float
        Controller actuator lag T [s] (0: none).
    method : {"zoh", "rk4"}
        Plant discretization (see :func:`discretize`).
    max_step : float, optional
        Internal RK4 step of the plant [s] (``method="rk4"``).
    dropped : numpy.ndarray
        Continuous eigenvalues [1/s] of modes removed by :func:`reduce_loop`
        (they count in the spectral radius, feedback does not move them).

    Examples
    --------
    >>> lm = LoopModel.from_scene("paper_closed_loop")          # doctest: +SKIP
    >>> lm.growth_rate(gain=1e9, delay=0.0, step=2.5e-4) < 0    # doctest: +SKIP
    True
    """

    A: np.ndarray
    B: np.ndarray
    C: np.ndarray
    algorithm: str = "gauss_seidel"
    order: tuple[str, ...] = ("plant", "controller")
    coupling: str = "zoh"
    sensor_delay: float = 0.0
    lag_time_constant: float = 0.0
    method: str = "zoh"
    max_step: float | None = None
    dropped: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=complex))
    _cache: dict[float, tuple[np.ndarray, np.ndarray]] = field(default_factory=dict,
                                                               repr=False)
    _modal: dict[str, Any] = field(default_factory=dict, repr=False)   # cosim.study.boundary

    @classmethod
    def from_scene(cls, scene: str | Any = "paper_closed_loop",
                   overrides: Mapping[str, Any] | None = None, **kwargs: Any) -> LoopModel:
        """Linearize a scene's plant and take the loop timing from its ``[cosim]``.

        Parameters
        ----------
        scene : str or SceneConfig
            Scene name/path, or a loaded :class:`cosim.scenario.config.SceneConfig`.
        overrides : mapping, optional
            Scene keys by key path (with a scene name).
        **kwargs
            Override any field (e.g. ``algorithm="jacobi"``, ``method="rk4"``).
        """
        config = scene if isinstance(scene, SceneConfig) else load_config(scene, overrides)
        sc = config.scene
        if sc.model != "full3d":
            raise ConfigError(f"scene {sc.name!r}: the stability prediction linearizes the "
                              "lateral strain loop (strain gauges -> bending actuators), which "
                              f"model {sc.model!r} does not have; allowed: a full3d scene")
        if config.controller.kind != "proportional":
            raise ConfigError(f"scene {sc.name!r}: the stability prediction models the P law "
                              f"(kind 'proportional'), not kind {config.controller.kind!r}")
        st = config.cosim
        if st.controller_ticks != 1:
            raise ConfigError("LoopModel: only controller_sample_period = step is modelled")
        A, B, C, dropped, stable_step = coupled_plant(sc)
        opts: dict[str, Any] = {
            "algorithm": st.algorithm, "order": tuple(st.order), "coupling": st.coupling,
            "sensor_delay": st.sensor_delay,
            "lag_time_constant": config.controller.params.lag_time_constant,
        }
        if kwargs.get("method") == "rk4" and "max_step" not in kwargs:
            kwargs["max_step"] = stable_step
        opts.update(kwargs)
        return cls(A, B, C, dropped=dropped, **opts)

    # -- pieces ------------------------------------------------------------------
    def discrete(self, step: float) -> tuple[np.ndarray, np.ndarray]:
        """``(Ad, Bd)`` for communication step ``step`` [s] (cached)."""
        key = float(step)
        if key not in self._cache:
            self._cache[key] = discretize(self.A, self.B, key, self.method, self.max_step)
        return self._cache[key]

    def matrix(self, gain: float, delay: float, step: float) -> np.ndarray:
        """Closed-loop matrix for gain K [N/strain], actuator delay [s], step H [s]."""
        if not (delay >= 0 and math.isfinite(delay)):
            raise ValueError(f"delay: a finite number >= 0 [s], got {delay!r}")
        Ad, Bd = self.discrete(step)
        w = loop_weights(delay / step, self.sensor_delay / step, self.algorithm, self.order,
                         self.coupling)
        lag = math.exp(-step / self.lag_time_constant) if self.lag_time_constant > 0 else 0.0
        return closed_loop_matrix(Ad, Bd, self.C, gain, w, lag)

    def spectral_radius(self, gain: float, delay: float, step: float) -> float:
        """Spectral radius of the closed loop (stable iff < 1)."""
        rho = spectral_radius(self.matrix(gain, delay, step))
        if self.dropped.size:
            rho = max(rho, float(np.max(np.abs(_scalar_map(self.dropped, step, self.method,
                                                           self.max_step)))))
        return rho

    def growth_rate(self, gain: float, delay: float, step: float) -> float:
        """``ln(rho) / H`` [1/s]: > 0 unstable (e-folding rate of the worst mode)."""
        rho = self.spectral_radius(gain, delay, step)
        return math.log(rho) / step if rho > 0 else -math.inf

    def is_stable(self, gain: float, delay: float, step: float) -> bool:
        """True iff the spectral radius is < 1."""
        return self.spectral_radius(gain, delay, step) < 1.0

    # -- boundaries --------------------------------------------------------------
    def critical_gain(self, step: float, delay: float = 0.0, gain_min: float = 1e3,
                      gain_max: float = 1e13, per_decade: int = 4, rtol: float = 1e-3
                      ) -> float:
        """Smallest gain [N/strain] at which the loop turns unstable.

        Scans log-spaced gains from ``gain_min`` (``per_decade`` a decade) for the
        first unstable one, then bisects (geometrically) to ``rtol``.

        Returns
        -------
        float
            ``inf`` if stable up to ``gain_max``; ``0`` if unstable at ``gain_min``.
        """
        def unstable(k: float) -> bool:
            return not self.is_stable(k, delay, step)

        return _first_crossing(unstable, gain_min, gain_max, per_decade, rtol, log=True)

    def critical_delay(self, gain: float, step: float, delay_max: float | None = None,
                       per_step: int = 4, atol: float | None = None) -> float:
        """Smallest actuator delay [s] at which the loop turns unstable.

        Scans delays ``0, H/per_step, 2 H/per_step, ...`` up to ``delay_max``
        (default ``40 H``) for the first unstable one, then bisects to ``atol``
        (default ``H / 1000``).

        Returns
        -------
        float
            ``inf`` if stable up to ``delay_max``; ``0`` if unstable without delay.
        """
        delay_max = 40 * step if delay_max is None else delay_max
        atol = step * 1e-3 if atol is None else atol

        def unstable(tau: float) -> bool:
            return not self.is_stable(gain, tau, step)

        if unstable(0.0):
            return 0.0
        n = max(1, math.ceil(delay_max / step * per_step))
        grid = np.linspace(0.0, delay_max, n + 1)
        lo = 0.0
        for tau in grid[1:]:
            if unstable(float(tau)):
                return _bisect(unstable, lo, float(tau), atol, log=False)
            lo = float(tau)
        return math.inf


def _bisect(unstable, lo: float, hi: float, tol: float, log: bool) -> float:
    """Bisect between stable ``lo`` and unstable ``hi``; returns the midpoint."""
    while (hi / lo - 1.0 if log else hi - lo) > tol:
        mid = math.sqrt(lo * hi) if log else 0.5 * (lo + hi)
        if unstable(mid):
            hi = mid
        else:
            lo = mid
    return math.sqrt(lo * hi) if log else 0.5 * (lo + hi)


def _first_crossing(unstable, x_min: float, x_max: float, per_decade: int, rtol: float,
                    log: bool) -> float:
    if unstable(x_min):
        return 0.0
    n = max(1, math.ceil(math.log10(x_max / x_min) * per_decade))
    lo = x_min
    for x in np.geomspace(x_min, x_max, n + 1)[1:]:
        if unstable(float(x)):
            return _bisect(unstable, lo, float(x), rtol, log)
        lo = float(x)
    return math.inf


def _boundary_report(scene: str = "paper_closed_loop") -> list[str]:
    """The numbers of ``docs/delay_study.md`` (``python -m drillcosim.cosim.study.stability [SCENE]``)."""
    lm = LoopModel.from_scene(scene)
    lines = [f"scene {scene}: loop {lm.algorithm} (inherent delay "
             f"{loop_delay_steps(lm.algorithm, lm.order)} step), coupling {lm.coupling}, "
             f"{lm.A.shape[0]} coupled states ({lm.dropped.size} decoupled modes dropped)"]
    for h in (1e-4, 2.5e-4):
        tau = lm.critical_delay(1e9, h, delay_max=1e-3, per_step=2)
        lines.append(f"critical delay at K = 1e9, H = {h * 1e3:g} ms: {tau * 1e6:.1f} us")
    for tau in (0.0, 1e-4, 2e-4, 5e-4, 1e-3, 2e-3):
        kc = lm.critical_gain(2.5e-4, tau, gain_min=1e5, gain_max=1e11, per_decade=2,
                              rtol=0.01)
        lines.append(f"critical gain at H = 0.25 ms, tau = {tau * 1e3:g} ms: {kc:.3g} N/strain")
    for h in (1e-4, 2.5e-4, 3.5e-4, 4e-4, 4.5e-4, 5e-4, 7.5e-4, 1e-3):
        lines.append(f"K = 1e9, tau = 0, H = {h * 1e3:g} ms: growth rate "
                     f"{lm.growth_rate(1e9, 0.0, h):+.3f} 1/s")
    for k, tau, h in ((1e9, 1e-4, 2.5e-4), (1e9, 2e-4, 2.5e-4), (1e9, 5e-4, 2.5e-4),
                      (1e9, 1e-3, 2.5e-4), (1e6, 2e-3, 2.5e-4), (1e6, 0.0, 1e-3)):
        M = lm.matrix(k, tau, h)
        ev = scipy.linalg.eigvals(M)
        z = ev[np.argmax(np.abs(ev))]
        s = np.log(z) / h
        lines.append(f"K = {k:g}, tau = {tau * 1e3:g} ms, H = {h * 1e3:g} ms: growth "
                     f"{s.real:+.3f} 1/s at {abs(s.imag):.0f} rad/s")
    return lines


if __name__ == "__main__":  # pragma: no cover
    try:
        print("\n".join(_boundary_report(*sys.argv[1:2])))
    except ValueError as exc:
        print(f"stability: error: {exc}", file=sys.stderr)
        sys.exit(2)
