"""Continuous-time linear stability of the strain-feedback loop, and the runs that check it.

The discrete prediction (:mod:`cosim.study.stability`) models what the co-simulation does:
strains sampled every communication step H, forces held. Its continuous limit is the loop with
the law inside the plant's right-hand side (:class:`analysis.closed_loop.ClosedLoopSimulator`)::

    dx/dt = A x(t) + B F(t),    F(t) = g * (C x)(t - tau)              (no lag)
    T dG/dt = K C x - G,        F(t) = G(t - tau)                       (lag T > 0)

about the straight string spinning with the top drive (``analysis.linearize``, top-drive frame,
where gauges and actuators are body-fixed and the loop is time-invariant; saturation is not
modelled: the analysis is for forces inside the limits). Characteristic equation::

    det M(s) = 0,   M(s) = s I - A - g(s) B C,   g(s) = K exp(-s tau) / (1 + s T)

* ``tau = 0``: the eigenvalues of ``A + K B C`` (with a lag: of the matrix with the G states).
* ``tau > 0``: a retarded delay equation with infinitely many roots, finitely many in any right
  half plane. :meth:`ContinuousLoop.roots` takes the rightmost eigenvalues of the loop with a
  Pade ``[p/p]`` approximation of ``exp(-s tau)`` per channel and refines each by Newton's
  method on ``det M(s)`` itself (``ds = -1 / tr(M(s)^-1 M'(s))``), so the returned roots solve
  the exact characteristic equation; :meth:`ContinuousLoop.chebyshev_roots` is an independent
  discretization (pseudospectral collocation of the infinitesimal generator on Chebyshev nodes
  in ``[-tau, 0]``, Breda, Maset & Vermiglio, SIAM J. Sci. Comput. 27, 2005) used to check it.

The growth rate of the loop is the largest real part of the roots [1/s]; the critical gain and
the critical delay are where it crosses 0. ``python -m drillcosim.cosim.study.continuous`` prints
the numbers of ``docs/delay_study.md`` (section 5).
"""

from __future__ import annotations

import math
import sys
import time
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from math import factorial
from pathlib import Path
from typing import Any

import numpy as np
import scipy.linalg
import scipy.signal
from threadpoolctl import threadpool_limits

from drillcosim.analysis.closed_loop import ClosedLoopSimulator, StrainLaw
from drillcosim.analysis.equilibrium import static_equilibrium
from drillcosim.analysis.linearize import operating_params
from drillcosim.cosim.scenario.config import SceneConfig, load_config
from drillcosim.plant.model import DrillstringModel

from .stability import LoopModel, _bisect, _first_crossing

__all__ = [
    "ContinuousLoop",
    "pade_delay",
    "law_from_scene",
    "operating_point_simulator",
    "envelope_growth_rate",
]


