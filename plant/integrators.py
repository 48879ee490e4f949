"""Fixed-step integrators compiled with the right-hand sides (no Python per internal step).

Each ``advance_*`` function integrates ``y`` in place over ``n_steps`` steps of ``dt`` [s] from
``t0`` [s], with the inputs ``u`` held, and returns the number of steps completed before a
non-finite state appeared (``n_steps`` on success). Failure is *returned*, not raised (as in
scipy's ``_ivp``): the caller decides how to report it. Time is ``t0 + s * dt`` (no drift).
"""

from __future__ import annotations

import math

from numba import njit

from .kernels import rhs

_CACHE = True


@njit(cache=_CACHE)
def _all_finite(y) -> bool:
    acc = 0.0
    for i in range(y.size):
        acc += y[i] * 0.0
    return acc == 0.0


@njit(cache=_CACHE)
def advance_rk4(model, t0, y, n_steps, dt, p, ip, fp, u, wR, wF, wM, k1, k2, k3, k4, yt):
    """Classic 4th-order Runge-Kutta; k1..k4, yt are scratch arrays shaped like y."""
    N = y.size
    for s in range(n_steps):
        t = t0 + s * dt
        rhs(model, t, y, k1, p, ip, fp, u, wR, wF, wM)
        for i in range(N):
            yt[i] = y[i] + 0.5 * dt * k1[i]
        rhs(model, t + 0.5 * dt, yt, k2, p, ip, fp, u, wR, wF, wM)
        for i in range(N):
            yt[i] = y[i] + 0.5 * dt * k2[i]
        rhs(model, t + 0.5 * dt, yt, k3, p, ip, fp, u, wR, wF, wM)
        for i in range(N):
            yt[i] = y[i] + dt * k3[i]
        rhs(model, t + dt, yt, k4, p, ip, fp, u, wR, wF, wM)
        c = dt / 6.0
        for i in range(N):
            y[i] += c * (k1[i] + 2.0 * (k2[i] + k3[i]) + k4[i])
        if (s & 63) == 63 and not _all_finite(y):
            return s
    if not _all_finite(y):
        return n_steps - 1
    return n_steps


# Stability limits |lambda dt| on the boundary of each method's region, used with a safety
# factor by the automatic step choice (RK4: 2.785 on the negative real axis, 2.828 on the
# imaginary axis; the minimum over the left half plane directions is ~2.6).
RK4_STABILITY_RADIUS = 2.6


def stable_step(max_abs_eigenvalue: float, radius: float = RK4_STABILITY_RADIUS,
                safety: float = 0.85) -> float:
    """Largest step [s] with |lambda| dt inside the method's stability region (with a margin).

    Parameters
    ----------
    max_abs_eigenvalue : float
        Spectral radius of the right-hand side's Jacobian [1/s].
    """
    if not math.isfinite(max_abs_eigenvalue) or max_abs_eigenvalue <= 0.0:
        raise ValueError(f"max_abs_eigenvalue = {max_abs_eigenvalue!r}: must be finite and > 0")
    return safety * radius / max_abs_eigenvalue
