"""Compiled right-hand sides of the drillstring models (numba, no allocation per call).

Two models share one signature ``rhs(model, t, y, dy, p, ip, fp, u, wR, wF, wM)``:

``MODEL_FULL3D``
    n rigid bodies in 3D (paper section 3). State ``y`` (length 12 n), blocks of 3 n:
    positions of the mass centres G in the inertial frame [m], Cardan angles (psi, theta, phi)
    [rad] with ``R = Rz(psi) Ry(theta) Rx(phi)`` (body -> inertial, eq. 9-11), inertial velocities
    [m/s], body-frame angular velocities [rad/s]. Inertial Z points down the well; body z lies
    along the pipe axis, pointing down.
``MODEL_AXIAL_TORSIONAL``
    The same chain restricted to axial and torsional motion. State (length 4 n), blocks of n:
    Z [m], twist psi [rad], Z-velocity [m/s], spin rate [rad/s]. For a straight string it is
    exactly the 3D model with every lateral DOF at zero.

Joints (between point B of body i and point A of body i+1): a diagonal spring-damper in body
i+1's frame. Translational: potential 1/2 d^T K d with d = R_{i+1}^T (A_{i+1} - B_i); the moment
d x (-f) keeps it exactly conservative and angular-momentum preserving. Rotational: potential
1/2 tr(G (I - R_rel)), R_rel = R_i^T R_{i+1}, G = diag(g1, g1, g3) chosen so that the small-angle
stiffness is diag(k_bend, k_bend, k_tors) (g1 = k_tors, g3 = 2 k_bend - k_tors); this is exactly
conservative at any angle, and needs no extra states. Dampers act on the relative velocities.

``ip`` (int64): header [n, n_stab, n_contact, n_act, unbalance_body (0-based, -1 none), n_loads,
top-drive mode, index of the top-drive angle in ``y`` (-1 none), bit mode, index of the bit's
auxiliary state in ``y`` (-1 none), extended outputs (0/1)] followed by stabilizer bodies,
contact bodies, actuator joints (0-based). ``fp`` (float64): stabilizer local z offsets [m], then
the load table (``layout.NLD`` columns a row). ``u`` (float64): 2 per actuator site, the actuator
forces [N] at C and E (> 0 opposing positive strain), then the top-drive input when
``top_drive.mode`` is not "prescribed" (speed command [rad/s] or motor torque [N m]).

Auxiliary states (extensions beyond the paper, off by default) follow the bodies' states in ``y``:
the top-drive angle [rad] (modes "speed" and "torque") and speed [rad/s] (mode "torque").
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from .layout import (
    B_CLIN,
    B_CQ,
    B_H,
    B_IJP,
    B_IM,
    B_JP,
    B_JT,
    B_K1,
    B_K2,
    B_M,
    B_ML,
    B_P,
    B_R,
    B_W,
    BIT_A,
    BIT_AMP,
    BIT_EPS,
    BIT_EPSI,
    BIT_JX,
    BIT_LOBES,
    BIT_MU,
    BIT_TORQUE,
    BIT_WEAK,
    BIT_WF,
    BIT_WSPD,
    BIT_ZETA,
    C_CONT,
    C_STAB,
    CB_AX,
    CP_BODY,
    CP_CLR,
    CP_RC,
    CP_Z,
    CT_AX,
    CT_LAT,
    CT_TO,
    HOIST,
    J_ARM,
    J_CAX,
    J_CBE,
    J_CSH,
    J_CTO,
    J_G1,
    J_G3,
    J_KAX,
    J_KSH,
    J_LEN,
    K_CONT,
    K_STAB,
    KB_AX,
    KT_AX,
    KT_LAT,
    KT_TO,
    LD_BODY,
    LD_DIR,
    LD_KIND,
    LD_MAG,
    LD_ON,
    LD_T0,
    LD_T1,
    MU_WALL,
    NB,
    NCP,
    NLD,
    NP,
    OMEGA0,
    T_RAMP,
    TD_INERTIA,
    TD_R,
    UNB,
    V_SLIP,
    ZBIT0,
)

MODEL_FULL3D = 0
MODEL_AXIAL_TORSIONAL = 1

IP_N = 0
IP_NS = 1
IP_NC = 2
IP_NA = 3
IP_UNB = 4
IP_NL = 5
IP_TD = 6  # top-drive mode: TD_PRESCRIBED, TD_SPEED, TD_TORQUE
IP_TDX = 7  # index of the top-drive angle in y (speed: + 1) or -1
IP_BIT = 8  # bit mode (BIT_PRESCRIBED)
IP_BITX = 9  # index of the bit's auxiliary state in y or -1
IP_XOUT = 10  # 1: the outputs include the extensions' (signals.plant_outputs(extended=True))
IP_NCP = 11  # number of contact points (rows of the contact-point table in fp)
IP_FRAMED = 12  # 1: positions and velocities are local to each body's reference frame
IP_FIELD = 13  # 1: the outputs include the field summary (signals.FIELD_SCALAR_OUTPUTS)
IP_HDR = 14

# top-drive modes (params.TOP_DRIVE_MODES order)
TD_PRESCRIBED = 0
TD_SPEED = 1
TD_TORQUE = 2
BIT_PRESCRIBED = 0
BIT_CUTTING = 1

_CACHE = True


@njit(cache=_CACHE)
def top_drive(t: float, omega0: float, t_ramp: float) -> tuple[float, float]:
    """Top-drive angle [rad] and speed [rad/s]: linear ramp 0 -> omega0 over t_ramp."""
    if t <= 0.0:
        return 0.0, 0.0
    if t_ramp <= 0.0:
        return omega0 * t, omega0
    if t < t_ramp:
        return 0.5 * omega0 * t * t / t_ramp, omega0 * t / t_ramp
    return omega0 * (t - 0.5 * t_ramp), omega0


@njit(cache=_CACHE, inline="always")
def drive_motion(t, y, p, ip, u):
    """Top-drive angle [rad] and speed [rad/s] at time ``t`` for state ``y`` and inputs ``u``.

    Mode "prescribed": the ramp of :func:`top_drive`; "speed": the angle is an auxiliary state
    and the speed the input ``u[2 n_act]``; "torque": angle and speed are auxiliary states.
    """
    mode = ip[IP_TD]
    if mode == TD_PRESCRIBED:
        return top_drive(t, p[OMEGA0], p[T_RAMP])
    x = ip[IP_TDX]
    if mode == TD_SPEED:
        return y[x], u[2 * ip[IP_NA]]
    return y[x], y[x + 1]


@njit(cache=_CACHE, inline="always")
def drive_rates(y, dy, p, ip, u, torque_on_string):
    """Derivatives of the top-drive auxiliary states (nothing in mode "prescribed").

    ``torque_on_string`` [N m]: torque of the top joint on body 1 about the well axis; the drive
    feels its reaction: ``J_td domega/dt = u_torque - torque_on_string``.
    """
    mode = ip[IP_TD]
    if mode == TD_PRESCRIBED:
        return
    x = ip[IP_TDX]
    if mode == TD_SPEED:
        dy[x] = u[2 * ip[IP_NA]]
    else:
        dy[x] = y[x + 1]
        dy[x + 1] = (u[2 * ip[IP_NA]] - torque_on_string) / p[TD_INERTIA]


@njit(cache=_CACHE)
def bit_rock(ang: float, om: float, p: np.ndarray) -> tuple[float, float]:
    """Prescribed rock position Z_bit [m] and its rate [m/s] for top-drive angle/speed."""
    lob = p[BIT_LOBES]
    a = p[BIT_AMP]
    return p[ZBIT0] + a * math.sin(lob * ang), a * lob * om * math.cos(lob * ang)


@njit(cache=_CACHE, inline="always")
def cutting_bit(zb, vb, zh, th, om, p):
    """Cutting + wear-flat bit on a unilateral contact (Detournay & Defourny 2008).

    ``zb`` [m], ``vb`` [m/s]: depth and axial velocity of the bit end; ``zh`` [m]: hole bottom
    (an auxiliary state); ``th`` [rad], ``om`` [rad/s]: bit angle and speed. The rock surface
    under the bit is ``zh + A sin(lobes th)`` (a lobed bottom-hole profile, ``A`` =
    ``bit.displacement_amplitude``). On bottom the contact spring-damper gives the weight on bit
    ``W >= 0`` (off bottom: everything 0, the bit bounces); the wear flats carry
    ``W_f = min(W, W_f*)``, the cutters ``W_c = W - W_f`` at the depth of cut per revolution
    ``d = W_c / (a zeta eps)``. Torque ``T = a/2 (W_c / zeta + mu(om) W_f) tanh(om / slip)``,
    ``mu(om) = mu gamma (1 + weak exp(-|om| / om_w))``; the hole deepens at
    ``d max(om, 0) / (2 pi)``. Returns ``(W [N], T [N m], rate of penetration [m/s], d [m])``.
    """
    lob = p[BIT_LOBES]
    amp = p[BIT_AMP]
    zs = zh + amp * math.sin(lob * th)
    pen = zb - zs
    if pen <= 0.0:
        return 0.0, 0.0, 0.0, 0.0
    w = p[KB_AX] * pen + p[CB_AX] * (vb - amp * lob * om * math.cos(lob * th))
    if w <= 0.0:
        return 0.0, 0.0, 0.0, 0.0
    wf = min(w, p[BIT_WF])
    wc = w - wf
    a = p[BIT_A]
    zeta = p[BIT_ZETA]
    d = wc / (a * zeta * p[BIT_EPSI])
    mu = p[BIT_MU]
    if p[BIT_WEAK] > 0.0:
        mu *= 1.0 + p[BIT_WEAK] * math.exp(-abs(om) / p[BIT_WSPD])
    tq = 0.5 * a * (wc / zeta + mu * wf) * math.tanh(om / p[BIT_EPS])
    rop = d * om / (2.0 * math.pi) if om > 0.0 else 0.0
    return w, tq, rop, d


@njit(cache=_CACHE)
def cardan(psi: float, th: float, ph: float, R: np.ndarray) -> None:
    """Fill R (3, 3) with Rz(psi) Ry(th) Rx(ph) (body -> inertial)."""
    cps = math.cos(psi)
    sps = math.sin(psi)
    cth = math.cos(th)
    sth = math.sin(th)
    cph = math.cos(ph)
    sph = math.sin(ph)
    R[0, 0] = cps * cth
    R[0, 1] = cps * sth * sph - sps * cph
    R[0, 2] = cps * sth * cph + sps * sph
    R[1, 0] = sps * cth
    R[1, 1] = sps * sth * sph + cps * cph
    R[1, 2] = sps * sth * cph - cps * sph
    R[2, 0] = -sth
    R[2, 1] = cth * sph
    R[2, 2] = cth * cph


@njit(cache=_CACHE, inline="always")
def _mv(R, a, b, c):
    return (
        R[0, 0] * a + R[0, 1] * b + R[0, 2] * c,
        R[1, 0] * a + R[1, 1] * b + R[1, 2] * c,
        R[2, 0] * a + R[2, 1] * b + R[2, 2] * c,
    )


@njit(cache=_CACHE, inline="always")
def _mtv(R, a, b, c):
    return (
        R[0, 0] * a + R[1, 0] * b + R[2, 0] * c,
        R[0, 1] * a + R[1, 1] * b + R[2, 1] * c,
        R[0, 2] * a + R[1, 2] * b + R[2, 2] * c,
    )


@njit(cache=_CACHE, inline="always")
def _cross(a0, a1, a2, b0, b1, b2):
    return a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0


@njit(cache=_CACHE)
def relative_rotation(Ra: np.ndarray, Rb: np.ndarray, Rrel: np.ndarray) -> None:
    """Rrel = Ra^T Rb: orientation of body b relative to body a."""
    for i in range(3):
        for j in range(3):
            Rrel[i, j] = Ra[0, i] * Rb[0, j] + Ra[1, i] * Rb[1, j] + Ra[2, i] * Rb[2, j]


@njit(cache=_CACHE, inline="always")
def gauge_strains(Rrel, rg, dx):
    """Bending strains (C, E) [1] of a gauge site from the rotation ``Rrel`` across its joint.

    Eq. 18-20: strain = (r / dx) * relative bending angle; gauge C reads bending about body y
    (negative sign, right-hand rule), gauge E about body x. ``rg`` gauge radius [m], ``dx``
    segment length [m].
    """
    thx = 0.5 * (Rrel[2, 1] - Rrel[1, 2])
    thy = 0.5 * (Rrel[0, 2] - Rrel[2, 0])
    return -rg / dx * thy, rg / dx * thx


@njit(cache=_CACHE)
def set_load_modes(ip, fp, t):
    """Switch the step loads on or off for time ``t`` [s] (``start <= t < end``).

    Loads are piecewise-constant inputs: the integrators call this once a step, at the step's
    midpoint, so that the whole step sees one value (a stage at a switch time belongs to both
    neighbouring steps and would otherwise see the wrong one: a first-order error); callers
    split their steps at :attr:`DrillstringModel.breakpoints`. Point evaluations
    (``DrillstringModel.rhs``) call it with their own ``t``. Returns whether any load switched.
    """
    ns = ip[IP_NS]
    changed = False
    for s in range(ip[IP_NL]):
        row = ns + NLD * s
        on = 1.0 if fp[row + LD_T0] <= t < fp[row + LD_T1] else 0.0
        if fp[row + LD_ON] != on:
            fp[row + LD_ON] = on
            changed = True
    return changed


@njit(cache=_CACHE, inline="always")
def _load_active(fp, row):
    return fp[row + LD_ON] != 0.0


@njit(cache=_CACHE, inline="always")
def wall_friction(nx, ny, fn, mu, vslip, rc, vx, vy, vz, wx, wy, wz, Rl):
    """Regularized Coulomb friction of the wall at a contact point, in the hole's local frame.

    The contact point P sits on the pipe surface at ``rc`` along the outward normal
    ``n = (nx, ny, 0)`` (local frame: z along the hole axis; the inertial frame for a vertical
    hole); ``(vx, vy, vz)`` is the velocity [m/s] of the axis point of the pipe next to P,
    ``(wx, wy, wz)`` the body-frame angular velocity and ``Rl`` the body's rotation relative to
    the local frame. P's slip velocity has a circumferential part ``v_t = v . t + rc omega_z``
    (``t = e_z x n``) and an axial part ``v_z + rc (omega_x n_y - omega_y n_x)`` (``omega`` in
    the local frame). The friction force ``-mu fn (v_t t + v_z e_z) / sqrt(v_t^2 + v_z^2 +
    v_eps^2)`` acts at P. Returns its local components and its moment ``rc n x F`` about the
    axis point in the body frame: ``(fx, fy, fz, mx, my, mz)``.
    """
    ox, oy, oz = _mv(Rl, wx, wy, wz)
    vt = -ny * vx + nx * vy + rc * oz
    vz = vz + rc * (ox * ny - oy * nx)
    g = mu * fn / math.sqrt(vt * vt + vz * vz + vslip * vslip)
    ft = -g * vt
    fz = -g * vz
    m0, m1, m2 = _mtv(Rl, rc * ny * fz, -rc * nx * fz, rc * ft)
    return -ft * ny, ft * nx, fz, m0, m1, m2


@njit(cache=_CACHE, inline="always")
def _local_rotation(y, oA, k, framed, wR, S):
    """Rotation of body ``k`` relative to its reference frame (``wR[k]`` unless framed: then
    built into the scratch ``S`` from the Cardan angles); returns the matrix to use."""
    if framed:
        cardan(y[oA + 3 * k], y[oA + 3 * k + 1], y[oA + 3 * k + 2], S)
        return S
    return wR[k]


@njit(cache=_CACHE, inline="always")
def _frame_mv(p, o, a, b, c):
    """Reference frame at ``p[o:o+9]`` (row-major) times the vector (a, b, c)."""
    return (p[o] * a + p[o + 1] * b + p[o + 2] * c,
            p[o + 3] * a + p[o + 4] * b + p[o + 5] * c,
            p[o + 6] * a + p[o + 7] * b + p[o + 8] * c)


@njit(cache=_CACHE, inline="always")
def _frame_mtv(p, o, a, b, c):
    """Transpose of the reference frame at ``p[o:o+9]`` times the vector (a, b, c)."""
    return (p[o] * a + p[o + 3] * b + p[o + 6] * c,
            p[o + 1] * a + p[o + 4] * b + p[o + 7] * c,
            p[o + 2] * a + p[o + 5] * b + p[o + 8] * c)


@njit(cache=_CACHE, inline="always")
def _frame_mm(p, o, S, R):
    """R = F S with F the reference frame at ``p[o:o+9]`` (row-major)."""
    for i in range(3):
        f0 = p[o + 3 * i]
        f1 = p[o + 3 * i + 1]
        f2 = p[o + 3 * i + 2]
        for j in range(3):
            R[i, j] = f0 * S[0, j] + f1 * S[1, j] + f2 * S[2, j]


@njit(cache=_CACHE, inline="always")
def _frame_tmm(p, o, S, R):
    """R = F^T S with F the reference frame at ``p[o:o+9]`` (row-major)."""
    for i in range(3):
        f0 = p[o + i]
        f1 = p[o + 3 + i]
        f2 = p[o + 6 + i]
        for j in range(3):
            R[i, j] = f0 * S[0, j] + f1 * S[1, j] + f2 * S[2, j]


@njit(cache=_CACHE, inline="always")
def body_inertial(y, p, k, framed, oV):
    """Inertial position [m] and velocity [m/s] of the mass centre of body ``k`` (6 values)."""
    if framed:
        o = NP + NB * k
        g0, g1, g2 = _frame_mv(p, o + B_R, y[3 * k], y[3 * k + 1], y[3 * k + 2])
        v0, v1, v2 = _frame_mv(p, o + B_R, y[oV + 3 * k], y[oV + 3 * k + 1], y[oV + 3 * k + 2])
        return (p[o + B_P] + g0, p[o + B_P + 1] + g1, p[o + B_P + 2] + g2, v0, v1, v2)
    return (y[3 * k], y[3 * k + 1], y[3 * k + 2], y[oV + 3 * k], y[oV + 3 * k + 1],
            y[oV + 3 * k + 2])


@njit(cache=_CACHE, inline="always")
def _add_local_force(wF, p, k, framed, fx, fy, fz):
    """Add a force given in body ``k``'s local frame to ``wF[k]`` (inertial)."""
    if framed:
        fx, fy, fz = _frame_mv(p, NP + NB * k + B_R, fx, fy, fz)
    wF[k, 0] += fx
    wF[k, 1] += fy
    wF[k, 2] += fz