def pade_delay(order: int, delay: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """State-space ``(a, b, c, d)`` of the Pade ``[p/p]`` approximation of ``exp(-s delay)``.

    Coefficients ``c_k = (2p - k)! p! / ((2p)! k! (p - k)!)``: numerator ``sum c_k (-s tau)^k``,
    denominator ``sum c_k (s tau)^k``. Realized in the scaled variable ``s tau`` and rescaled
    (better conditioned than the polynomial in ``s``).

    Parameters
    ----------
    order : int
        p >= 1.
    delay : float
        tau > 0 [s].

    Returns
    -------
    a : numpy.ndarray, shape (p, p)  [1/s]
    b : numpy.ndarray, shape (p, 1)  [1/s]
    c : numpy.ndarray, shape (1, p)
    d : numpy.ndarray, shape (1, 1)
    """
    if not (isinstance(order, int) and order >= 1):
        raise ValueError(f"order = {order!r}: an integer >= 1")
    if not (delay > 0 and math.isfinite(delay)):
        raise ValueError(f"delay = {delay!r}: a finite number > 0 [s]")
    p = order
    coef = [factorial(2 * p - k) * factorial(p) / (factorial(2 * p) * factorial(k)
                                                   * factorial(p - k)) for k in range(p + 1)]
    num = [coef[k] * (-1) ** k for k in range(p + 1)][::-1]
    den = coef[::-1]
    a, b, c, d = scipy.signal.tf2ss(num, den)
    return a / delay, b / delay, c, d


@dataclass
class ContinuousLoop:
    """The strain-feedback loop of a linearized plant in continuous time.

    Parameters
    ----------
    A, B, C : numpy.ndarray
        Plant ``dx/dt = A x + B F``, strains ``C x``; shapes (N, N), (N, M), (M, N).
    lag_time_constant : float
        Controller lag T [s] (0: none).
    dropped : numpy.ndarray
        Eigenvalues [1/s] of modes the loop cannot see (:func:`cosim.study.stability.reduce_loop`);
        they bound the growth rate from below.
    pade_order : int
        Order p of the Pade approximation used to find the roots before Newton refinement.
    """

    A: np.ndarray
    B: np.ndarray
    C: np.ndarray
    lag_time_constant: float = 0.0
    dropped: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=complex))
    pade_order: int = 6

    @classmethod
    def from_scene(cls, scene: str | Any = "paper_closed_loop",
                   overrides: Mapping[str, Any] | None = None, **kwargs: Any) -> ContinuousLoop:
        """The continuous limit of the scene's sampled loop (:meth:`from_loop_model` of
        ``LoopModel.from_scene(scene, overrides)``: the same linearization and lag).

        ``kwargs`` override fields (e.g. ``pade_order=8``).
        """
        return cls.from_loop_model(LoopModel.from_scene(scene, overrides), **kwargs)

    @classmethod
    def from_loop_model(cls, lm: Any, **kwargs: Any) -> ContinuousLoop:
        """The continuous loop of a discrete :class:`cosim.study.stability.LoopModel`: its plant
        ``(A, B, C)``, dropped modes and lag time constant, without the sampling."""
        opts: dict[str, Any] = {"lag_time_constant": lm.lag_time_constant,
                                "dropped": lm.dropped}
        opts.update(kwargs)
        return cls(lm.A, lm.B, lm.C, **opts)

    # -- matrices ----------------------------------------------------------------------------
    def matrix(self, gain: float) -> np.ndarray:
        """Closed-loop matrix without delay: ``A + K B C`` (with a lag, on ``[x, G]``)."""
        T = self.lag_time_constant
        if T <= 0.0:
            return self.A + gain * self.B @ self.C
        n, m = self.B.shape
        M = np.zeros((n + m, n + m))
        M[:n, :n] = self.A
        M[:n, n:] = self.B
        M[n:, :n] = gain / T * self.C
        M[n:, n:] = -np.eye(m) / T
        return M

    def pade_matrix(self, gain: float, delay: float, order: int | None = None) -> np.ndarray:
        """Closed-loop matrix with ``exp(-s delay)`` replaced by its Pade ``[p/p]`` form.

        States ``[x, z]`` (no lag) or ``[x, G, z]`` (lag), ``z`` the Pade states of every channel.
        """
        if delay <= 0.0:
            return self.matrix(gain)
        a, b, c, d = pade_delay(order or self.pade_order, delay)
        n, m = self.B.shape
        eye = np.eye(m)
        Ap, Bp, Cp, Dp = (np.kron(eye, q) for q in (a, b, c, d))
        T = self.lag_time_constant
        if T <= 0.0:  # delayed signal: K C x
            top = np.hstack([self.A + gain * self.B @ Dp @ self.C, gain * self.B @ Cp])
            bot = np.hstack([Bp @ self.C, Ap])
            return np.vstack([top, bot])
        q = Ap.shape[0]  # delayed signal: the lag state G
        M = np.zeros((n + m + q, n + m + q))
        M[:n, :n] = self.A
        M[:n, n:n + m] = self.B @ Dp
        M[:n, n + m:] = self.B @ Cp
        M[n:n + m, :n] = gain / T * self.C
        M[n:n + m, n:n + m] = -eye / T
        M[n + m:, n:n + m] = Bp
        M[n + m:, n + m:] = Ap
        return M

    # -- roots ----------------------------------------------------------------------------------
    def _g(self, s: complex, gain: float, delay: float) -> tuple[complex, complex]:
        """Loop transfer factor g(s) and its derivative g'(s)."""
        T = self.lag_time_constant
        e = gain * np.exp(-s * delay)
        if T <= 0.0:
            return e, -delay * e
        q = 1.0 + s * T
        return e / q, e * (-delay / q - T / q**2)

    def refine(self, s: complex, gain: float, delay: float, max_iter: int = 50) -> complex:
        """Newton's method on ``det M(s)`` from ``s`` [1/s]: a root of the exact equation."""
        n = self.A.shape[0]
        eye = np.eye(n)
        BC = self.B @ self.C
        for _ in range(max_iter):
            g, dg = self._g(s, gain, delay)
            M = s * eye - self.A - g * BC
            Mp = eye - dg * BC
            step = 1.0 / np.trace(np.linalg.solve(M, Mp))
            s = s - step
            if abs(step) <= 1e-13 * max(1.0, abs(s)):
                break
        return complex(s)

    def roots(self, gain: float, delay: float = 0.0, count: int = 6,
              order: int | None = None) -> np.ndarray:
        """The ``count`` rightmost characteristic roots [1/s], largest real part first.

        Without a delay these are eigenvalues; with a delay, Pade eigenvalues refined on the
        exact equation (:meth:`refine`). Roots of the dropped modes are not included.
        """
        with threadpool_limits(1):  # ~250 states: one BLAS thread is fastest on a shared machine
            ev = scipy.linalg.eigvals(self.pade_matrix(gain, delay, order), check_finite=False)
            ev = ev[np.argsort(-ev.real)][:count]
            if delay > 0.0:
                ev = np.array([self.refine(s, gain, delay) for s in ev])
                ev = ev[np.argsort(-ev.real)]
        return ev

    def growth_rate(self, gain: float, delay: float = 0.0) -> float:
        """Largest real part [1/s] of the loop's roots and the dropped modes (> 0: unstable)."""
        g = float(self.roots(gain, delay, count=4)[0].real)
        if self.dropped.size:
            g = max(g, float(np.max(self.dropped.real)))
        return g

    def chebyshev_roots(self, gain: float, delay: float, nodes: int = 10,
                        count: int = 6) -> np.ndarray:
        """Rightmost roots from a Chebyshev collocation of the delay equation (independent of
        the Pade route; cost ~ (N (nodes + 1))^3).

        ``x'(t) = A0 x(t) + A1 x(t - tau)`` with ``A1 = K B C`` (lag: on ``[x, G]``); the
        generator acts on functions on ``[-tau, 0]`` sampled at ``theta_j = tau/2 (cos(j pi /
        nodes) - 1)``: rows ``j >= 1`` differentiate (Chebyshev differentiation matrix), row 0
        is the equation ``A0 phi(0) + A1 phi(-tau)``.
        """
        n, m = self.B.shape
        T = self.lag_time_constant
        if T <= 0.0:
            A0, A1 = self.A, gain * self.B @ self.C
        else:
            d = n + m
            A0 = np.zeros((d, d))
            A0[:n, :n] = self.A
            A0[n:, :n] = gain / T * self.C
            A0[n:, n:] = -np.eye(m) / T
            A1 = np.zeros((d, d))
            A1[:n, n:] = self.B
        d = A0.shape[0]
        N = nodes
        x = np.cos(np.pi * np.arange(N + 1) / N)
        c = np.ones(N + 1)
        c[0] = c[-1] = 2.0
        c *= (-1.0) ** np.arange(N + 1)
        X = np.tile(x, (N + 1, 1)).T
        D = np.outer(c, 1.0 / c) / (X - X.T + np.eye(N + 1))
        D -= np.diag(D.sum(axis=1))
        D *= 2.0 / delay  # theta = tau/2 (x - 1)
        G = np.kron(D, np.eye(d))
        G[:d, :] = 0.0
        G[:d, :d] = A0
        G[:d, N * d:] = A1
        with threadpool_limits(1):
            ev = scipy.linalg.eigvals(G, check_finite=False)
        return ev[np.argsort(-ev.real)][:count]

    # -- boundaries ------------------------------------------------------------------------------
    def critical_gain(self, delay: float = 0.0, gain_min: float = 1e3, gain_max: float = 1e13,
                      per_decade: int = 4, rtol: float = 1e-3) -> float:
        """Smallest gain [N/strain] with a root in the right half plane (``inf`` if none up to
        ``gain_max``; scan and geometric bisection as the discrete prediction)."""
        return _first_crossing(lambda k: self._unstable(k, delay), gain_min, gain_max,
                               per_decade, rtol, log=True)

    def critical_delay(self, gain: float, delay_max: float = 5e-3, points: int = 50,
                       atol: float = 1e-7) -> float:
        """Smallest actuator delay [s] with a root in the right half plane.

        Scans ``points`` delays up to ``delay_max`` and bisects to ``atol`` [s]; ``inf`` if stable
        up to ``delay_max``, 0 if unstable without delay.
        """
        if self._unstable(gain, 0.0):
            return 0.0
        lo = 0.0
        for tau in np.linspace(0.0, delay_max, points + 1)[1:]:
            if self._unstable(gain, float(tau)):
                return _bisect(lambda d: self._unstable(gain, d), lo, float(tau), atol,
                               log=False)
            lo = float(tau)
        return math.inf

    def _unstable(self, gain: float, delay: float) -> bool:
        return float(self.roots(gain, delay, count=4)[0].real) > 0.0


