"""Compiled validity checks of a state (one pass, no allocation): is the run diverging?

:func:`check_state` returns ``(code, index, value)``: code 0 = fine; otherwise the first
violation found, with the offending state index (codes 1, 4) or body / joint index (codes 2, 3,
5) and its value. :class:`plant.simulator.PlantSimulator` turns it into a message.
"""

from __future__ import annotations

import math

from numba import njit

from .kernels import IP_FRAMED, _frame_mm, cardan, relative_rotation
from .layout import B_R, J_SF, NB, NP

OK = 0
NOT_FINITE = 1  # index: state component
LATERAL = 2  # index: body; value: radial deflection [m]
TILT = 3  # index: body; value: |theta| or |phi| [rad]
SPEED = 4  # index: state component (velocity block); value [m/s or rad/s]
STRAIN = 5  # index: joint (below body index+1); value: bending strain [1]


@njit(cache=True)
def check_state(full3d, n, y, max_lateral, max_tilt, max_speed, max_strain, wR, p, ip,
                rotations_ready=False):
    """First violation in ``y`` (see the module docstring); wR is (n+2, 3, 3) scratch, ``p`` /
    ``ip`` the model's parameter arrays (a framed string's bodies turn with their reference
    frames: the strain is that of their inertial rotations, as the joints and gauges see it).

    The strain at a joint is its relative bending angle times the joint's factor
    (``p[NP + NB * a + J_SF]``: outer radius / joint length [1/m]). Every state must be finite;
    the speed limit applies to the bodies' velocity block (the auxiliary states after the
    ``12 n`` or ``4 n`` body states are checked for finiteness only).
    ``rotations_ready``: ``wR[:n]`` already holds the bodies' inertial rotation matrices of ``y``
    (the output kernel computed them the same way): not computed again.
    """
    N = y.size
    for i in range(N):
        if not math.isfinite(y[i]):
            return NOT_FINITE, i, y[i]
    nb = (12 if full3d else 4) * n
    half = nb // 2
    for i in range(half, nb):
        if abs(y[i]) > max_speed:
            return SPEED, i, y[i]
    if not full3d:
        return OK, -1, 0.0
    oA = 3 * n
    framed = ip[IP_FRAMED] != 0
    for k in range(n):
        r = math.sqrt(y[3 * k] ** 2 + y[3 * k + 1] ** 2)
        if r > max_lateral:
            return LATERAL, k, r
        th = abs(y[oA + 3 * k + 1])
        ph = abs(y[oA + 3 * k + 2])
        if th > max_tilt or ph > max_tilt:
            return TILT, k, max(th, ph)
        if rotations_ready:
            continue
        if framed:
            S = wR[n + 1]
            cardan(y[oA + 3 * k], y[oA + 3 * k + 1], y[oA + 3 * k + 2], S)
            _frame_mm(p, NP + NB * k + B_R, S, wR[k])
        else:
            cardan(y[oA + 3 * k], y[oA + 3 * k + 1], y[oA + 3 * k + 2], wR[k])
    Rrel = wR[n]
    for a in range(n - 1):
        relative_rotation(wR[a], wR[a + 1], Rrel)
        bx = 0.5 * (Rrel[2, 1] - Rrel[1, 2])
        by = 0.5 * (Rrel[0, 2] - Rrel[2, 0])
        eps = p[NP + NB * a + J_SF] * math.sqrt(bx * bx + by * by)
        if eps > max_strain:
            return STRAIN, a, eps
    return OK, -1, 0.0