@njit(cache=_CACHE, inline="always")
def top_hoist(t, p):
    """Axial displacement [m] and speed [m/s] of the top drive along its axis (hoisting)."""
    if p[HOIST] == 0.0:
        return 0.0, 0.0
    return top_drive(t, p[HOIST], p[T_RAMP])


@njit(cache=_CACHE, inline="always")
def top_point(t, y, p, framed, oV, R0, h):
    """Position of body 0's top end A relative to the top drive [m] and the velocity of its
    mass centre relative to the drive [m/s] (inertial; the drive hoists along its axis)."""
    G0, G1, G2, V0, V1, V2 = body_inertial(y, p, 0, framed, oV)
    A0 = G0 - h * R0[0, 2]
    A1 = G1 - h * R0[1, 2]
    A2 = G2 - h * R0[2, 2]
    if p[HOIST] != 0.0:
        zt, vt = top_hoist(t, p)
        A0 -= zt * p[TD_R + 2]
        A1 -= zt * p[TD_R + 5]
        A2 -= zt * p[TD_R + 8]
        V0 -= vt * p[TD_R + 2]
        V1 -= vt * p[TD_R + 5]
        V2 -= vt * p[TD_R + 8]
    return A0, A1, A2, V0, V1, V2


@njit(cache=_CACHE)
def rhs3d(t, y, dy, p, ip, fp, u, wR, wF, wM):
    """Full 3D right-hand side (:func:`_rhs3d`), compiled once per frame kind: with the frame
    flag a constant, the vertical hole's code carries no per-body frame tests."""
    if ip[IP_FRAMED] != 0:
        _rhs3d(t, y, dy, p, ip, fp, u, wR, wF, wM, True)
    else:
        _rhs3d(t, y, dy, p, ip, fp, u, wR, wF, wM, False)


