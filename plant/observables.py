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
    IP_HDR,
    IP_N,
    IP_NA,
    IP_NC,
    IP_NS,
    IP_XOUT,
    bit_rock,
    cardan,
    cutting_bit,
    drive_motion,
    gauge_strains,
    one_minus_cos_small,
    relative_rotation,
    sin_small,
)
from .layout import (
    ACT_ARM,
    BIT_AMP,
    BIT_EPS,
    BIT_JX,
    BIT_LOBES,
    BIT_TORQUE,
    BIT_ZH0,
    C_CONT,
    CB_AX,
    CLEAR,
    CT_AX,
    CT_TO,
    G1,
    G3,
    GAUGE_R,
    GRAV,
    HALF,
    JP,
    JT,
    K_AX,
    K_CONT,
    K_SH,
    K_STAB,
    KB_AX,
    KT_AX,
    KT_LAT,
    KT_TO,
    MASS,
)
from .signals import SCALAR_OUTPUTS, WHIRL_MIN_RADIUS

_CACHE = True

NSCAL = len(SCALAR_OUTPUTS)


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


@njit(cache=_CACHE)
def outputs3d(t, y, p, ip, fp, u, wR, zbit_ref, out):
    """Fill ``out`` with the 3D model's outputs; wR (n+1, 3, 3) is scratch."""
    n = ip[IP_N]
    ns = ip[IP_NS]
    nc = ip[IP_NC]
    na = ip[IP_NA]
    h = p[HALF]
    dx = 2.0 * h
    m = p[MASS]
    oA = 3 * n
    oV = 6 * n
    oW = 9 * n
    Rrel = wR[n]
    for k in range(n):
        cardan(y[oA + 3 * k], y[oA + 3 * k + 1], y[oA + 3 * k + 2], wR[k])
    o = 0
    clr = p[CLEAR]
    e_cont = 0.0
    for s in range(nc):
        k = ip[IP_HDR + ns + s]
        X = y[3 * k]
        Y = y[3 * k + 1]
        dl = math.sqrt(X * X + Y * Y)
        pen = dl - clr
        fc = 0.0
        if pen > 0.0:
            fc = p[K_CONT] * pen
            e_cont += 0.5 * p[K_CONT] * pen * pen
            # contact damping acts too, but never pulls
            vn = (X * y[oV + 3 * k] + Y * y[oV + 3 * k + 1]) / dl
            fc = max(fc + p[C_CONT] * vn, 0.0)
        out[o] = X
        out[o + 1] = Y
        out[o + 2] = dl
        out[o + 3] = fc
        # whirl: angular velocity of the centre about the well axis, and its sense vs the spin
        whirl = 0.0
        sense = 0.0
        if dl > WHIRL_MIN_RADIUS:
            whirl = (X * y[oV + 3 * k + 1] - Y * y[oV + 3 * k]) / (dl * dl)
            R = wR[k]
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
    rg = p[GAUGE_R]
    arm = p[ACT_ARM]
    for s in range(na):
        a = ip[IP_HDR + ns + nc + s]
        b = a + 1
        relative_rotation(wR[a], wR[b], Rrel)
        eps_c, eps_e = gauge_strains(Rrel, rg, dx)
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
    # energies
    jt = p[JT]
    jp = p[JP]
    ke = 0.0
    pe = 0.0
    g = p[GRAV]
    for k in range(n):
        vx = y[oV + 3 * k]
        vy = y[oV + 3 * k + 1]
        vz = y[oV + 3 * k + 2]
        wx = y[oW + 3 * k]
        wy = y[oW + 3 * k + 1]
        wz = y[oW + 3 * k + 2]
        ke += 0.5 * m * (vx * vx + vy * vy + vz * vz) + 0.5 * (jt * (wx * wx + wy * wy) + jp * wz * wz)
        pe -= m * g * y[3 * k + 2]
    g1 = p[G1]
    g3 = p[G3]
    ksh = p[K_SH]
    kax = p[K_AX]
    for a in range(n - 1):
        b = a + 1
        Ra = wR[a]
        Rb = wR[b]
        d0 = (y[3 * b] - h * Rb[0, 2]) - (y[3 * a] + h * Ra[0, 2])
        d1 = (y[3 * b + 1] - h * Rb[1, 2]) - (y[3 * a + 1] + h * Ra[1, 2])
        d2 = (y[3 * b + 2] - h * Rb[2, 2]) - (y[3 * a + 2] + h * Ra[2, 2])
        e0 = Rb[0, 0] * d0 + Rb[1, 0] * d1 + Rb[2, 0] * d2
        e1 = Rb[0, 1] * d0 + Rb[1, 1] * d1 + Rb[2, 1] * d2
        e2 = Rb[0, 2] * d0 + Rb[1, 2] * d1 + Rb[2, 2] * d2
        pe += 0.5 * (ksh * (e0 * e0 + e1 * e1) + kax * e2 * e2)
        relative_rotation(Ra, Rb, Rrel)
        pe += 0.5 * (g1 * (2.0 - Rrel[0, 0] - Rrel[1, 1]) + g3 * (1.0 - Rrel[2, 2]))
    # top joint
    R0 = wR[0]
    A0 = y[0] - h * R0[0, 2]
    A1 = y[1] - h * R0[1, 2]
    A2 = y[2] - h * R0[2, 2]
    e0 = R0[0, 0] * A0 + R0[1, 0] * A1 + R0[2, 0] * A2
    e1 = R0[0, 1] * A0 + R0[1, 1] * A1 + R0[2, 1] * A2
    e2 = R0[0, 2] * A0 + R0[1, 2] * A1 + R0[2, 2] * A2
    pe += 0.5 * (p[KT_LAT] * (e0 * e0 + e1 * e1) + p[KT_AX] * e2 * e2)
    # axial tension: the top spring's force, d(body-z) > 0 stretches it (damping included)
    vA0 = y[oV] + h * (-R0[0, 0] * y[oW + 1] + R0[0, 1] * y[oW])
    vA1 = y[oV + 1] + h * (-R0[1, 0] * y[oW + 1] + R0[1, 1] * y[oW])
    vA2 = y[oV + 2] + h * (-R0[2, 0] * y[oW + 1] + R0[2, 1] * y[oW])
    r2 = R0[0, 2] * vA0 + R0[1, 2] * vA1 + R0[2, 2] * vA2
    c2 = y[oW] * e1 - y[oW + 1] * e0
    hook = p[KT_AX] * e2 + p[CT_AX] * (r2 - c2)
    ang, om = drive_motion(t, y, p, ip, u)
    ktt = p[KT_TO]
    tt = 0.0
    if ktt > 0.0:
        ca = math.cos(ang)
        sa = math.sin(ang)
        for j in range(3):
            Rrel[0, j] = ca * R0[0, j] + sa * R0[1, j]
            Rrel[1, j] = -sa * R0[0, j] + ca * R0[1, j]
            Rrel[2, j] = R0[2, j]
        pe += 0.5 * ktt * ((1.0 - Rrel[0, 0]) + (1.0 - Rrel[1, 1]) - (1.0 - Rrel[2, 2]))
        tt = -0.5 * ktt * (Rrel[1, 0] - Rrel[0, 1]) - p[CT_TO] * (y[oW + 2] - om * R0[2, 2])
    # bit
    e = n - 1
    Re = wR[e]
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
        P0 = y[3 * k] + zl * wR[k][0, 2]
        P1 = y[3 * k + 1] + zl * wR[k][1, 2]
        pe += 0.5 * p[K_STAB] * (P0 * P0 + P1 * P1)
    pe += e_cont
    _scalars_common(om, out, o, fb, tb, tt, hook, y[oW + 3 * e + 2], bz - zbit_ref,
                    y[oA + 3 * e] - ang, ke + pe)
    if ip[IP_XOUT] != 0:
        _scalars_extended(out, o + NSCAL, ip, y, p, fb, rop, dcut)


