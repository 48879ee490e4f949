"""Critical gains of the sampled strain loop from its frequency response, checked on the
closed-loop matrix.

:meth:`cosim.study.stability.LoopModel.critical_gain` finds the gain where the loop turns
unstable by scanning and bisecting, one eigenvalue problem of the closed-loop matrix (~240
states) per trial gain, ~15 per delay. The loop has more structure: with ``P(z) = C (zI -
Ad)^-1 Bd`` the plant's transfer matrix over one step (``m x m``, ``m`` strain channels) and

    D(z) = (1 - a) sum_l W_l z^-l / (1 - a z^-1)

the loop's timing (:func:`cosim.study.stability.loop_weights`) and the controller's lag ``a``,
the same scalar on every channel, the closed loop's poles are the ``z`` with
``det(I - K D(z) P(z)) = 0`` (besides the modes the loop does not see). A pole on the unit circle
``z = exp(i theta)`` at a gain ``K > 0`` means ``1 / K`` is an eigenvalue of ``D(z) P(z)``: ``D``
times an eigenvalue ``nu`` of ``P`` is real and positive. With the open loop stable (every pole
inside the circle), poles move continuously with ``K``, so the smallest such ``K`` is the
critical gain.

The eigenvalues ``nu(theta)`` depend on the plant and the step only: they are computed once per
step (:class:`StepResponse`) on a grid over ``[0, pi]`` (conjugate symmetry gives the rest),
dense around every plant pole (a lightly damped mode swings ``nu`` through a large circle within
a few pole widths ``1 - |mu|``). Each delay then multiplies them by its scalar ``D``; a change of
the number of eigenvalues above the real axis between two grid points is a crossing, bisected to
machine precision. The plant's transfer matrix comes from its modes (``A = V diag(lam) V^-1``,
the same discretization as :func:`cosim.study.stability.discretize`, mode by mode).

:func:`critical_gains` checks every result on the closed-loop matrix (stable just below it,
unstable just above, within the requested tolerance) and falls back to the scan and bisection
where the check fails or the open loop is not strictly stable, so its answers are those of
:meth:`LoopModel.critical_gain` to the tolerance, at ~1/10 of its cost.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import scipy.linalg
from threadpoolctl import threadpool_limits
from tqdm import tqdm

from .stability import _EPS, LoopModel, _scalar_map, loop_weights

__all__ = ["StepResponse", "critical_gains", "frequency_critical_gain", "growth_rates",
           "loop_timing", "spectral_radii"]

#: Pole-width multiples of the grid around each plant pole (``sinh``-spaced, up to ~200).
_AROUND = np.sinh(np.linspace(-6.0, 6.0, 61))
#: Uniform grid points over ``[0, pi]``.
_UNIFORM = 4001
#: Bisection steps of a crossing in ``theta`` (grid interval / 2^52: machine precision).
_BISECT = 52


@dataclass(frozen=True)
class _Modes:
    """The plant's modes: ``lam`` [1/s], ``cv = C V`` and ``wb = V^-1 B``."""

    lam: np.ndarray
    cv: np.ndarray
    wb: np.ndarray


def _modes(lm: LoopModel) -> _Modes:
    modes = lm._modal.get("modes")
    if modes is None:
        lam, V = scipy.linalg.eig(lm.A)
        modes = lm._modal["modes"] = _Modes(lam, lm.C @ V, np.linalg.solve(V, lm.B))
    return modes


def _input_map(lam: np.ndarray, step: float, method: str, max_step: float | None
               ) -> tuple[np.ndarray, np.ndarray]:
    """Per mode ``dx/dt = lam x + u`` over one step with ``u`` held: ``(mu, phi)``, ``x_{k+1} =
    mu x_k + phi u_k`` (as :func:`cosim.study.stability.discretize` does it)."""
    if method == "zoh":
        z = lam * step
        small = np.abs(z) < 1e-12
        phi = np.where(small, step, np.expm1(z) / np.where(small, 1.0, lam))
        return np.exp(z), phi
    n_sub = max(1, math.ceil(step / max_step - _EPS))
    h = step / n_sub
    z = lam * h
    r = 1 + z + z**2 / 2 + z**3 / 6 + z**4 / 24
    s = (1 + z / 2 + z**2 / 6 + z**3 / 24) * h
    rn = r ** n_sub
    near = np.abs(r - 1) < 1e-12
    return rn, s * np.where(near, n_sub, (rn - 1) / np.where(near, 2.0, r - 1))