@njit(cache=_CACHE)
def _rhs3d(t, y, dy, p, ip, fp, u, wR, wF, wM, framed):
    """Full 3D right-hand side; writes dy (12 n). wR (n + 2, 3, 3), wF (n, 3), wM (n, 3) are
    scratch (``wR[k]`` body k's rotation to the inertial frame, ``wR[n]`` and ``wR[n + 1]``
    free).

    Unframed (the uniform vertical string): positions and velocities are inertial. Framed
    (``ip[IP_FRAMED]``, a curved hole): body k's position, velocity and Cardan angles are
    relative to its reference frame (point ``B_P``, rotation ``B_R``: the body's place in the
    initial state along the hole), forces are summed in the inertial frame (gravity along +Z)
    and turned into the local frame for Newton's law.
    """
    n = ip[IP_N]
    ns = ip[IP_NS]
    na = ip[IP_NA]
    unb = ip[IP_UNB]
    nl = ip[IP_NL]
    ncp = ip[IP_NCP]
    oA = 3 * n
    oV = 6 * n
    oW = 9 * n
    Rrel = wR[n]  # scratch slots: wR has n + 2 matrices
    S = wR[n + 1]
    # kinematics, weight, lateral drag
    for k in range(n):
        o = NP + NB * k
        R = wR[k]
        psi = y[oA + 3 * k]
        th = y[oA + 3 * k + 1]
        ph = y[oA + 3 * k + 2]
        if framed:
            cardan(psi, th, ph, S)
            _frame_mm(p, o + B_R, S, R)
        else:
            cardan(psi, th, ph, R)
        wx = y[oW + 3 * k]
        wy = y[oW + 3 * k + 1]
        wz = y[oW + 3 * k + 2]
        cth = math.cos(th)
        sph = math.sin(ph)
        cph = math.cos(ph)
        a = wy * sph + wz * cph
        dy[oA + 3 * k] = a / cth
        dy[oA + 3 * k + 1] = wy * cph - wz * sph
        dy[oA + 3 * k + 2] = wx + math.tan(th) * a
        for i in range(3):
            dy[3 * k + i] = y[oV + 3 * k + i]
            wM[k, i] = 0.0
        alpha = p[o + B_CLIN]
        vx = y[oV + 3 * k]
        vy = y[oV + 3 * k + 1]
        fx = -alpha * vx
        fy = -alpha * vy
        cq = p[o + B_CQ]
        if cq > 0.0:
            q = cq * math.sqrt(vx * vx + vy * vy)
            fx -= q * vx
            fy -= q * vy
        if framed:
            fx, fy, fz = _frame_mv(p, o + B_R, fx, fy, 0.0)
            wF[k, 0] = fx
            wF[k, 1] = fy
            wF[k, 2] = fz + p[o + B_W]
        else:
            wF[k, 0] = fx
            wF[k, 1] = fy
            wF[k, 2] = p[o + B_W]

    # joints between body a (point B) and body b = a + 1 (point A)
    Ga0, Ga1, Ga2, Va0, Va1, Va2 = body_inertial(y, p, 0, framed, oV)
    for a in range(n - 1):
        b = a + 1
        oa = NP + NB * a
        ha = p[oa + B_H]
        hb = p[oa + NB + B_H]
        Gb0, Gb1, Gb2, Vb0, Vb1, Vb2 = body_inertial(y, p, b, framed, oV)
        Ra = wR[a]
        Rb = wR[b]
        wxa = y[oW + 3 * a]
        wya = y[oW + 3 * a + 1]
        wza = y[oW + 3 * a + 2]
        wxb = y[oW + 3 * b]
        wyb = y[oW + 3 * b + 1]
        wzb = y[oW + 3 * b + 2]
        dI0 = (Gb0 - hb * Rb[0, 2]) - (Ga0 + ha * Ra[0, 2])
        dI1 = (Gb1 - hb * Rb[1, 2]) - (Ga1 + ha * Ra[1, 2])
        dI2 = (Gb2 - hb * Rb[2, 2]) - (Ga2 + ha * Ra[2, 2])
        vA = _mv(Rb, -hb * wyb, hb * wxb, 0.0)
        vB = _mv(Ra, ha * wya, -ha * wxa, 0.0)
        dv0 = Vb0 + vA[0] - Va0 - vB[0]
        dv1 = Vb1 + vA[1] - Va1 - vB[1]
        dv2 = Vb2 + vA[2] - Va2 - vB[2]
        ksh = p[oa + J_KSH]
        csh = p[oa + J_CSH]
        d0, d1, d2 = _mtv(Rb, dI0, dI1, dI2)
        r0, r1, r2 = _mtv(Rb, dv0, dv1, dv2)
        c0, c1, c2 = _cross(wxb, wyb, wzb, d0, d1, d2)
        f0 = -(ksh * d0 + csh * (r0 - c0))
        f1 = -(ksh * d1 + csh * (r1 - c1))
        f2 = -(p[oa + J_KAX] * d2 + p[oa + J_CAX] * (r2 - c2))
        F0, F1, F2 = _mv(Rb, f0, f1, f2)
        wF[b, 0] += F0
        wF[b, 1] += F1
        wF[b, 2] += F2
        wF[a, 0] -= F0
        wF[a, 1] -= F1
        wF[a, 2] -= F2
        # moment on b: r_A x f with r_A = (0, 0, -h_b), plus -d x f
        e0, e1, e2 = _cross(d0, d1, d2, f0, f1, f2)
        wM[b, 0] += hb * f1 - e0
        wM[b, 1] += -hb * f0 - e1
        wM[b, 2] += -e2
        fa0, fa1, fa2 = _mtv(Ra, -F0, -F1, -F2)
        wM[a, 0] += -ha * fa1
        wM[a, 1] += ha * fa0
        # rotational spring-damper
        g1 = p[oa + J_G1]
        g3 = p[oa + J_G3]
        cbe = p[oa + J_CBE]
        relative_rotation(Ra, Rb, Rrel)
        tb0 = -0.5 * (g3 * Rrel[2, 1] - g1 * Rrel[1, 2])
        tb1 = -0.5 * (g1 * Rrel[0, 2] - g3 * Rrel[2, 0])
        tb2 = -0.5 * g1 * (Rrel[1, 0] - Rrel[0, 1])
        ta0 = 0.5 * (g1 * Rrel[2, 1] - g3 * Rrel[1, 2])
        ta1 = 0.5 * (g3 * Rrel[0, 2] - g1 * Rrel[2, 0])
        ta2 = 0.5 * g1 * (Rrel[1, 0] - Rrel[0, 1])
        q0, q1, q2 = _mtv(Rrel, wxa, wya, wza)
        td0 = -cbe * (wxb - q0)
        td1 = -cbe * (wyb - q1)
        td2 = -p[oa + J_CTO] * (wzb - q2)
        wM[b, 0] += tb0 + td0
        wM[b, 1] += tb1 + td1
        wM[b, 2] += tb2 + td2
        s0, s1, s2 = _mv(Rrel, td0, td1, td2)
        wM[a, 0] += ta0 - s0
        wM[a, 1] += ta1 - s1
        wM[a, 2] += ta2 - s2
        Ga0, Ga1, Ga2, Va0, Va1, Va2 = Gb0, Gb1, Gb2, Vb0, Vb1, Vb2

    # actuator couples (site s at the joint below body ip[...]): moment on b, reaction on a
    o_act = IP_HDR + ns + ip[IP_NC]
    for s in range(na):
        a = ip[o_act + s]
        b = a + 1
        arm = p[NP + NB * a + J_ARM]
        t0 = -arm * u[2 * s + 1]
        t1 = arm * u[2 * s]
        relative_rotation(wR[a], wR[b], Rrel)
        wM[b, 0] += t0
        wM[b, 1] += t1
        s0, s1, s2 = _mv(Rrel, t0, t1, 0.0)
        wM[a, 0] -= s0
        wM[a, 1] -= s1
        wM[a, 2] -= s2

    # top drive joint on body 0 (top drive at the origin, rotating about its axis, hoisting)
    R0 = wR[0]
    h = p[NP + B_H]
    wx0 = y[oW]
    wy0 = y[oW + 1]
    wz0 = y[oW + 2]
    ang, om = drive_motion(t, y, p, ip, u)
    A0, A1, A2, V0, V1, V2 = top_point(t, y, p, framed, oV, R0, h)
    vA = _mv(R0, -h * wy0, h * wx0, 0.0)
    d0, d1, d2 = _mtv(R0, A0, A1, A2)
    r0, r1, r2 = _mtv(R0, V0 + vA[0], V1 + vA[1], V2 + vA[2])
    c0, c1, c2 = _cross(wx0, wy0, wz0, d0, d1, d2)
    klat = p[KT_LAT]
    clat = p[CT_LAT]
    f0 = -(klat * d0 + clat * (r0 - c0))
    f1 = -(klat * d1 + clat * (r1 - c1))
    f2 = -(p[KT_AX] * d2 + p[CT_AX] * (r2 - c2))
    F0, F1, F2 = _mv(R0, f0, f1, f2)
    wF[0, 0] += F0
    wF[0, 1] += F1
    wF[0, 2] += F2
    e0, e1, e2 = _cross(d0, d1, d2, f0, f1, f2)
    wM[0, 0] += h * f1 - e0
    wM[0, 1] += -h * f0 - e1
    wM[0, 2] += -e2
    ktt = p[KT_TO]
    if ktt > 0.0:
        Rt = R0
        if framed:  # the body's rotation relative to the top drive's frame
            _frame_tmm(p, TD_R, R0, S)
            Rt = S
        ca = math.cos(ang)
        sa = math.sin(ang)
        # Rrel = Rz(ang)^T Rt
        for j in range(3):
            Rrel[0, j] = ca * Rt[0, j] + sa * Rt[1, j]
            Rrel[1, j] = -sa * Rt[0, j] + ca * Rt[1, j]
            Rrel[2, j] = Rt[2, j]
        m0 = 0.5 * ktt * (Rrel[2, 1] + Rrel[1, 2])
        m1 = -0.5 * ktt * (Rrel[0, 2] + Rrel[2, 0])
        m2 = -0.5 * ktt * (Rrel[1, 0] - Rrel[0, 1]) - p[CT_TO] * (wz0 - om * Rt[2, 2])
        wM[0, 0] += m0
        wM[0, 1] += m1
        wM[0, 2] += m2
        if ip[IP_TD] != TD_PRESCRIBED:
            drive_rates(y, dy, p, ip, u, Rt[2, 0] * m0 + Rt[2, 1] * m1 + Rt[2, 2] * m2)

    # bit: axial spring to the prescribed rock position (or the cutting law), resisting torque;
    # in the bit body's local frame (the inertial one unless framed)
    e = n - 1
    h = p[NP + NB * e + B_H]
    kb = p[KB_AX]
    if ip[IP_BIT] == BIT_CUTTING or kb > 0.0:
        Re = _local_rotation(y, oA, e, framed, wR, S)
        vB = _mv(Re, h * y[oW + 3 * e + 1], -h * y[oW + 3 * e], 0.0)
        if ip[IP_BIT] == BIT_CUTTING:
            x = ip[IP_BITX]
            wb, tqb, rop, dcut = cutting_bit(y[3 * e + 2] + h * Re[2, 2],
                                             y[oV + 3 * e + 2] + vB[2], y[x], y[oA + 3 * e],
                                             y[oW + 3 * e + 2], p)
            dy[x] = rop
            wM[e, 2] -= tqb
            Fz = -wb
        else:
            zr, vr = bit_rock(ang, om, p)
            Bz = y[3 * e + 2] + h * Re[2, 2]
            Fz = -kb * (Bz - zr) - p[CB_AX] * (y[oV + 3 * e + 2] + vB[2] - vr)
        if framed:
            _add_local_force(wF, p, e, framed, 0.0, 0.0, Fz)
        else:
            wF[e, 2] += Fz
        fb0, fb1, fb2 = _mtv(Re, 0.0, 0.0, Fz)
        wM[e, 0] += -h * fb1
        wM[e, 1] += h * fb0
    if p[BIT_TORQUE] > 0.0:
        wM[e, 2] -= p[BIT_TORQUE] * math.tanh(y[oW + 3 * e + 2] / p[BIT_EPS])

    # stabilizers: lateral springs at material points (to the local hole axis)
    ks = p[K_STAB]
    cs = p[C_STAB]
    for s in range(ns):
        k = ip[IP_HDR + s]
        zl = fp[s]
        R = _local_rotation(y, oA, k, framed, wR, S)
        vP = _mv(R, zl * y[oW + 3 * k + 1], -zl * y[oW + 3 * k], 0.0)
        P0 = y[3 * k] + zl * R[0, 2]
        P1 = y[3 * k + 1] + zl * R[1, 2]
        Fx = -ks * P0 - cs * (y[oV + 3 * k] + vP[0])
        Fy = -ks * P1 - cs * (y[oV + 3 * k + 1] + vP[1])
        if framed:
            _add_local_force(wF, p, k, framed, Fx, Fy, 0.0)
        else:
            wF[k, 0] += Fx
            wF[k, 1] += Fy
        fb0, fb1, fb2 = _mtv(R, Fx, Fy, 0.0)
        wM[k, 0] += -zl * fb1
        wM[k, 1] += zl * fb0

    # wellbore contact (eq. 14-17) at the contact points; normal force never pulls; optional
    # regularized Coulomb friction
    kc = p[K_CONT]
    cc = p[C_CONT]
    mu = p[MU_WALL]
    if kc == 0.0 and cc == 0.0:
        ncp = 0  # contact off: no cost
    o_cp = ns + NLD * nl
    for s in range(ncp):
        row = o_cp + NCP * s
        k = int(fp[row + CP_BODY])
        zl = fp[row + CP_Z]
        clr = fp[row + CP_CLR]
        X = y[3 * k]
        Y = y[3 * k + 1]
        Z = y[3 * k + 2]
        vx = y[oV + 3 * k]
        vy = y[oV + 3 * k + 1]
        vz = y[oV + 3 * k + 2]
        if zl != 0.0:  # a point off the mass centre (stabilizer blades, bit gauge)
            Rl = _local_rotation(y, oA, k, framed, wR, S)
            X += zl * Rl[0, 2]
            Y += zl * Rl[1, 2]
            Z += zl * Rl[2, 2]
            q0, q1, q2 = _mv(Rl, zl * y[oW + 3 * k + 1], -zl * y[oW + 3 * k], 0.0)
            vx += q0
            vy += q1
            vz += q2
        k1 = 0.0
        k2 = 0.0
        if framed:  # lateral offset from the curved hole axis
            o = NP + NB * k
            k1 = p[o + B_K1]
            k2 = p[o + B_K2]
            X -= 0.5 * k1 * Z * Z
            Y -= 0.5 * k2 * Z * Z
        dlt = math.sqrt(X * X + Y * Y)
        if dlt > clr:
            nx = X / dlt
            ny = Y / dlt
            vn = nx * vx + ny * vy
            fn = kc * (dlt - clr) + cc * vn
            if fn > 0.0:
                if not framed and zl == 0.0:
                    wF[k, 0] -= fn * nx
                    wF[k, 1] -= fn * ny
                    if mu > 0.0:
                        gx, gy, gz, m0, m1, m2 = wall_friction(
                            nx, ny, fn, mu, p[V_SLIP], fp[row + CP_RC], vx, vy, vz,
                            y[oW + 3 * k], y[oW + 3 * k + 1], y[oW + 3 * k + 2], wR[k])
                        wF[k, 0] += gx
                        wF[k, 1] += gy
                        wF[k, 2] += gz
                        wM[k, 0] += m0
                        wM[k, 1] += m1
                        wM[k, 2] += m2
                    continue
                Rl = _local_rotation(y, oA, k, framed, wR, S)
                fx = -fn * nx
                fy = -fn * ny
                fz = fn * (nx * k1 + ny * k2) * Z
                if mu > 0.0:
                    gx, gy, gz, m0, m1, m2 = wall_friction(
                        nx, ny, fn, mu, p[V_SLIP], fp[row + CP_RC], vx, vy, vz,
                        y[oW + 3 * k], y[oW + 3 * k + 1], y[oW + 3 * k + 2], Rl)
                    fx += gx
                    fy += gy
                    fz += gz
                    wM[k, 0] += m0
                    wM[k, 1] += m1
                    wM[k, 2] += m2
                if zl != 0.0:  # moment of the force at the point about the mass centre
                    b0, b1, b2 = _mtv(Rl, fx, fy, fz)
                    wM[k, 0] -= zl * b1
                    wM[k, 1] += zl * b0
                _add_local_force(wF, p, k, framed, fx, fy, fz)

    # mass unbalance: centrifugal force along body x
    if unb >= 0:
        R = wR[unb]
        wz = y[oW + 3 * unb + 2]
        fu = p[UNB] * wz * wz
        wF[unb, 0] += fu * R[0, 0]
        wF[unb, 1] += fu * R[1, 0]
        wF[unb, 2] += fu * R[2, 0]

    # external loads
    o_ld = ns
    for s in range(nl):
        row = o_ld + NLD * s
        if _load_active(fp, row):
            k = int(fp[row + LD_BODY])
            d = int(fp[row + LD_DIR])
            if fp[row + LD_KIND] == 0.0:
                wF[k, d] += fp[row + LD_MAG]
            else:
                wM[k, d] += fp[row + LD_MAG]

    # Newton (local frame; lateral with the mud's added mass), Euler with the gyroscopic term
    # (body frame)
    for k in range(n):
        o = NP + NB * k
        m = p[o + B_M]
        if framed:
            Fx, Fy, Fz = _frame_mtv(p, o + B_R, wF[k, 0], wF[k, 1], wF[k, 2])
            ml = p[o + B_ML]
            dy[oV + 3 * k] = Fx / ml
            dy[oV + 3 * k + 1] = Fy / ml
            dy[oV + 3 * k + 2] = Fz / m
        else:
            ml = p[o + B_ML]
            if ml == m:
                for i in range(3):
                    dy[oV + 3 * k + i] = wF[k, i] / m
            else:
                dy[oV + 3 * k] = wF[k, 0] / ml
                dy[oV + 3 * k + 1] = wF[k, 1] / ml
                dy[oV + 3 * k + 2] = wF[k, 2] / m
        jt = p[o + B_JT]
        jp = p[o + B_JP]
        wx = y[oW + 3 * k]
        wy = y[oW + 3 * k + 1]
        wz = y[oW + 3 * k + 2]
        dy[oW + 3 * k] = (wM[k, 0] - (jp - jt) * wy * wz) / jt
        dy[oW + 3 * k + 1] = (wM[k, 1] - (jt - jp) * wz * wx) / jt
        dy[oW + 3 * k + 2] = wM[k, 2] / jp
    if p[BIT_JX] > 0.0:  # bit and bottom-hole assembly: more polar inertia on the bit body
        k = n - 1
        o = NP + NB * k
        jt = p[o + B_JT]
        jpe = p[o + B_JP] + p[BIT_JX]
        wx = y[oW + 3 * k]
        wy = y[oW + 3 * k + 1]
        wz = y[oW + 3 * k + 2]
        dy[oW + 3 * k] = (wM[k, 0] - (jpe - jt) * wy * wz) / jt
        dy[oW + 3 * k + 1] = (wM[k, 1] - (jt - jpe) * wz * wx) / jt
        dy[oW + 3 * k + 2] = wM[k, 2] / jpe