@njit(cache=_CACHE)
def outputs_at(t, y, p, ip, fp, u, wR, zbit_ref, out):
    """Fill ``out`` with the axial-torsional model's outputs."""
    n = ip[IP_N]
    h = p[HALF]
    dx = 2.0 * h
    m = p[MASS]
    jp = p[JP]
    g = p[GRAV]
    ke = 0.0
    pe = 0.0
    for k in range(n):
        ke += 0.5 * m * y[2 * n + k] ** 2 + 0.5 * jp * y[3 * n + k] ** 2
        pe -= m * g * y[k]
    for a in range(n - 1):
        d = y[a + 1] - y[a] - dx
        pe += 0.5 * p[K_AX] * d * d + p[G1] * one_minus_cos_small(y[n + a + 1] - y[n + a])
    pe += 0.5 * p[KT_AX] * (y[0] - h) ** 2
    hook = p[KT_AX] * (y[0] - h) + p[CT_AX] * y[2 * n]
    ang, om = drive_motion(t, y, p, ip, u)
    tt = 0.0
    if p[KT_TO] > 0.0:
        pe += p[KT_TO] * one_minus_cos_small(y[n] - ang)
        tt = -(p[KT_TO] * sin_small(y[n] - ang) + p[CT_TO] * (y[3 * n] - om))
    e = n - 1
    bz = y[e] + h
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

