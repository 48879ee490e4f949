"""Compiled output and energy kernels (what sensors and users read from a state).

``outputs3d`` / ``outputs_at`` fill ``out`` in the order given by
:func:`plant.signals.plant_outputs`; units are
in :data:`OUTPUT_UNITS`. Energies use exactly the potentials of the right-hand sides, so that the
undamped, unforced model conserves ``total_energy`` up to the integrator's error.
"""

from __future__ import annotations

import math

from numba import njit

from .kernels import (
    BIT_CUTTING,
    IP_BIT,
    IP_BITX,
    IP_FIELD,
    IP_FRAMED,
    IP_HDR,
    IP_N,
    IP_NA,
    IP_NC,
    IP_NCP,
    IP_NL,
    IP_NS,
    IP_XOUT,
    _frame_mm,
    _frame_tmm,
    _local_rotation,
    bit_rock,
    body_inertial,
    cardan,
    cutting_bit,
    drive_motion,
    gauge_strains,
    one_minus_cos_small,
    relative_rotation,
    sin_small,
    top_hoist,
    top_point,
)
from .layout import (
    B_CLR,
    B_H,
    B_JP,
    B_JT,
    B_K1,
    B_K2,
    B_M,
    B_ML,
    B_R,
    B_W,
    BIT_AMP,
    BIT_EPS,
    BIT_JX,
    BIT_LOBES,
    BIT_TORQUE,
    BIT_ZH0,
    C_CONT,
    CB_AX,
    CP_BODY,
    CP_CLR,
    CP_Z,
    CT_AX,
    CT_TO,
    HOIST,
    J_ARM,
    J_G1,
    J_G3,
    J_KAX,
    J_KSH,
    J_LEN,
    J_RG,
    K_CONT,
    K_STAB,
    KB_AX,
    KT_AX,
    KT_LAT,
    KT_TO,
    NB,
    NCP,
    NLD,
    NP,
    TD_R,
)
from .signals import EXTENDED_SCALAR_OUTPUTS, SCALAR_OUTPUTS, WHIRL_MIN_RADIUS

_CACHE = True

NSCAL = len(SCALAR_OUTPUTS)
NXSCAL = len(EXTENDED_SCALAR_OUTPUTS)


@njit(cache=_CACHE)
def _scalars_common(om, out, o, fb, tb, tt, hook, wbit, zdisp, twist, energy):
    out[o] = fb
    out[o + 1] = tb
    out[o + 2] = tt
    out[o + 3] = hook
    out[o + 4] = om
    out[o + 5] = wbit
    out[o + 6] = zdisp
    out[o + 7] = twist
    out[o + 8] = energy


@njit(cache=_CACHE)
def _bit_contact_energy(zb, zh, th, p):
    """Elastic energy [J] of the cutting bit's contact spring (0 off bottom)."""
    pen = zb - (zh + p[BIT_AMP] * math.sin(p[BIT_LOBES] * th))
    return 0.5 * p[KB_AX] * pen * pen if pen > 0.0 else 0.0


@njit(cache=_CACHE)
def _scalars_extended(out, o, ip, y, p, fb, rop, dcut):
    """The extensions' scalars (:data:`EXTENDED_SCALAR_OUTPUTS`) at ``out[o:]``."""
    cutting = ip[IP_BIT] == BIT_CUTTING
    out[o] = rop
    out[o + 1] = y[ip[IP_BITX]] - p[BIT_ZH0] if cutting else 0.0
    out[o + 2] = dcut
    out[o + 3] = 1.0 if (cutting and fb > 0.0) else 0.0