# ---------------------------------------------------------------------------------- simulations
def _config(scene: str | Path | SceneConfig, overrides: Mapping[str, Any] | None = None
            ) -> SceneConfig:
    return scene if isinstance(scene, SceneConfig) else load_config(scene, overrides)


def law_from_scene(scene: str | Path | SceneConfig, delay: float = 0.0,
                   gain: float | None = None) -> StrainLaw:
    """The scene's strain controller as a :class:`analysis.closed_loop.StrainLaw` [SI units].

    ``scene`` is a name, a file or a :class:`cosim.scenario.config.SceneConfig` (validated
    once there); ``gain`` overrides the scene's gain [N per unit strain], ``delay`` is the
    actuator delay [s].
    """
    params = _config(scene).controller.params
    if gain is not None:
        params = replace(params, gain=float(gain))
    return StrainLaw.from_controller(params, delay=delay)


def operating_point_simulator(scene: str | Path | SceneConfig, gain: float, delay: float,
                              perturbation: float = 1e-6, seed: int = 0,
                              overrides: Mapping[str, Any] | None = None,
                              max_step: float | None = None) -> ClosedLoopSimulator:
    """A continuous-time closed loop started at the linearization's operating point.

    The scene's plant without forcing (``analysis.linearize.operating_params``), spinning at the
    top-drive speed from t = 0 (no ramp), in static equilibrium, with every body's lateral
    position perturbed by a seeded Gaussian of std ``perturbation`` [m]: the linear prediction's
    roots then govern the strains' growth. The law is the scene's (``gain`` [N/strain] and
    ``delay`` [s] given here).

    Returns
    -------
    analysis.closed_loop.ClosedLoopSimulator
    """
    config = _config(scene, overrides)
    prm = operating_params(config.scene.plant)
    omega = prm.top_drive.rotary_speed
    spin = replace(prm, top_drive=replace(prm.top_drive, ramp_time=0.0))
    rest = replace(prm, top_drive=replace(prm.top_drive, rotary_speed=0.0))
    y0 = static_equilibrium(DrillstringModel(rest, "full3d"))
    model = DrillstringModel(spin, "full3d")
    n = model.n
    y0[9 * n + 2::3] = omega
    rng = np.random.default_rng(seed)
    y0[0:3 * n:3] += perturbation * rng.standard_normal(n)
    y0[1:3 * n:3] += perturbation * rng.standard_normal(n)
    sim = ClosedLoopSimulator(model, law_from_scene(config, delay, gain), max_step=max_step)
    sim.y[:] = y0
    return sim


