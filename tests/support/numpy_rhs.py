"""An independent, vectorised numpy implementation of the full 3D right-hand side.

This is the right-hand side a user would write without numba (the naive baseline of the
work-precision benchmarks: scipy ``solve_ivp`` RK45 on it), and a second implementation of the
physics of :func:`plant.kernels.rhs3d`: a test asserts both agree to ~1e-12 relative on random
states, a strong check of each. It is written from the model description (joint spring-dampers in
body ``i+1``'s frame, rotational potential ``1/2 tr(G (I - R_rel))``, Newton in the inertial frame,
Euler with the gyroscopic term in the body frame), with arrays over bodies and joints instead of
loops. It derives its own masses, inertias, joint springs and dampers and the boundary springs
from the parameters (:func:`body_constants`: the formulas of the paper's section 3 and of the
damping model, written again, not the model's packed array ``p``); it shares with the kernel
only the layout arrays ``ip``, ``fp`` (which bodies carry stabilizers, contact, actuators and
loads), the first lateral frequency of the pinned multi-span beam (the model's finite-element
value, :func:`plant.uniform_pipe.lateral_reference_frequency`) and the bit's static rock position
(``p[ZBIT0]``, set by the static equilibrium of :meth:`DrillstringModel.initial_state`).

State layout (length 12 n, blocks of 3 n): positions of the mass centres [m], Cardan angles
(psi, theta, phi) [rad], inertial velocities [m/s], body-frame angular velocities [rad/s].
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from drillcosim.plant import layout as lay
from drillcosim.plant.kernels import IP_FIELD, IP_HDR, IP_N, IP_NA, IP_NC, IP_NL, IP_NS, IP_UNB

__all__ = ["NumpyRhs", "body_constants", "cardan_matrices", "rhs3d_numpy"]


def _series(k_boundary: float, k_half: float) -> float:
    """A boundary spring in series with half a segment (2 k of the segment); inf: rigid, 0: free."""
    if k_boundary <= 0.0:
        return 0.0
    return k_half if math.isinf(k_boundary) else k_boundary * k_half / (k_boundary + k_half)


def body_constants(params: Any, w_lateral: float) -> dict[str, float]:
    """The uniform string's body and joint constants, from the parameters (SI).

    n rigid hollow cylinders of length dx = L / n (OD, ID, E, G, rho): mass rho A dx, polar
    inertia m (ro^2 + ri^2) / 2, transverse inertia m (3 (ro^2 + ri^2) + dx^2) / 12; joint springs
    EA / dx, kappa G A / dx (Cowper's kappa of a hollow circle unless given), EI / dx, G J / dx
    (J = 2 I); the rotational potential ``1/2 tr(G (I - R_rel))`` with G = diag(g1, g1, g3) has
    the small-angle stiffnesses g1 (torsion) and (g1 + g3) / 2 (bending), so g1 = G J / dx and
    g3 = 2 EI / dx - g1. Dampers stiffness-proportional, ``beta = 2 zeta / w`` at the first
    fixed-free rod frequency w = pi c / (2 L) (axial, also for shear; torsional with c_t); the
    lateral drag ``2 zeta_l w_l`` (or bending dampers ``2 zeta_l / w_l`` in the joint model).
    The top drive's and the bit's springs act in series with half a segment.

    Parameters
    ----------
    params : plant.params.PlantParams
        A uniform pipe without a damping-rate cap (``damping.max_joint_rate = inf``).
    w_lateral : float
        First bending frequency [rad/s] of the pinned spans (used when the damping parameters
        give none).
    """
    pipe, dmp = params.pipe, params.damping
    if not params.uniform:
        raise ValueError("the numpy reference is the uniform pipe's right-hand side; it has no "
                         "string sections")
    if not math.isinf(dmp.max_joint_rate):
        raise ValueError("the numpy reference has no joint-damper rate cap "
                         "(damping.max_joint_rate = inf)")
    E, Gm, rho = pipe.youngs_modulus, pipe.shear_modulus, pipe.density
    ro, ri = pipe.outer_diameter / 2.0, pipe.inner_diameter / 2.0
    L, n = pipe.length, pipe.n_segments
    dx = L / n
    area = math.pi * (ro**2 - ri**2)
    inertia = math.pi / 4.0 * (ro**4 - ri**4)
    kappa = pipe.shear_coefficient
    if kappa <= 0.0:  # Cowper (1966), hollow circle
        nu, m2 = E / (2.0 * Gm) - 1.0, (ri / ro) ** 2
        kappa = 6.0 * (1 + nu) * (1 + m2) ** 2 / ((7 + 6 * nu) * (1 + m2) ** 2 + (20 + 12 * nu) * m2)
    mass = rho * area * dx
    k_ax, k_sh = E * area / dx, kappa * Gm * area / dx
    k_be, k_to = E * inertia / dx, Gm * 2.0 * inertia / dx
    beta_ax = 2.0 * dmp.axial_ratio / (math.pi * math.sqrt(E / rho) / (2.0 * L))
    beta_to = 2.0 * dmp.torsional_ratio / (math.pi * math.sqrt(Gm / rho) / (2.0 * L))
    w_l = dmp.lateral_reference_frequency if dmp.lateral_reference_frequency > 0.0 else w_lateral
    joint = dmp.lateral_model == "joint"
    td, bit, st, ct = params.top_drive, params.bit, params.stabilizers, params.contact
    out = {"HALF": dx / 2.0, "MASS": mass, "JP": 0.5 * mass * (ro**2 + ri**2),
           "JT": mass * (3.0 * (ro**2 + ri**2) + dx**2) / 12.0, "GRAV": params.gravity,
           "K_AX": k_ax, "K_SH": k_sh, "G1": k_to, "G3": 2.0 * k_be - k_to,
           "C_AX": beta_ax * k_ax, "C_SH": beta_ax * k_sh, "C_TO": beta_to * k_to,
           "C_BE": (2.0 * dmp.lateral_ratio / w_l if joint else beta_ax) * k_be,
           "ALPHA_LAT": 0.0 if joint else 2.0 * dmp.lateral_ratio * w_l,
           "KT_AX": _series(td.axial_stiffness, 2.0 * k_ax),
           "KT_LAT": _series(td.lateral_stiffness, 2.0 * k_sh),
           "KT_TO": _series(td.torsional_stiffness, 2.0 * k_to),
           "KB_AX": _series(bit.axial_stiffness, 2.0 * k_ax),
           "OMEGA0": td.rotary_speed, "T_RAMP": td.ramp_time,
           "BIT_AMP": bit.displacement_amplitude if bit.axial_stiffness > 0.0 else 0.0,
           "BIT_LOBES": bit.lobes, "BIT_TORQUE": bit.torque, "BIT_EPS": bit.slip_speed,
           "K_STAB": st.stiffness, "C_STAB": beta_ax * st.stiffness if st.damping < 0.0
           else st.damping,
           "K_CONT": ct.stiffness if ct.enabled else 0.0,
           "C_CONT": ct.damping if ct.enabled else 0.0, "CLEAR": ct.clearance,
           "UNB": params.unbalance.moment if params.unbalance.enabled else 0.0,
           "ACT_ARM": 2.0 * (params.actuators.radius or ro)}
    out.update(CT_AX=beta_ax * out["KT_AX"], CT_LAT=beta_ax * out["KT_LAT"],
               CT_TO=beta_to * out["KT_TO"], CB_AX=beta_ax * out["KB_AX"])
    return out


def cardan_matrices(ang: np.ndarray) -> np.ndarray:
    """Rotation matrices ``Rz(psi) Ry(theta) Rx(phi)`` (body -> inertial), shape (n, 3, 3).

    Parameters
    ----------
    ang : numpy.ndarray, shape (n, 3)
        Cardan angles (psi, theta, phi) [rad].
    """
    cps, sps = np.cos(ang[:, 0]), np.sin(ang[:, 0])
    cth, sth = np.cos(ang[:, 1]), np.sin(ang[:, 1])
    cph, sph = np.cos(ang[:, 2]), np.sin(ang[:, 2])
    n = ang.shape[0]
    Rz = np.zeros((n, 3, 3))
    Ry = np.zeros((n, 3, 3))
    Rx = np.zeros((n, 3, 3))
    Rz[:, 0, 0], Rz[:, 0, 1], Rz[:, 1, 0], Rz[:, 1, 1], Rz[:, 2, 2] = cps, -sps, sps, cps, 1.0
    Ry[:, 0, 0], Ry[:, 0, 2], Ry[:, 2, 0], Ry[:, 2, 2], Ry[:, 1, 1] = cth, sth, -sth, cth, 1.0
    Rx[:, 1, 1], Rx[:, 1, 2], Rx[:, 2, 1], Rx[:, 2, 2], Rx[:, 0, 0] = cph, -sph, sph, cph, 1.0
    return Rz @ Ry @ Rx


def _apply(R: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Batched ``R @ v``: R (k, 3, 3), v (k, 3)."""
    return (R @ v[:, :, None])[:, :, 0]


def _apply_t(R: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Batched ``R^T @ v``."""
    return (v[:, None, :] @ R)[:, 0, :]


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Row-wise cross product of (k, 3) arrays (np.cross is slow for many short rows)."""
    a, b = np.broadcast_arrays(a, b)
    return a[..., [1, 2, 0]] * b[..., [2, 0, 1]] - a[..., [2, 0, 1]] * b[..., [1, 2, 0]]


def _cross_ez(a: np.ndarray, c: float) -> np.ndarray:
    """Row-wise ``a x (0, 0, c)``."""
    out = np.zeros(a.shape)
    out[..., 0] = c * a[..., 1]
    out[..., 1] = -c * a[..., 0]
    return out


def _top_drive(t: float, omega0: float, t_ramp: float) -> tuple[float, float]:
    """Top-drive angle [rad] and speed [rad/s] of the linear speed ramp."""
    if t <= 0.0:
        return 0.0, 0.0
    if t_ramp <= 0.0:
        return omega0 * t, omega0
    if t < t_ramp:
        return 0.5 * omega0 * t * t / t_ramp, omega0 * t / t_ramp
    return omega0 * (t - 0.5 * t_ramp), omega0


def _skew_torque(G: np.ndarray, Rrel: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Torques of the potential ``1/2 tr(G (I - R_rel))`` on bodies b (its frame) and a (a's frame).

    With ``R_rel = R_a^T R_b`` and a perturbation ``R_b -> R_b (I + [dth]x)`` the potential changes
    by ``-1/2 tr(G R_rel [dth]x)``; the torque on b is minus the gradient: the axial vector of
    ``1/2 (G R_rel - (G R_rel)^T)`` with sign, and on a the matching term from the left factor.
    """
    M = G[None, :, :] @ Rrel  # G R_rel, (k, 3, 3)
    # on b: tau_b = -vee(skew(G R_rel)) where vee picks (M21 - M12, M02 - M20, M10 - M01) / 2
    tb = -0.5 * np.stack([M[:, 2, 1] - M[:, 1, 2], M[:, 0, 2] - M[:, 2, 0],
                          M[:, 1, 0] - M[:, 0, 1]], axis=1)
    N = Rrel @ G[None, :, :]  # R_rel G
    ta = 0.5 * np.stack([N[:, 2, 1] - N[:, 1, 2], N[:, 0, 2] - N[:, 2, 0],
                         N[:, 1, 0] - N[:, 0, 1]], axis=1)
    return tb, ta


def rhs3d_numpy(t: float, y: np.ndarray, constants: dict[str, float], ip: np.ndarray,
                fp: np.ndarray, u: np.ndarray, zbit0: float) -> np.ndarray:
    """Full 3D right-hand side, vectorised (allocates).

    Parameters
    ----------
    t : float
        Time [s].
    y : numpy.ndarray, shape (12 n,)
        State (see the module docstring).
    constants : dict
        :func:`body_constants` of the parameters.
    ip, fp : numpy.ndarray
        The layout arrays of :class:`plant.model.DrillstringModel` (``model.ip``, ``model.fp``).
    u : numpy.ndarray, shape (2 n_sites,)
        Actuator forces [N].
    zbit0 : float
        The rock's position under the bit at rest [m] (``model.p[layout.ZBIT0]``).

    Returns
    -------
    numpy.ndarray, shape (12 n,)
        dy/dt.
    """
    if ip[IP_FIELD]:
        raise ValueError("rhs3d_numpy is the reference of the uniform pipe's right-hand side; "
                         "it has no string sections, trajectory or fluid")
    q = constants
    n = int(ip[IP_N])
    ns, nc, na, unb, nl = (int(ip[k]) for k in (IP_NS, IP_NC, IP_NA, IP_UNB, IP_NL))
    h = q["HALF"]
    m = q["MASS"]
    jt, jp = q["JT"], q["JP"]
    X = y[:3 * n].reshape(n, 3)
    ang = y[3 * n:6 * n].reshape(n, 3)
    V = y[6 * n:9 * n].reshape(n, 3)
    W = y[9 * n:].reshape(n, 3)
    R = cardan_matrices(ang)

    # Cardan kinematics
    th, ph = ang[:, 1], ang[:, 2]
    a = W[:, 1] * np.sin(ph) + W[:, 2] * np.cos(ph)
    dang = np.stack([a / np.cos(th), W[:, 1] * np.cos(ph) - W[:, 2] * np.sin(ph),
                     W[:, 0] + np.tan(th) * a], axis=1)

    F = np.zeros((n, 3))
    M = np.zeros((n, 3))  # body frame
    F[:, 0] = -q["ALPHA_LAT"] * m * V[:, 0]
    F[:, 1] = -q["ALPHA_LAT"] * m * V[:, 1]
    F[:, 2] = m * q["GRAV"]

    # ---- joints a -> b = a + 1: translational spring-damper in b's frame
    Ra, Rb = R[:-1], R[1:]
    Wa, Wb = W[:-1], W[1:]
    # points A of b and B of a sit at body z = -h and +h
    dI = (X[1:] - h * Rb[:, :, 2]) - (X[:-1] + h * Ra[:, :, 2])
    dv = (V[1:] + _apply(Rb, _cross_ez(Wb, -h))) - (V[:-1] + _apply(Ra, _cross_ez(Wa, h)))
    d = _apply_t(Rb, dI)
    # rate of d seen in b's frame: R_b^T d(dI)/dt - w_b x d
    ddot = _apply_t(Rb, dv) - _cross(Wb, d)
    kvec = np.array([q["K_SH"], q["K_SH"], q["K_AX"]])
    cvec = np.array([q["C_SH"], q["C_SH"], q["C_AX"]])
    f = -(kvec * d + cvec * ddot)  # force on b at A, b frame
    Fin = _apply(Rb, f)
    F[1:] += Fin
    F[:-1] -= Fin
    # moment on b: r_A x f - d x f (keeps the potential exactly conservative)
    M[1:] += -_cross_ez(f, -h) - _cross(d, f)
    M[:-1] += -_cross_ez(_apply_t(Ra, -Fin), h)

    # ---- joints: rotational spring-damper
    Rrel = np.transpose(Ra, (0, 2, 1)) @ Rb
    G = np.diag([q["G1"], q["G1"], q["G3"]])
    tb, ta = _skew_torque(G, Rrel)
    cw = np.array([q["C_BE"], q["C_BE"], q["C_TO"]])
    td = -cw * (Wb - _apply_t(Rrel, Wa))  # on b, b frame
    M[1:] += tb + td
    M[:-1] += ta - _apply(Rrel, td)

    # ---- actuator couples at joints below body ip[...] (moment on b, reaction on a)
    o_act = IP_HDR + ns + nc
    arm = q["ACT_ARM"]
    for s in range(na):
        ja = int(ip[o_act + s])
        tq = np.array([-arm * u[2 * s + 1], arm * u[2 * s], 0.0])
        M[ja + 1] += tq
        M[ja] -= (R[ja].T @ R[ja + 1]) @ tq

    # ---- top drive joint on body 0
    ang_td, om_td = _top_drive(t, q["OMEGA0"], q["T_RAMP"])
    R0, w0 = R[0], W[0]
    rA0 = np.array([0.0, 0.0, -h])
    A0 = X[0] + R0 @ rA0
    d0 = R0.T @ A0
    r0 = R0.T @ (V[0] + R0 @ _cross(w0, rA0)) - _cross(w0, d0)
    kt = np.array([q["KT_LAT"], q["KT_LAT"], q["KT_AX"]])
    ct = np.array([q["CT_LAT"], q["CT_LAT"], q["CT_AX"]])
    f0 = -(kt * d0 + ct * r0)
    F[0] += R0 @ f0
    M[0] += _cross(rA0, f0) - _cross(d0, f0)
    ktt = q["KT_TO"]
    if ktt > 0.0:
        ca, sa = np.cos(ang_td), np.sin(ang_td)
        Rd = np.array([[ca, -sa, 0.0], [sa, ca, 0.0], [0.0, 0.0, 1.0]])
        Rr = Rd.T @ R0
        # potential 1/2 ktt tr(I - Rr) restricted as in the kernel (pin about the drive axis)
        M[0] += np.array([0.5 * ktt * (Rr[2, 1] + Rr[1, 2]), -0.5 * ktt * (Rr[0, 2] + Rr[2, 0]),
                          -0.5 * ktt * (Rr[1, 0] - Rr[0, 1]) - q["CT_TO"] * (w0[2] - om_td * R0[2, 2])])

    # ---- bit: axial spring-damper to the rock, resisting torque
    e = n - 1
    if q["KB_AX"] > 0.0:
        lob, amp = q["BIT_LOBES"], q["BIT_AMP"]
        zr = zbit0 + amp * np.sin(lob * ang_td)
        vr = amp * lob * om_td * np.cos(lob * ang_td)
        rB = np.array([0.0, 0.0, h])
        Bz = X[e, 2] + (R[e] @ rB)[2]
        vBz = V[e, 2] + (R[e] @ _cross(W[e], rB))[2]
        Fz = -q["KB_AX"] * (Bz - zr) - q["CB_AX"] * (vBz - vr)
        F[e, 2] += Fz
        M[e] += _cross(rB, R[e].T @ np.array([0.0, 0.0, Fz]))
    if q["BIT_TORQUE"] > 0.0:
        M[e, 2] -= q["BIT_TORQUE"] * np.tanh(W[e, 2] / q["BIT_EPS"])

    # ---- stabilizers: lateral springs at material points (local offset z)
    if ns:
        ks = ip[IP_HDR:IP_HDR + ns]
        rP = np.zeros((ns, 3))
        rP[:, 2] = fp[:ns]
        P = X[ks] + _apply(R[ks], rP)
        vP = V[ks] + _apply(R[ks], _cross(W[ks], rP))
        Fs = np.zeros((ns, 3))
        Fs[:, :2] = -q["K_STAB"] * P[:, :2] - q["C_STAB"] * vP[:, :2]
        np.add.at(F, ks, Fs)
        np.add.at(M, ks, _cross(rP, _apply_t(R[ks], Fs)))

    # ---- wellbore contact, frictionless, never pulling
    kc, cc = q["K_CONT"], q["C_CONT"]
    if nc and (kc != 0.0 or cc != 0.0):
        kb = ip[IP_HDR + ns:IP_HDR + ns + nc]
        XY = X[kb, :2]
        dl = np.hypot(XY[:, 0], XY[:, 1])
        on = dl > q["CLEAR"]
        if on.any():
            nrm = XY[on] / dl[on, None]
            vn = np.sum(nrm * V[kb[on], :2], axis=1)
            fn = kc * (dl[on] - q["CLEAR"]) + cc * vn
            push = fn > 0.0
            np.add.at(F, (kb[on][push], 0), -fn[push] * nrm[push, 0])
            np.add.at(F, (kb[on][push], 1), -fn[push] * nrm[push, 1])

    # ---- unbalance: centrifugal force along body x
    if unb >= 0:
        F[unb] += q["UNB"] * W[unb, 2] ** 2 * R[unb, :, 0]

    # ---- external loads (pulses/steps)
    for s in range(nl):
        row = ns + lay.NLD * s
        if fp[row + lay.LD_T0] <= t < fp[row + lay.LD_T1]:
            k, dd = int(fp[row + lay.LD_BODY]), int(fp[row + lay.LD_DIR])
            (F if fp[row + lay.LD_KIND] == 0.0 else M)[k, dd] += fp[row + lay.LD_MAG]

    # ---- Newton and Euler
    J = np.array([jt, jt, jp])
    dW = (M - _cross(W, J * W)) / J
    return np.concatenate([V.ravel(), dang.ravel(), (F / m).ravel(), dW.ravel()])


class NumpyRhs:
    """Callable ``f(t, y)`` for scipy on a model's arrays (the naive baseline's right-hand side).

    Parameters
    ----------
    model : DrillstringModel
        A ``full3d`` model; its ``p``, ``ip``, ``fp`` and held inputs ``u`` are used.
    """

    def __init__(self, model) -> None:
        from drillcosim.plant.uniform_pipe import lateral_reference_frequency

        if model.kind != "full3d":
            raise ValueError("NumpyRhs implements the full 3D model only")
        self.model = model
        self.constants = body_constants(model.params, lateral_reference_frequency(model.params))
        self.calls = 0

    def __call__(self, t: float, y: np.ndarray) -> np.ndarray:
        self.calls += 1
        m = self.model
        return rhs3d_numpy(t, y, self.constants, m.ip, m.fp, m.u, m.p[lay.ZBIT0])
