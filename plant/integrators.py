"""Fixed-step integrators compiled with the right-hand sides (no Python per internal step).

Each ``advance_*`` function integrates ``y`` in place over ``n_steps`` steps of ``dt`` [s] from
``t0`` [s], with the inputs ``u`` held, and returns the number of steps completed before a
non-finite state appeared (``n_steps`` on success). Failure is *returned*, not raised (as in
scipy's ``_ivp``): the caller decides how to report it. Time is ``t0 + s * dt`` (no drift).
The step loads are switched once a step, at its midpoint (``kernels.set_load_modes``): a step
must not straddle a switch time, which callers ensure with :func:`next_breakpoint`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit

from .kernels import rhs, set_load_modes, top_drive
from .layout import T_RAMP

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
        set_load_modes(ip, fp, t + 0.5 * dt)
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


@njit(cache=_CACHE)
def advance_erk(model, t0, y, n_steps, dt, A, b, c, K, yt, p, ip, fp, u, wR, wF, wM):
    """An explicit Runge-Kutta method given by its Butcher tableau, in place.

    ``A`` (s, s) strictly lower triangular, weights ``b`` (s,), nodes ``c`` (s,) (one of
    :data:`METHODS`); ``K`` (>= s, N) stage scratch, ``yt`` scratch like ``y``. Stage ``i``:
    ``K[i] = rhs(t + c_i dt, y + sum_j (dt a_ij) K[j])``; ``y1 = y + sum_i (dt b_i) K[i]``,
    each sum term by term over whole rows (contiguous, vectorised loops). Returns the number of
    completed steps like :func:`advance_rk4`.
    """
    N = y.size
    S = b.size
    for s in range(n_steps):
        t = t0 + s * dt
        set_load_modes(ip, fp, t + 0.5 * dt)
        for st in range(S):
            for i in range(N):
                yt[i] = y[i]
            for j in range(st):
                a = dt * A[st, j]
                if a != 0.0:
                    kj = K[j]
                    for i in range(N):
                        yt[i] += a * kj[i]
            rhs(model, t + c[st] * dt, yt, K[st], p, ip, fp, u, wR, wF, wM)
        for j in range(S):
            w = dt * b[j]
            if w != 0.0:
                kj = K[j]
                for i in range(N):
                    y[i] += w * kj[i]
        if (s & 63) == 63 and not _all_finite(y):
            return s
    if not _all_finite(y):
        return n_steps - 1
    return n_steps


# Stability limits |lambda dt| on the boundary of each method's region, used with a safety
# factor by the automatic step choice (RK4: 2.785 on the negative real axis, 2.828 on the
# imaginary axis; the minimum over the left half plane directions is ~2.6).
RK4_STABILITY_RADIUS = 2.6
# Every 3-stage, 3rd-order explicit Runge-Kutta method has the stability polynomial
# 1 + z + z^2/2 + z^3/6: sqrt(3) = 1.732 on the imaginary axis (its minimum over the left half
# plane directions), 2.51 on the negative real axis.
RK3_STABILITY_RADIUS = 1.7
# Velocity Verlet with the damping forces at the predicted velocity (lam = 1): with the
# stiffness-proportional damping of the chain's highest (overdamped torsional) mode the step is
# stable up to |lambda_max| dt ~ 0.79 (scalar mode analysis; measured on the n = 30 chain: stable at
# 0.1 ms, unstable at 0.2 ms, |lambda_max| = 5.1e3 1/s).
VERLET_STABILITY_RADIUS = 0.75


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


# ---------------------------------------------------------------------------------------------
# Adaptive embedded Runge-Kutta: Dormand-Prince 5(4), error control, step to the output time.

# Butcher tableau (Dormand & Prince 1980; Hairer, Norsett & Wanner, "Solving ODEs I", II.5).
DP5_C = np.array([0.0, 1.0 / 5.0, 3.0 / 10.0, 4.0 / 5.0, 8.0 / 9.0, 1.0, 1.0])
DP5_A = np.zeros((7, 7))
DP5_A[1, :1] = [1.0 / 5.0]
DP5_A[2, :2] = [3.0 / 40.0, 9.0 / 40.0]
DP5_A[3, :3] = [44.0 / 45.0, -56.0 / 15.0, 32.0 / 9.0]
DP5_A[4, :4] = [19372.0 / 6561.0, -25360.0 / 2187.0, 64448.0 / 6561.0, -212.0 / 729.0]
DP5_A[5, :5] = [9017.0 / 3168.0, -355.0 / 33.0, 46732.0 / 5247.0, 49.0 / 176.0,
                -5103.0 / 18656.0]
DP5_A[6, :6] = [35.0 / 384.0, 0.0, 500.0 / 1113.0, 125.0 / 192.0, -2187.0 / 6784.0, 11.0 / 84.0]
DP5_B = DP5_A[6].copy()  # 5th-order weights (FSAL: the last stage is at the new point)
DP5_E = np.array([  # b - b_hat (5th minus embedded 4th order weights)
    71.0 / 57600.0, 0.0, -71.0 / 16695.0, 71.0 / 1920.0, -17253.0 / 339200.0, 22.0 / 525.0,
    -1.0 / 40.0,
])

# status codes of advance_dopri5
DP5_OK = 0
DP5_NONFINITE = -1
DP5_MAX_STEPS = -2
DP5_STEP_TOO_SMALL = -3


@njit(cache=_CACHE)
def next_breakpoint(t, t1, breakpoints):
    """End [s] of the integration segment that starts at ``t`` and must end by ``t1``.

    The first of the sorted ``breakpoints`` [s] strictly inside ``(t, t1)`` (by more than
    1e-9 relative: a switch that falls on a communication point within rounding is not split),
    else ``t1``. Stepping segment by segment, no integration step straddles a load switch.
    """
    tol = 1e-9 * max(1.0, abs(t1))
    for b in breakpoints:
        if b > t + tol:
            if b < t1 - tol:
                return b
            return t1
    return t1


@njit(cache=_CACHE)
def advance_rk4_span(model, t0, t1, max_dt, breakpoints, y, p, ip, fp, u, wR, wF, wM, k1, k2, k3,
                     k4, yt):
    """RK4 from ``t0`` to ``t1`` [s] in steps of at most ``max_dt`` [s], split at breakpoints.

    Each segment between breakpoints gets ``ceil(length / max_dt)`` equal steps (one segment
    without breakpoints: exactly the ``ceil(h / max_dt)`` equal steps of a plain call).
    Returns the time [s] reached: ``t1``, or the end of the last finite step.
    """
    t = t0
    while t < t1:
        te = next_breakpoint(t, t1, breakpoints)
        n = max(1, math.ceil((te - t) / max_dt - 1e-9))
        dt = (te - t) / n
        done = advance_rk4(model, t, y, n, dt, p, ip, fp, u, wR, wF, wM, k1, k2, k3, k4, yt)
        if done < n:
            return t + done * dt
        t = te
    return t1


@njit(cache=_CACHE)
def _dp5_stage(model, t, h, y, K, s, yt, p, ip, fp, u, wR, wF, wM):
    """yt = y + h * sum_j a[s][j] K[j]; K[s] = rhs(t + c_s h, yt)."""
    N = y.size
    for i in range(N):
        acc = 0.0
        for j in range(s):
            acc += DP5_A[s, j] * K[j, i]
        yt[i] = y[i] + h * acc
    rhs(model, t + DP5_C[s] * h, yt, K[s], p, ip, fp, u, wR, wF, wM)


@njit(cache=_CACHE)
def advance_dopri5(model, t0, t1, y, hstate, stats, rtol, atol, max_steps, p, ip, fp, u, wR, wF,
                   wM, K, yt, ynew):
    """Adaptive Dormand-Prince 5(4) from ``t0`` to exactly ``t1`` [s], ``y`` updated in place.

    Error control on the embedded 4th-order estimate, scaled per component by
    ``atol + rtol * max(|y|, |y_new|)`` (RMS norm, as scipy's ``RK45``); step-size controller
    ``h_new = h * min(5, max(0.2, 0.9 * err^(-1/5)))``. The last step is shortened to land on
    ``t1`` (step to output, no dense output needed). Inputs ``u`` are held.

    Parameters
    ----------
    hstate : numpy.ndarray, shape (1,)
        In: proposed first step [s] (<= 0: choose one); out: the step to try next call.
    stats : numpy.ndarray of int64, shape (3,)
        Accumulated (accepted steps, rejected steps, rhs evaluations).
    K : numpy.ndarray, shape (7, N)
        Stage scratch; ``yt``, ``ynew`` scratch shaped like ``y``.

    Returns
    -------
    int
        ``DP5_OK`` (0) or a negative failure code (non-finite state, too many steps, step
        underflow); on failure ``y`` holds the last accepted state.
    """
    N = y.size
    t = t0
    span = t1 - t0
    if span <= 0.0:
        return DP5_OK
    set_load_modes(ip, fp, t0 + 0.5 * span)  # one load state over [t0, t1]: see module doc
    rhs(model, t, y, K[0], p, ip, fp, u, wR, wF, wM)
    stats[2] += 1
    h = hstate[0]
    if h <= 0.0:
        # Hairer's starting step guess from the rhs scale
        d0 = 0.0
        d1 = 0.0
        for i in range(N):
            sc = atol + rtol * abs(y[i])
            d0 += (y[i] / sc) ** 2
            d1 += (K[0, i] / sc) ** 2
        d0 = math.sqrt(d0 / N)
        d1 = math.sqrt(d1 / N)
        h = 1e-6 if (d0 < 1e-5 or d1 < 1e-5) else 0.01 * d0 / d1
    steps = 0
    while t < t1:
        last = False
        if t + h >= t1 - 1e-12 * span:
            h_use = t1 - t
            last = True
        else:
            h_use = h
        for s in range(1, 7):
            _dp5_stage(model, t, h_use, y, K, s, ynew, p, ip, fp, u, wR, wF, wM)
        stats[2] += 6
        # stage 7 was evaluated at y_new (FSAL): ynew holds the 5th-order solution
        err = 0.0
        for i in range(N):
            e = 0.0
            for j in range(7):
                e += DP5_E[j] * K[j, i]
            sc = atol + rtol * max(abs(y[i]), abs(ynew[i]))
            err += (h_use * e / sc) ** 2
        err = math.sqrt(err / N)
        if not (err == err) or err > 1e300:
            err = 1e300
        if err <= 1.0:
            t = t1 if last else t + h_use
            for i in range(N):
                y[i] = ynew[i]
                K[0, i] = K[6, i]
            stats[0] += 1
            fac = 5.0 if err == 0.0 else min(5.0, max(0.2, 0.9 * err ** -0.2))
            if not last:
                h = h_use * fac
            elif fac < 1.0:
                h = h_use * fac
            # a shortened last step keeps the previous, longer proposal otherwise
            if not _all_finite(y):
                return DP5_NONFINITE
        else:
            stats[1] += 1
            h = h_use * max(0.2, 0.9 * err ** -0.2)
            if h < 1e-14 * max(1.0, abs(t)):
                hstate[0] = h
                return DP5_STEP_TOO_SMALL
        steps += 1
        if steps >= max_steps:
            hstate[0] = h
            return DP5_MAX_STEPS
    hstate[0] = h
    return DP5_OK


# ---------------------------------------------------------------------------------------------
# Velocity Verlet on the second-order structure: y = [q, v] with q = positions (and Cardan angles
# in 3D) in the first half and v = velocities (and body angular velocities) in the second.


@njit(cache=_CACHE)
def _qdot(model, n, y, v, out):
    """out = dq/dt for configuration q = y[:N/2] and generalized velocities v (length N/2).

    Axial-torsional: dq/dt = v. Full 3D: positions' rate = velocities; Cardan rates from the body
    angular velocities (the kinematic map of ``kernels.rhs3d``).
    """
    if model != 0:  # MODEL_AXIAL_TORSIONAL
        for i in range(v.size):
            out[i] = v[i]
        return
    for i in range(3 * n):
        out[i] = v[i]
    oA = 3 * n
    for k in range(n):
        th = y[oA + 3 * k + 1]
        ph = y[oA + 3 * k + 2]
        wx = v[oA + 3 * k]
        wy = v[oA + 3 * k + 1]
        wz = v[oA + 3 * k + 2]
        sph = math.sin(ph)
        cph = math.cos(ph)
        a = wy * sph + wz * cph
        out[oA + 3 * k] = a / math.cos(th)
        out[oA + 3 * k + 1] = wy * cph - wz * sph
        out[oA + 3 * k + 2] = wx + math.tan(th) * a


@njit(cache=_CACHE)
def advance_verlet(model, t0, y, n_steps, dt, lam, p, ip, fp, u, wR, wF, wM, f, yt, vh, qd):
    """Velocity Verlet (kick-drift-kick), one rhs evaluation a step, in place.

    Kick ``v+ = v + dt/2 a(q, v)``; drift ``q1 = q + dt qdot(q_mid, v+)`` (kinematics at the
    midpoint configuration, 2nd order for the Cardan map); kick ``v1 = v+ + dt/2 a(q1, v*)``
    with the velocity-dependent (damping) forces at the predicted ``v* = v + lam dt a(q, v)``
    (``lam = 1``: second order also in the damping; ``lam = 0.5``: ``v* = v+``, first order in
    the damping forces but a ~1.8x larger stable step with the stiffness-proportional damping
    of the high modes; Groot & Warren's modified velocity Verlet).
    The acceleration of the last kick is reused for the next step's first kick (FSAL), so after
    the first step each step costs one rhs call. Symplectic for conservative forces; second
    order for ``lam = 1``. Stability: ``dt |lambda| < 2`` on the imaginary axis (undamped modes);
    the stiffness-proportional damping of the high modes lowers it (see
    ``VERLET_STABILITY_RADIUS``).

    ``f``, ``yt`` are scratch shaped like ``y``; ``vh``, ``qd`` half as long. Returns the number of
    completed steps (``n_steps`` on success), as :func:`advance_rk4`.
    """
    N = y.size
    H = N // 2
    n = ip[0]
    set_load_modes(ip, fp, t0 + 0.5 * dt)
    rhs(model, t0, y, f, p, ip, fp, u, wR, wF, wM)
    for s in range(n_steps):
        t = t0 + s * dt
        if set_load_modes(ip, fp, t + 0.5 * dt):  # a load switched at t: the FSAL force is stale
            rhs(model, t, y, f, p, ip, fp, u, wR, wF, wM)
        for i in range(H):
            vh[i] = y[H + i] + 0.5 * dt * f[H + i]
        # midpoint configuration for the kinematic map
        _qdot(model, n, y, vh, qd)
        for i in range(H):
            yt[i] = y[i] + 0.5 * dt * qd[i]
        _qdot(model, n, yt, vh, qd)
        for i in range(H):
            y[i] += dt * qd[i]
            yt[i] = y[i]
            yt[H + i] = y[H + i] + lam * dt * f[H + i]
        rhs(model, t + dt, yt, f, p, ip, fp, u, wR, wF, wM)
        for i in range(H):
            y[H + i] = vh[i] + 0.5 * dt * f[H + i]
        if (s & 63) == 63 and not _all_finite(y):
            return s
    if not _all_finite(y):
        return n_steps - 1
    return n_steps


# ---------------------------------------------------------------------------------------------
# Exponential integrators for (nearly) linear models: y' = A y + g(t, y), A a fixed matrix
# (the Jacobian at the static equilibrium), g = f - A y the forcing and nonlinear remainder.


@njit(cache=_CACHE, fastmath=True)
def _matvec_add(M, x, out, c):
    """out += c * M @ x for a dense square (or row-block) M."""
    R, C = M.shape
    for i in range(R):
        acc = 0.0
        for j in range(C):
            acc += M[i, j] * x[j]
        out[i] += c * acc


def block_split(M: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A square matrix with exactly-zero couplings as dense diagonal blocks (for mat-vecs).

    The blocks are the connected components of the graph ``i ~ j if M[i, j] != 0 or
    M[j, i] != 0`` (the axial-torsional chain's ``P1`` is two blocks of 2 n: axial and torsional,
    half the work of the dense product). Returns ``(idx, sizes, blocks)``, padded to the largest
    block ``m``: block ``b`` acts on the indices ``idx[b, :sizes[b]]`` (shape (nb, m), int64)
    with the matrix ``blocks[b, :sizes[b], :sizes[b]]`` (shape (nb, m, m)); see
    :func:`block_matvec_add`.
    """
    from scipy.sparse import csr_matrix
    from scipy.sparse.csgraph import connected_components

    M = np.asarray(M, dtype=float)
    nb, label = connected_components(csr_matrix(M != 0.0), directed=True, connection="weak")
    groups = [np.flatnonzero(label == b) for b in range(nb)]
    m = max(g.size for g in groups)
    idx = np.zeros((nb, m), dtype=np.int64)
    blocks = np.zeros((nb, m, m))
    for b, ii in enumerate(groups):
        idx[b, :ii.size] = ii
        blocks[b, :ii.size, :ii.size] = M[np.ix_(ii, ii)]
    return idx, np.array([g.size for g in groups], dtype=np.int64), blocks


@njit(cache=_CACHE, fastmath=True)
def block_matvec_add(idx, sizes, blocks, x, out, xb):
    """out += M @ x for M in the block form of :func:`block_split`; ``xb`` scratch like x.

    (A padded 3D array of blocks: 3.3x faster than flat offsets, which numba did not vectorize.)
    """
    for b in range(blocks.shape[0]):
        m = sizes[b]
        for j in range(m):
            xb[j] = x[idx[b, j]]
        for r in range(m):
            acc = 0.0
            for j in range(m):
                acc += blocks[b, r, j] * xb[j]
            out[idx[b, r]] += acc


@njit(cache=_CACHE, inline="always")
def add_drive_ramp(t, dt, y, ramp, t_ramp):
    """``y +=`` what exponential Euler's ``y + P1 f(t, y)`` leaves out of the exact step's
    response to the top drive's prescribed motion over ``[t, t + dt]`` [s].

    The drive moves as :func:`plant.kernels.top_drive` with unit final speed times each drive's
    speed: its speed is linear in time over a step that does not straddle the end of the ramp
    ``t_ramp`` [s] (a breakpoint), ``s(t + tau) = s0 + a tau`` (``s0`` the speed just after
    ``t``, ``a`` the acceleration), and its position is the integral. With ``g`` the
    direction in which the drive's position and speed enter ``f`` (spring ``K``, damper ``C``),
    the exact step adds to ``y + P1 f(t, y)`` (which holds ``f``'s drive terms at ``t``):
    ``(s0 - s(t)) C P1 g + s0 K dt^2 phi2 g + a (C dt^2 phi2 g + K dt^3 phi3 g)`` (the
    ``phi_k`` at ``dt A``). ``ramp`` (3, N) holds those three vectors summed over the drives,
    each times its speed (:meth:`plant.model.DrillstringModel.expeuler_operator`); ``(0, N)``:
    no drive moves, nothing added. ``s0 - s(t)`` is nonzero only at ``t = 0`` without a ramp.
    """
    if ramp.shape[0] == 0:
        return
    tm = t + 0.5 * dt
    acc = 1.0 / t_ramp if (t_ramp > 0.0 and tm < t_ramp) else 0.0
    s_t = top_drive(t, 1.0, t_ramp)[1]
    s0 = top_drive(tm, 1.0, t_ramp)[1] - 0.5 * dt * acc
    jump = s0 - s_t
    for i in range(y.size):
        y[i] += jump * ramp[0, i] + s0 * ramp[1, i] + acc * ramp[2, i]


@njit(cache=_CACHE)
def advance_expeuler(model, t0, y, n_steps, dt, idx, sizes, blocks, ramp, p, ip, fp, u, wR, wF,
                     wM, f, xb):
    """Exponential Euler ``y1 = y + dt phi1(dt A) f(t, y)``, ``P1 = dt phi1(dt A)`` precomputed,
    plus the exact response to the top drive's prescribed motion (:func:`add_drive_ramp`).

    Exact for linear systems with constant forcing over the step and the top drive's hoisting
    and rotation ramps (any ``dt``: no stability limit from the stiff, overdamped high modes);
    first order in any other variation of the forcing and in the nonlinear remainder
    ``g = f - A y``. One rhs and one block mat-vec a step (``P1`` in the form of
    :func:`block_split`, computed for this ``dt``; ``ramp`` (3, N) or (0, N) for this ``dt``;
    ``f``, ``xb`` scratch like ``y``). Returns completed steps like :func:`advance_rk4`.
    """
    for s in range(n_steps):
        t = t0 + s * dt
        set_load_modes(ip, fp, t + 0.5 * dt)
        rhs(model, t, y, f, p, ip, fp, u, wR, wF, wM)
        block_matvec_add(idx, sizes, blocks, f, y, xb)
        add_drive_ramp(t, dt, y, ramp, p[T_RAMP])
        if (s & 63) == 63 and not _all_finite(y):
            return s
    if not _all_finite(y):
        return n_steps - 1
    return n_steps


@njit(cache=_CACHE)
def advance_etd2(model, t0, y, n_steps, dt, P1, P2, Q, p, ip, fp, u, wR, wF, wM, f, fa, ya):
    """Second-order exponential Runge-Kutta (ETD2RK, Cox & Matthews 2002), in place.

    ``a = y + P1 f(t, y)``; ``y1 = a + P2 (g(t + dt, a) - g(t, y))`` with ``g = f - A y``,
    rewritten without ``A``: ``y1 = y + (P1 - Q) f(t, y) + P2 f(t + dt, a)``, where
    ``P1 = dt phi1(dt A)``, ``P2 = dt phi2(dt A)``, ``Q = P2 exp(dt A)`` (see
    :func:`exponential_matrices`). Two rhs calls and three mat-vecs a step; exact for linear
    systems with forcing linear in time over the step.
    """
    N = y.size
    for s in range(n_steps):
        t = t0 + s * dt
        set_load_modes(ip, fp, t + 0.5 * dt)
        rhs(model, t, y, f, p, ip, fp, u, wR, wF, wM)
        for i in range(N):
            ya[i] = y[i]
        _matvec_add(P1, f, ya, 1.0)
        rhs(model, t + dt, ya, fa, p, ip, fp, u, wR, wF, wM)
        _matvec_add(P1, f, y, 1.0)
        _matvec_add(Q, f, y, -1.0)
        _matvec_add(P2, fa, y, 1.0)
        if (s & 63) == 63 and not _all_finite(y):
            return s
    if not _all_finite(y):
        return n_steps - 1
    return n_steps


def exponential_matrices(A, dt: float):
    """``(P1, P2, Q)`` of the exponential integrators for the matrix ``A`` [1/s] and step ``dt`` [s].

    ``P1 = dt phi1(dt A)``, ``P2 = dt phi2(dt A)``, ``Q = P2 exp(dt A)``, with
    ``phi1(z) = (e^z - 1) / z`` and ``phi2(z) = (e^z - 1 - z) / z^2``, from one matrix
    exponential of the augmented block matrix ``[[A, I, 0], [0, 0, I], [0, 0, 0]] dt``
    (Higham's scaling and squaring in ``scipy.linalg.expm``; no inverse of ``A`` needed, so a
    singular ``A`` — free rigid-body modes — is fine).
    """
    from scipy.linalg import expm

    A = np.asarray(A, dtype=float)
    N = A.shape[0]
    M = np.zeros((3 * N, 3 * N))
    M[:N, :N] = A * dt
    M[:N, N:2 * N] = np.eye(N) * dt
    M[N:2 * N, 2 * N:] = np.eye(N) * dt
    E = expm(M)
    eA = E[:N, :N]
    P1 = np.ascontiguousarray(E[:N, N:2 * N])
    P2 = np.ascontiguousarray(E[:N, 2 * N:] / dt)
    Q = np.ascontiguousarray(P2 @ eA)
    return P1, P2, Q


def polynomial_input_responses(A, G, dt: float) -> np.ndarray:
    """``W[k] = dt^(k+1) phi_(k+1)(dt A) G`` for k = 0, 1, 2: the responses over one step
    ``dt`` [s] of ``y' = A y + G w(t)`` from ``y = 0`` to the inputs ``w = 1``, ``w = t`` and
    ``w = t^2 / 2`` (``A`` (N, N) [1/s], ``G`` (N, m)); shape (3, N, m).

    One matrix exponential of the augmented matrix ``[[A, G, 0, 0], [0, 0, I, 0], [0, 0, 0, I],
    [0, 0, 0, 0]] dt`` (Al-Mohy and Higham 2011, "Computing the action of the matrix
    exponential ...", section 2): its top-right blocks are
    ``int_0^dt e^((dt - s) A) G s^k / k! ds``. Size N + 3 m, no inverse of ``A``.
    """
    from scipy.linalg import expm

    A = np.asarray(A, dtype=float)
    G = np.asarray(G, dtype=float).reshape(A.shape[0], -1)
    N, m = G.shape
    M = np.zeros((N + 3 * m, N + 3 * m))
    M[:N, :N] = A * dt
    M[:N, N:N + m] = G * dt
    M[N:N + m, N + m:N + 2 * m] = np.eye(m) * dt
    M[N + m:N + 2 * m, N + 2 * m:] = np.eye(m) * dt
    E = expm(M)
    return np.stack([E[:N, N + k * m:N + (k + 1) * m] for k in range(3)])


# ---------------------------------------------------------------------------------------------
# The table of fixed-step methods (data; tests/test_integrator_table.py checks its invariants:
# order conditions of the tableaus, the order measured on a linear test problem, the stability
# radii against each method's stability polynomial).

KERNEL_RK4 = 0  # advance_rk4
KERNEL_ERK = 1  # advance_erk with the method's tableau
KERNEL_VERLET = 2  # advance_verlet
KERNEL_EXPEULER = 3  # advance_expeuler
KERNEL_ETD2 = 4  # advance_etd2


@dataclass(frozen=True)
class Method:
    """A fixed-step integrator of :data:`METHODS`.

    Attributes
    ----------
    name : str
    kernel : int
        Which compiled ``advance_*`` runs it (``KERNEL_*``).
    stages : int
        Right-hand side evaluations a step (the cost unit).
    order : int
        Classical order of convergence.
    radius : float or None
        Stability bound ``|lambda| dt`` of the automatic step (:func:`stable_step`), at most the
        distance from 0 to the boundary of the stability region in every left-half-plane
        direction; ``None``: no stability limit (exponential integrators); ``0``: the region
        holds no segment of the imaginary axis, so no automatic step exists (give ``max_step``).
    tableau : tuple of numpy.ndarray or None
        ``(A, b, c)`` of an explicit Runge-Kutta method.
    automatic : tuple of str
        The model kinds for which it is a candidate of the automatic choice per communication
        step (:meth:`plant.model.DrillstringModel.method_for_step`): it met the accuracy bar
        of ``BENCHMARKS.md`` ("Integrator at the communication step",
        ``benchmarks/bench_fixed_step.py``, which checks these marks) at its automatic step on
        every smooth benchmark scene of that kind. Only methods with an automatic step
        (``radius > 0``: an imaginary-axis interval, which the lightly damped modes need).
    """

    name: str
    kernel: int
    stages: int
    order: int
    radius: float | None
    tableau: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None
    automatic: tuple[str, ...] = ()


def _tableau(A, b, c) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    return (np.array(A, dtype=float), np.array(b, dtype=float), np.array(c, dtype=float))


#: The fixed-step methods by name. Explicit Runge-Kutta tableaus: Hairer, Norsett & Wanner,
#: "Solving ODEs I", II.1 (Kutta 1901, Heun 1900, Ralston 1962); SSPRK3: Shu & Osher 1988.
METHODS: dict[str, Method] = {m.name: m for m in (
    Method("rk4", KERNEL_RK4, 4, 4, RK4_STABILITY_RADIUS,
           _tableau([[0, 0, 0, 0], [0.5, 0, 0, 0], [0, 0.5, 0, 0], [0, 0, 1, 0]],
                    [1 / 6, 1 / 3, 1 / 3, 1 / 6], [0, 0.5, 0.5, 1]),
           automatic=("full3d", "axial_torsional")),
    # Kutta's 3rd-order method: like RK4 it samples the forcing at t, t + h/2, t + h with
    # Simpson's weights and satisfies the linear 4th-order condition b.A.c^2 = 1/12, so the
    # prescribed bit motion of the 3D scenes is integrated to RK4's accuracy with 3 stages
    # (BENCHMARKS.md); on the axial-torsional pulse scene it misses the bar (2.5e-4).
    Method("kutta3", KERNEL_ERK, 3, 3, RK3_STABILITY_RADIUS,
           _tableau([[0, 0, 0], [0.5, 0, 0], [-1, 2, 0]], [1 / 6, 2 / 3, 1 / 6], [0, 0.5, 1]),
           automatic=("full3d",)),
    Method("ralston3", KERNEL_ERK, 3, 3, RK3_STABILITY_RADIUS,
           _tableau([[0, 0, 0], [0.5, 0, 0], [0, 0.75, 0]], [2 / 9, 1 / 3, 4 / 9],
                    [0, 0.5, 0.75])),
    Method("ssprk3", KERNEL_ERK, 3, 3, RK3_STABILITY_RADIUS,
           _tableau([[0, 0, 0], [1, 0, 0], [0.25, 0.25, 0]], [1 / 6, 1 / 6, 2 / 3],
                    [0, 1, 0.5])),
    Method("heun2", KERNEL_ERK, 2, 2, 0.0, _tableau([[0, 0], [1, 0]], [0.5, 0.5], [0, 1])),
    Method("ralston2", KERNEL_ERK, 2, 2, 0.0,
           _tableau([[0, 0], [2 / 3, 0]], [0.25, 0.75], [0, 2 / 3])),
    Method("verlet", KERNEL_VERLET, 1, 2, VERLET_STABILITY_RADIUS),
    Method("expeuler", KERNEL_EXPEULER, 1, 1, None),
    Method("etd2", KERNEL_ETD2, 2, 2, None),
)}


def stability_function(method: Method, z: np.ndarray) -> np.ndarray:
    """``R(z)`` of an explicit Runge-Kutta method: ``y1 = R(lambda dt) y0`` on ``y' = lambda y``.

    ``R(z) = 1 + z b^T (I - z A)^{-1} 1 = 1 + sum_k z^k b^T A^(k-1) 1`` (A nilpotent).
    """
    if method.tableau is None:
        raise ValueError(f"method {method.name!r} has no Runge-Kutta tableau")
    A, b, _c = method.tableau
    z = np.asarray(z, dtype=complex)
    out = np.ones_like(z)
    v = np.ones(b.size)
    for k in range(1, b.size + 1):
        out = out + z**k * float(b @ v)
        v = A @ v
    return out