def loop_timing(lm: LoopModel, delay: float, step: float) -> tuple[dict[int, float], float]:
    """``(W, a)``: the loop's weights (:func:`cosim.study.stability.loop_weights`) and the lag
    factor of :meth:`LoopModel.matrix` for actuator delay ``delay`` [s] and step ``step`` [s]."""
    w = loop_weights(delay / step, lm.sensor_delay / step, lm.algorithm, lm.order, lm.coupling)
    lag = math.exp(-step / lm.lag_time_constant) if lm.lag_time_constant > 0 else 0.0
    return w, lag


def _loop_scalar(z: np.ndarray, weights: dict[int, float], lag: float) -> np.ndarray:
    """``D(z) = (1 - a) sum_l W_l z^-l / (1 - a z^-1)``."""
    zi = 1.0 / z
    w = sum(wl * zi**l for l, wl in weights.items())
    return (1.0 - lag) * w / (1.0 - lag * zi)


class StepResponse:
    """The eigenvalues of the plant's transfer matrix ``P(exp(i theta))`` for one step.

    Parameters
    ----------
    lm : LoopModel
    step : float
        Communication step H [s].

    Attributes
    ----------
    theta : numpy.ndarray, shape (N,)
        Grid over ``[0, pi]`` [rad per step], dense near the plant poles.
    nu : numpy.ndarray, shape (N, m)
        Eigenvalues of ``P`` at ``exp(i theta)`` (unordered).
    open_loop_radius : float
        Largest plant pole modulus (the loop's modes): the method needs it < 1 (else
        ``theta`` and ``nu`` are empty).
    """

    def __init__(self, lm: LoopModel, step: float):
        self.modes = _modes(lm)
        self.mu, self.phi = _input_map(self.modes.lam, step, lm.method, lm.max_step)
        self.open_loop_radius = float(np.max(np.abs(self.mu), initial=0.0))
        if not self.open_loop_radius < 1.0:        # a pole on or outside the circle: no grid
            self.theta, self.nu = np.zeros(0), np.zeros((0, len(self.modes.cv)))
            return
        arg = np.angle(self.mu)
        width = np.maximum(1.0 - np.abs(self.mu), 1e-12)
        up = arg >= 0
        near = (arg[up][:, None] + width[up][:, None] * _AROUND[None, :]).ravel()
        theta = np.concatenate([np.linspace(0.0, math.pi, _UNIFORM), near])
        self.theta = np.unique(theta[(theta >= 0.0) & (theta <= math.pi)])
        self.nu = np.concatenate([self.eigenvalues(self.theta[i:i + 2000])
                                  for i in range(0, len(self.theta), 2000)])

    def transfer(self, theta: np.ndarray) -> np.ndarray:
        """``P(exp(i theta))``, shape (len(theta), m, m)."""
        g = self.phi[None, :] / (np.exp(1j * theta)[:, None] - self.mu[None, :])
        return (self.modes.cv[None, :, :] * g[:, None, :]) @ self.modes.wb

    def eigenvalues(self, theta: np.ndarray) -> np.ndarray:
        """Eigenvalues of :meth:`transfer`, shape (len(theta), m)."""
        return np.linalg.eigvals(self.transfer(np.atleast_1d(theta)))


def _above(values: np.ndarray) -> np.ndarray:
    return np.count_nonzero(values.imag > 0, axis=-1)


def frequency_critical_gain(response: StepResponse, weights: dict[int, float], lag: float
                            ) -> float:
    """Smallest gain ``K > 0`` with a closed-loop pole on the unit circle [N/strain] (``inf``:
    none), from the frequency response (module docstring). Assumes the open loop is stable."""
    def loop(theta: np.ndarray, nu: np.ndarray) -> np.ndarray:
        return _loop_scalar(np.exp(1j * theta), weights, lag)[:, None] * nu

    theta = response.theta
    lam = loop(theta, response.nu)
    count = _above(lam)
    cross = np.flatnonzero(np.diff(count))
    best = 0.0
    if cross.size:        # every crossing bisected at once, to machine precision
        a, b, ca = theta[cross], theta[cross + 1], count[cross]
        for _ in range(_BISECT):
            mid = 0.5 * (a + b)
            lower = _above(loop(mid, response.eigenvalues(mid))) == ca
            a, b = np.where(lower, mid, a), np.where(lower, b, mid)
        vals = loop(b, response.eigenvalues(b))
        crossing = vals[np.arange(len(b)), np.argmin(np.abs(vals.imag), axis=1)]
        best = max(best, float(np.max(crossing.real)))
    for end in (0, -1):              # z = 1 and z = -1: D P is real there
        vals = lam[end]
        real = vals[np.abs(vals.imag) <= 1e-9 * max(float(np.max(np.abs(vals))), 1e-300)]
        if real.size:
            best = max(best, float(np.max(real.real)))
    return 1.0 / best if best > 0 else math.inf