def envelope_growth_rate(t: np.ndarray, signal: np.ndarray, band: tuple[float, float],
                         t_start: float = 0.0) -> float:
    """Growth rate [1/s] of a signal's component in a frequency band.

    Zero-phase Butterworth band-pass (``band`` in rad/s), analytic-signal envelope, then a
    least-squares line through ``log(envelope)`` for ``t >= t_start`` [s] (the first and last
    5 % dropped against filter edge effects).

    Parameters
    ----------
    t : numpy.ndarray, shape (k,)
        Uniform sample times [s].
    signal : numpy.ndarray, shape (k,)
    band : (float, float)
        Pass band [rad/s].
    """
    dt = float(t[1] - t[0])
    nyq = math.pi / dt
    sos = scipy.signal.butter(4, [band[0] / nyq, band[1] / nyq], btype="band", output="sos")
    f = scipy.signal.sosfiltfilt(sos, signal)
    env = np.abs(scipy.signal.hilbert(f))
    k = len(t)
    sel = (t >= t_start) & (np.arange(k) >= k // 20) & (np.arange(k) < k - k // 20)
    sel &= env > 0.0
    return float(np.polyfit(t[sel], np.log(env[sel]), 1)[0])


def _report(scene: str = "paper_closed_loop") -> list[str]:
    """The numbers of ``docs/delay_study.md`` (section 5)."""
    lm = LoopModel.from_scene(scene)
    cl = ContinuousLoop.from_loop_model(lm)
    lines = [f"scene {scene}: {cl.A.shape[0]} coupled states ({cl.dropped.size} decoupled modes "
             f"dropped, slowest {np.max(cl.dropped.real):+.3f} 1/s); Pade order {cl.pade_order}"]
    kc = cl.critical_gain(0.0, gain_min=1e5, gain_max=1e13, per_decade=2, rtol=0.01)
    lines.append(f"critical gain, no delay, continuous: {kc:.3g} N/strain")
    for tau in (1e-4, 2e-4, 5e-4, 1e-3, 2e-3):
        k = cl.critical_gain(tau, gain_min=1e5, gain_max=1e13, per_decade=2, rtol=0.01)
        lines.append(f"critical gain, delay {tau * 1e3:g} ms, continuous: {k:.3g} N/strain")
    tc = cl.critical_delay(1e9, delay_max=1e-3, points=20, atol=1e-8)
    lines.append(f"critical delay at K = 1e9, continuous: {tc * 1e6:.2f} us")
    for h in (2.5e-4, 1e-4, 5e-5, 2.5e-5):
        td = lm.critical_delay(1e9, h, delay_max=1e-3, per_step=2, atol=h * 1e-3)
        lines.append(f"critical delay at K = 1e9, sampled H = {h * 1e3:g} ms: {td * 1e6:.2f} us "
                     f"(+ H/2 = {(td + h / 2) * 1e6:.2f} us)")
        kd = lm.critical_gain(h, 0.0, gain_min=1e5, gain_max=1e13, per_decade=2, rtol=0.01)
        lines.append(f"critical gain, no delay, sampled H = {h * 1e3:g} ms: {kd:.3g} N/strain "
                     f"(K H = {kd * h:.3g} N s/strain)")
    for tau in (1.5e-4, 1.8e-4, 2.2e-4, 3e-4, 5e-4):
        r = cl.roots(1e9, tau, count=1)[0]
        lines.append(f"K = 1e9, delay {tau * 1e3:g} ms: rightmost root {r.real:+.4f} 1/s at "
                     f"{abs(r.imag):.1f} rad/s")
    return lines


def _band_root(cl: ContinuousLoop, gain: float, delay: float, band: tuple[float, float]
               ) -> complex:
    """Rightmost root [1/s] whose frequency lies in ``band`` [rad/s] (refined from 228j if
    the Pade eigenvalues hold none there)."""
    ev = cl.roots(gain, delay, count=cl.A.shape[0])
    inb = ev[(np.abs(ev.imag) > band[0]) & (np.abs(ev.imag) < band[1])]
    if inb.size:
        return complex(inb[np.argmax(inb.real)])
    return cl.refine(-1.0 + 228j, gain, delay)


def _simulation_report(scene: str = "paper_closed_loop") -> list[str]:
    """Simulated growth of the continuous loop vs the prediction (``--simulate``)."""
    cl = ContinuousLoop.from_scene(scene)
    lines = ["gain [N/strain] | delay [ms] | predicted root in 150-300 rad/s [1/s] | simulated "
             "growth of strain1_C, 4 s from the perturbed operating point [1/s] | wall [s]"]
    for gain, tau in ((1e9, 1.5e-4), (1e9, 1.8e-4), (1e9, 2.2e-4), (1e9, 2.5e-4), (1e9, 3e-4),
                      (3.2e8, 5e-4), (6.3e8, 5e-4)):
        r = _band_root(cl, gain, tau, (150.0, 300.0))
        t0 = time.perf_counter()
        run = operating_point_simulator(scene, gain, tau).run(4.0, 2.5e-4, ["strain1_C"])
        g = envelope_growth_rate(run.time, run.outputs["strain1_C"], (150.0, 300.0), 0.5)
        lines.append(f"{gain:.3g} | {tau * 1e3:g} | {r.real:+.3f} at {abs(r.imag):.1f} rad/s | "
                     f"{g:+.3f} | {time.perf_counter() - t0:.1f}")
    return lines


if __name__ == "__main__":  # pragma: no cover
    args = [a for a in sys.argv[1:] if not a.startswith("--")]
    report = _simulation_report if "--simulate" in sys.argv else _report
    print("\n".join(report(*args[:1])))