@njit(cache=_CACHE, inline="always")
def _point_offset(y, p, oA, oV, oW, k, zl, framed, wR, S):
    """Lateral offset (X, Y) [m] from the hole axis and velocity (vx, vy) [m/s] of the point
    ``zl`` [m] along body ``k``'s axis from its mass centre (local frame when framed)."""
    X = y[3 * k]
    Y = y[3 * k + 1]
    Z = y[3 * k + 2]
    vx = y[oV + 3 * k]
    vy = y[oV + 3 * k + 1]
    if zl != 0.0:
        Rl = _local_rotation(y, oA, k, framed, wR, S)
        X += zl * Rl[0, 2]
        Y += zl * Rl[1, 2]
        Z += zl * Rl[2, 2]
        vx += zl * (Rl[0, 0] * y[oW + 3 * k + 1] - Rl[0, 1] * y[oW + 3 * k])
        vy += zl * (Rl[1, 0] * y[oW + 3 * k + 1] - Rl[1, 1] * y[oW + 3 * k])
    if framed:
        o = NP + NB * k
        X -= 0.5 * p[o + B_K1] * Z * Z
        Y -= 0.5 * p[o + B_K2] * Z * Z
    return X, Y, vx, vy


@njit(cache=_CACHE)
def outputs3d(t, y, p, ip, fp, u, wR, zbit_ref, out):
    """Fill ``out`` with the 3D model's outputs; wR (n + 2, 3, 3) is scratch."""
    n = ip[IP_N]
    ns = ip[IP_NS]
    nc = ip[IP_NC]
    na = ip[IP_NA]
    nl = ip[IP_NL]
    ncp = ip[IP_NCP]
    framed = ip[IP_FRAMED] != 0
    oA = 3 * n
    oV = 6 * n
    oW = 9 * n
    Rrel = wR[n]
    S = wR[n + 1]
    for k in range(n):
        if framed:
            cardan(y[oA + 3 * k], y[oA + 3 * k + 1], y[oA + 3 * k + 2], S)
            _frame_mm(p, NP + NB * k + B_R, S, wR[k])
        else:
            cardan(y[oA + 3 * k], y[oA + 3 * k + 1], y[oA + 3 * k + 2], wR[k])
    o = 0
    for s in range(nc):
        k = ip[IP_HDR + ns + s]
        X, Y, vx, vy = _point_offset(y, p, oA, oV, oW, k, 0.0, framed, wR, S)
        dl = math.sqrt(X * X + Y * Y)
        pen = dl - p[NP + NB * k + B_CLR]
        fc = 0.0
        if pen > 0.0:
            fc = p[K_CONT] * pen
            # contact damping acts too, but never pulls
            vn = (X * vx + Y * vy) / dl
            fc = max(fc + p[C_CONT] * vn, 0.0)
        out[o] = X
        out[o + 1] = Y
        out[o + 2] = dl
        out[o + 3] = fc
        # whirl: angular velocity of the centre about the well axis, and its sense vs the spin
        whirl = 0.0
        sense = 0.0
        if dl > WHIRL_MIN_RADIUS:
            whirl = (X * vy - Y * vx) / (dl * dl)
            R = _local_rotation(y, oA, k, framed, wR, S)
            spin = R[2, 0] * y[oW + 3 * k] + R[2, 1] * y[oW + 3 * k + 1] + R[2, 2] * y[oW + 3 * k + 2]
            if whirl * spin > 0.0:
                sense = 1.0
            elif whirl * spin < 0.0:
                sense = -1.0
        if ip[IP_XOUT] == 0:
            o += 4
            continue
        out[o + 4] = whirl
        out[o + 5] = sense
        o += 6
    for s in range(na):
        a = ip[IP_HDR + ns + nc + s]
        b = a + 1
        oa = NP + NB * a
        arm = p[oa + J_ARM]
        relative_rotation(wR[a], wR[b], Rrel)
        eps_c, eps_e = gauge_strains(Rrel, p[oa + J_RG], p[oa + J_LEN])
        wxa = y[oW + 3 * a]
        wya = y[oW + 3 * a + 1]
        wza = y[oW + 3 * a + 2]
        q0 = Rrel[0, 0] * wxa + Rrel[1, 0] * wya + Rrel[2, 0] * wza
        q1 = Rrel[0, 1] * wxa + Rrel[1, 1] * wya + Rrel[2, 1] * wza
        wrx = y[oW + 3 * b] - q0
        wry = y[oW + 3 * b + 1] - q1
        out[o] = eps_c
        out[o + 1] = eps_e
        out[o + 2] = -arm * u[2 * s + 1] * wrx + arm * u[2 * s] * wry
        o += 3
    # wall contact at every contact point: energy and the field summary
    e_cont = 0.0
    max_dl = 0.0
    f_wall = 0.0
    touching = 0.0
    o_cp = ns + NLD * nl
    for s in range(ncp):
        row = o_cp + NCP * s
        k = int(fp[row + CP_BODY])
        X, Y, vx, vy = _point_offset(y, p, oA, oV, oW, k, fp[row + CP_Z], framed, wR, S)
        dl = math.sqrt(X * X + Y * Y)
        max_dl = max(max_dl, dl)
        pen = dl - fp[row + CP_CLR]
        if pen > 0.0:
            e_cont += 0.5 * p[K_CONT] * pen * pen
            if p[K_CONT] > 0.0 or p[C_CONT] > 0.0:
                fc = max(p[K_CONT] * pen + p[C_CONT] * (X * vx + Y * vy) / dl, 0.0)
                f_wall += fc
                if fc > 0.0:
                    touching += 1.0
    # energies
    ke = 0.0
    pe = 0.0
    for k in range(n):
        ob = NP + NB * k
        m = p[ob + B_M]
        ml = p[ob + B_ML]
        jt = p[ob + B_JT]
        jp = p[ob + B_JP]
        vx = y[oV + 3 * k]
        vy = y[oV + 3 * k + 1]
        vz = y[oV + 3 * k + 2]
        wx = y[oW + 3 * k]
        wy = y[oW + 3 * k + 1]
        wz = y[oW + 3 * k + 2]
        if ml == m:
            ke += 0.5 * m * (vx * vx + vy * vy + vz * vz) + 0.5 * (jt * (wx * wx + wy * wy) + jp * wz * wz)
        else:
            ke += 0.5 * (ml * (vx * vx + vy * vy) + m * vz * vz) + 0.5 * (
                jt * (wx * wx + wy * wy) + jp * wz * wz)
        Gk = body_inertial(y, p, k, framed, oV)
        pe -= p[ob + B_W] * Gk[2]
    Ga0, Ga1, Ga2, Va0, Va1, Va2 = body_inertial(y, p, 0, framed, oV)
    for a in range(n - 1):
        b = a + 1
        oa = NP + NB * a
        ha = p[oa + B_H]
        hb = p[oa + NB + B_H]
        Gb0, Gb1, Gb2, Vb0, Vb1, Vb2 = body_inertial(y, p, b, framed, oV)
        Ra = wR[a]
        Rb = wR[b]
        d0 = (Gb0 - hb * Rb[0, 2]) - (Ga0 + ha * Ra[0, 2])
        d1 = (Gb1 - hb * Rb[1, 2]) - (Ga1 + ha * Ra[1, 2])
        d2 = (Gb2 - hb * Rb[2, 2]) - (Ga2 + ha * Ra[2, 2])
        e0 = Rb[0, 0] * d0 + Rb[1, 0] * d1 + Rb[2, 0] * d2
        e1 = Rb[0, 1] * d0 + Rb[1, 1] * d1 + Rb[2, 1] * d2
        e2 = Rb[0, 2] * d0 + Rb[1, 2] * d1 + Rb[2, 2] * d2
        pe += 0.5 * (p[oa + J_KSH] * (e0 * e0 + e1 * e1) + p[oa + J_KAX] * e2 * e2)
        relative_rotation(Ra, Rb, Rrel)
        pe += 0.5 * (p[oa + J_G1] * (2.0 - Rrel[0, 0] - Rrel[1, 1])
                     + p[oa + J_G3] * (1.0 - Rrel[2, 2]))
        Ga0, Ga1, Ga2 = Gb0, Gb1, Gb2
    # top joint
    h = p[NP + B_H]
    R0 = wR[0]
    A0, A1, A2, V0, V1, V2 = top_point(t, y, p, framed, oV, R0, h)
    e0 = R0[0, 0] * A0 + R0[1, 0] * A1 + R0[2, 0] * A2
    e1 = R0[0, 1] * A0 + R0[1, 1] * A1 + R0[2, 1] * A2
    e2 = R0[0, 2] * A0 + R0[1, 2] * A1 + R0[2, 2] * A2
    pe += 0.5 * (p[KT_LAT] * (e0 * e0 + e1 * e1) + p[KT_AX] * e2 * e2)
    # axial tension: the top spring's force, d(body-z) > 0 stretches it (damping included)
    vA0 = V0 + h * (-R0[0, 0] * y[oW + 1] + R0[0, 1] * y[oW])
    vA1 = V1 + h * (-R0[1, 0] * y[oW + 1] + R0[1, 1] * y[oW])
    vA2 = V2 + h * (-R0[2, 0] * y[oW + 1] + R0[2, 1] * y[oW])
    r2 = R0[0, 2] * vA0 + R0[1, 2] * vA1 + R0[2, 2] * vA2
    c2 = y[oW] * e1 - y[oW + 1] * e0
    hook = p[KT_AX] * e2 + p[CT_AX] * (r2 - c2)
    ang, om = drive_motion(t, y, p, ip, u)
    ktt = p[KT_TO]
    tt = 0.0
    if ktt > 0.0:
        Rt = R0
        if framed:
            _frame_tmm(p, TD_R, R0, S)
            Rt = S
        ca = math.cos(ang)
        sa = math.sin(ang)
        for j in range(3):
            Rrel[0, j] = ca * Rt[0, j] + sa * Rt[1, j]
            Rrel[1, j] = -sa * Rt[0, j] + ca * Rt[1, j]
            Rrel[2, j] = Rt[2, j]
        pe += 0.5 * ktt * ((1.0 - Rrel[0, 0]) + (1.0 - Rrel[1, 1]) - (1.0 - Rrel[2, 2]))
        tt = -0.5 * ktt * (Rrel[1, 0] - Rrel[0, 1]) - p[CT_TO] * (y[oW + 2] - om * Rt[2, 2])
    # bit (in the bit body's local frame)
    e = n - 1
    h = p[NP + NB * e + B_H]
    Re = _local_rotation(y, oA, e, framed, wR, S)
    fb = 0.0
    bz = y[3 * e + 2] + h * Re[2, 2]
    tb = 0.0
    rop = 0.0
    dcut = 0.0
    if ip[IP_BIT] == BIT_CUTTING:
        vbz = y[oV + 3 * e + 2] + h * (Re[2, 0] * y[oW + 3 * e + 1] - Re[2, 1] * y[oW + 3 * e])
        fb, tb, rop, dcut = cutting_bit(bz, vbz, y[ip[IP_BITX]], y[oA + 3 * e],
                                        y[oW + 3 * e + 2], p)
        pe += _bit_contact_energy(bz, y[ip[IP_BITX]], y[oA + 3 * e], p)
    elif p[KB_AX] > 0.0:
        zr, vr = bit_rock(ang, om, p)
        vbz = y[oV + 3 * e + 2] + h * (Re[2, 0] * y[oW + 3 * e + 1] - Re[2, 1] * y[oW + 3 * e])
        fb = p[KB_AX] * (bz - zr) + p[CB_AX] * (vbz - vr)
        pe += 0.5 * p[KB_AX] * (bz - zr) ** 2
    if p[BIT_TORQUE] > 0.0:
        tb += p[BIT_TORQUE] * math.tanh(y[oW + 3 * e + 2] / p[BIT_EPS])
    ke += 0.5 * p[BIT_JX] * y[oW + 3 * e + 2] ** 2
    # stabilizers
    for s in range(ns):
        k = ip[IP_HDR + s]
        zl = fp[s]
        R = _local_rotation(y, oA, k, framed, wR, S)
        P0 = y[3 * k] + zl * R[0, 2]
        P1 = y[3 * k + 1] + zl * R[1, 2]
        pe += 0.5 * p[K_STAB] * (P0 * P0 + P1 * P1)
    pe += e_cont
    _scalars_common(om, out, o, fb, tb, tt, hook, y[oW + 3 * e + 2], bz - zbit_ref,
                    y[oA + 3 * e] - ang, ke + pe)
    o += NSCAL
    if ip[IP_XOUT] != 0:
        _scalars_extended(out, o, ip, y, p, fb, rop, dcut)
        o += NXSCAL
    if ip[IP_FIELD] != 0:
        out[o] = max_dl
        out[o + 1] = f_wall
        out[o + 2] = touching