def critical_gains(lm: LoopModel, step: float, delays: Sequence[float], gain_min: float = 1e3,
                   gain_max: float = 1e13, per_decade: int = 4, rtol: float = 1e-3,
                   progress: tqdm | None = None) -> list[float]:
    """:meth:`LoopModel.critical_gain` at each delay [s] for one step [s], fast.

    Parameters
    ----------
    lm : LoopModel
    step : float
        Communication step H [s].
    delays : sequence of float
        Actuator delays [s].
    gain_min, gain_max, per_decade, rtol
        As for :meth:`LoopModel.critical_gain` (``per_decade``: its scan, where the check fails).
    progress : tqdm, optional
        Advanced by one per delay.

    Returns
    -------
    list of float
        The critical gain [N/strain] per delay: ``inf`` if stable up to ``gain_max``, ``0`` if
        unstable at ``gain_min``. Where the frequency response gives it (the open loop strictly
        stable), the exact crossing, checked on the closed-loop matrix: stable at ``K / (1 +
        rtol / 2)``, unstable at ``K (1 + rtol / 2)``; elsewhere :meth:`LoopModel.critical_gain`
        (the bisection's midpoint).
    """
    delays = [float(d) for d in delays]
    found = [math.nan] * len(delays)
    dropped = float(np.max(np.abs(_scalar_map(lm.dropped, step, lm.method, lm.max_step)),
                           initial=0.0))
    if dropped < 1.0:
        response = StepResponse(lm, step)
        if response.open_loop_radius < 1.0:
            found = [frequency_critical_gain(response, *loop_timing(lm, d, step))
                     for d in delays]
    # the check: two gains per delay; (gain, expected stable) or None
    f = 1.0 + 0.5 * rtol
    checks = []
    for k in found:
        if math.isnan(k):
            checks.append(())
        elif k < gain_min:
            checks.append(((gain_min, False),))
        elif k > gain_max:
            checks.append(((gain_max, True),))
        else:
            checks.append(((k / f, True), (k * f, False)))
    radii = iter(spectral_radii(lm, [(g, d, step) for d, c in zip(delays, checks)
                                     for g, _ in c]))
    out = []
    for d, k, c in zip(delays, found, checks):
        confirmed = bool(c) and all((next(radii) < 1.0) == want for _, want in c)
        if not confirmed:
            k = lm.critical_gain(step, d, gain_min=gain_min, gain_max=gain_max,
                                 per_decade=per_decade, rtol=rtol)
        out.append(0.0 if k < gain_min else (math.inf if k > gain_max else k))
        if progress is not None:
            progress.update(1)
    return out


def spectral_radii(lm: LoopModel, points: Sequence[tuple[float, float, float]],
                   threads: int | None = None) -> list[float]:
    """:meth:`LoopModel.spectral_radius` of each ``(gain, delay, step)``, the eigenvalue problems
    on ``threads`` threads (default: the cores, at most 4; numpy's LAPACK call releases the
    GIL), in order."""
    if not points:
        return []
    import os
    from concurrent.futures import ThreadPoolExecutor

    def radius(point: tuple[float, float, float]) -> float:
        gain, delay, step = point
        M = lm.matrix(gain, delay, step)
        rho = float(np.max(np.abs(np.linalg.eigvals(M)))) if M.size else 0.0
        if lm.dropped.size:
            rho = max(rho, float(np.max(np.abs(_scalar_map(lm.dropped, step, lm.method,
                                                            lm.max_step)))))
        return rho

    for step in {p[2] for p in points}:
        lm.discrete(step)             # once, before the threads share it
    n = min(len(points), threads or min(os.cpu_count() or 1, 4))
    with threadpool_limits(1):      # ~250 states: one BLAS thread per problem is fastest
        if n <= 1:
            return [radius(p) for p in points]
        with ThreadPoolExecutor(n) as pool:
            return list(pool.map(radius, points))


def growth_rates(lm: LoopModel, points: Sequence[tuple[float, float, float]],
                 progress: tqdm | None = None) -> list[float]:
    """:meth:`LoopModel.growth_rate` [1/s] of each ``(gain, delay, step)`` (one eigenvalue
    problem each, on the cores' threads: :func:`spectral_radii`); ``progress`` advanced by
    ``len(points)``."""
    rates = [math.log(rho) / p[2] if rho > 0 else -math.inf
             for rho, p in zip(spectral_radii(lm, list(points)), points)]
    if progress is not None:
        progress.update(len(rates))
    return rates