@njit(cache=_CACHE, inline="always")
def sin_small(x: float) -> float:
    """``sin(x)``, fast for the small relative twist across a joint.

    For ``|x| <= 1/32`` rad the Taylor series to ``x^7`` (truncation ``x^9 / 9! < 3e-18 |x|``,
    below half an ulp; tested against ``math.sin``), else ``math.sin``. The library call was half
    the cost of the axial-torsional right-hand side.
    """
    if abs(x) <= 0.03125:
        x2 = x * x
        return x + x * x2 * (-1.0 / 6.0 + x2 * (1.0 / 120.0 - x2 * (1.0 / 5040.0)))
    return math.sin(x)


@njit(cache=_CACHE, inline="always")
def one_minus_cos_small(x: float) -> float:
    """``1 - cos(x)`` without cancellation for a small twist: Taylor to ``x^8`` for
    ``|x| <= 1/32`` rad (truncation below half an ulp), else ``2 sin(x/2)^2``."""
    x2 = x * x
    if x2 <= 0.0009765625:
        return x2 * (0.5 + x2 * (-1.0 / 24.0 + x2 * (1.0 / 720.0 - x2 * (1.0 / 40320.0))))
    s = math.sin(0.5 * x)
    return 2.0 * s * s


@njit(cache=_CACHE)
def rhs_at(t, y, dy, p, ip, fp, u, wR, wF, wM):
    """Axial-torsional right-hand side; writes dy (4 n). Unused scratch kept for one signature.

    One pass over the bodies: the force and torque of the joint above a body are carried from
    the previous body (no scratch arrays), end springs and loads added afterwards. Positions
    are depths along the (vertical) hole [m].
    """
    n = ip[IP_N]
    ns = ip[IP_NS]
    nl = ip[IP_NL]
    oV = 2 * n
    oW = 3 * n
    f_up = 0.0  # force [N] / torque [N m] of the joint above body k, acting on body k
    tq_up = 0.0
    for k in range(n - 1):
        o = NP + NB * k
        dy[k] = y[oV + k]
        dy[n + k] = y[oW + k]
        d = y[k + 1] - y[k] - p[o + J_LEN]
        f = -(p[o + J_KAX] * d + p[o + J_CAX] * (y[oV + k + 1] - y[oV + k]))
        tq = -(p[o + J_G1] * sin_small(y[n + k + 1] - y[n + k])
               + p[o + J_CTO] * (y[oW + k + 1] - y[oW + k]))
        dy[oV + k] = p[o + B_W] + f_up - f
        dy[oW + k] = tq_up - tq
        f_up = f
        tq_up = tq
    e = n - 1
    dy[e] = y[oV + e]
    dy[n + e] = y[oW + e]
    dy[oV + e] = p[NP + NB * e + B_W] + f_up
    dy[oW + e] = tq_up
    ang, om = drive_motion(t, y, p, ip, u)
    h = p[NP + B_H]
    if p[HOIST] != 0.0:
        zt, vt = top_hoist(t, p)
        dy[oV] += -(p[KT_AX] * (y[0] - h - zt) + p[CT_AX] * (y[oV] - vt))
    else:
        dy[oV] += -(p[KT_AX] * (y[0] - h) + p[CT_AX] * y[oV])
    if p[KT_TO] > 0.0:
        tq_top = -(p[KT_TO] * sin_small(y[n] - ang) + p[CT_TO] * (y[oW] - om))
        dy[oW] += tq_top
        if ip[IP_TD] != TD_PRESCRIBED:
            drive_rates(y, dy, p, ip, u, tq_top)
    h = p[NP + NB * e + B_H]
    if ip[IP_BIT] == BIT_CUTTING:
        x = ip[IP_BITX]
        wb, tqb, rop, dcut = cutting_bit(y[e] + h, y[oV + e], y[x], y[n + e], y[oW + e], p)
        dy[oV + e] -= wb
        dy[oW + e] -= tqb
        dy[x] = rop
    elif p[KB_AX] > 0.0:
        zr, vr = bit_rock(ang, om, p)
        dy[oV + e] += -p[KB_AX] * (y[e] + h - zr) - p[CB_AX] * (y[oV + e] - vr)
    if p[BIT_TORQUE] > 0.0:
        dy[oW + e] -= p[BIT_TORQUE] * math.tanh(y[oW + e] / p[BIT_EPS])
    for s in range(nl):
        row = ns + NLD * s
        if _load_active(fp, row) and int(fp[row + LD_DIR]) == 2:
            k = int(fp[row + LD_BODY])
            if int(fp[row + LD_KIND]) == 0:
                dy[oV + k] += fp[row + LD_MAG]
            else:
                dy[oW + k] += fp[row + LD_MAG]
    for k in range(n):
        o = NP + NB * k
        dy[oV + k] *= p[o + B_IM]
        dy[oW + k] *= p[o + B_IJP]
    if p[BIT_JX] > 0.0:  # bit and bottom-hole assembly: more polar inertia on the bit body
        jp = p[NP + NB * e + B_JP]
        dy[oW + e] *= jp / (jp + p[BIT_JX])


# The right-hand sides are called, not inlined (inline="always" is kept for the small helpers):
# inlined, every integrator and the compiled step typed the whole 3D rhs again, a cold
# compile of the closed loop took 88-98 s instead of 41-50 s, for a span ~3 % faster.
@njit(cache=_CACHE)
def rhs(model, t, y, dy, p, ip, fp, u, wR, wF, wM):
    """Dispatch to the model's right-hand side (one compiled entry point for the integrators)."""
    if model == MODEL_FULL3D:
        rhs3d(t, y, dy, p, ip, fp, u, wR, wF, wM)
    else:
        rhs_at(t, y, dy, p, ip, fp, u, wR, wF, wM)