@njit(cache=_CACHE)
def outputs_at(t, y, p, ip, fp, u, wR, zbit_ref, out):
    """Fill ``out`` with the axial-torsional model's outputs."""
    n = ip[IP_N]
    ke = 0.0
    pe = 0.0
    for k in range(n):
        o = NP + NB * k
        ke += 0.5 * p[o + B_M] * y[2 * n + k] ** 2 + 0.5 * p[o + B_JP] * y[3 * n + k] ** 2
        pe -= p[o + B_W] * y[k]
    for a in range(n - 1):
        o = NP + NB * a
        d = y[a + 1] - y[a] - p[o + J_LEN]
        pe += 0.5 * p[o + J_KAX] * d * d + p[o + J_G1] * one_minus_cos_small(y[n + a + 1] - y[n + a])
    h = p[NP + B_H]
    zt, vt = top_hoist(t, p)
    stretch = y[0] - h - zt if p[HOIST] != 0.0 else y[0] - h
    pe += 0.5 * p[KT_AX] * stretch ** 2
    hook = p[KT_AX] * stretch + p[CT_AX] * (y[2 * n] - vt)
    ang, om = drive_motion(t, y, p, ip, u)
    tt = 0.0
    if p[KT_TO] > 0.0:
        pe += p[KT_TO] * one_minus_cos_small(y[n] - ang)
        tt = -(p[KT_TO] * sin_small(y[n] - ang) + p[CT_TO] * (y[3 * n] - om))
    e = n - 1
    bz = y[e] + p[NP + NB * e + B_H]
    fb = 0.0
    tb = 0.0
    rop = 0.0
    dcut = 0.0
    if ip[IP_BIT] == BIT_CUTTING:
        fb, tb, rop, dcut = cutting_bit(bz, y[2 * n + e], y[ip[IP_BITX]], y[n + e], y[3 * n + e],
                                        p)
        pe += _bit_contact_energy(bz, y[ip[IP_BITX]], y[n + e], p)
    elif p[KB_AX] > 0.0:
        zr, vr = bit_rock(ang, om, p)
        fb = p[KB_AX] * (bz - zr) + p[CB_AX] * (y[2 * n + e] - vr)
        pe += 0.5 * p[KB_AX] * (bz - zr) ** 2
    if p[BIT_TORQUE] > 0.0:
        tb += p[BIT_TORQUE] * math.tanh(y[3 * n + e] / p[BIT_EPS])
    ke += 0.5 * p[BIT_JX] * y[3 * n + e] ** 2
    _scalars_common(om, out, 0, fb, tb, tt, hook, y[3 * n + e], bz - zbit_ref,
                    y[n + e] - ang, ke + pe)
    if ip[IP_XOUT] != 0:
        _scalars_extended(out, NSCAL, ip, y, p, fb, rop, dcut)
