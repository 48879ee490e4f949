"""An independent soft-string torque-and-drag model (Johancsik, Friesen and Dawson 1984).

Written for the tests from the paper's equations, sharing no code with ``plant/``: the string is
a cable lying on the hole wall. From the bit up, over elements of length ``dL`` with the buoyed
weight ``W = w dL``, average inclination ``theta`` and the changes of inclination / azimuth over
the element ``d_theta``, ``d_phi`` (upper minus lower end)::

    N = sqrt((F d_phi sin(theta))^2 + (F d_theta + W sin(theta))^2)   normal force on the wall
    F_upper = F + W cos(theta) + s mu N                              s = +1 pulling out,
                                                                       -1 running in, 0 rotating
    M_upper = M + mu N r                                             rotating off bottom

``F`` is the axial (effective) tension at the element's lower end, ``r`` the radius at which the
string touches the wall.

``lateral_friction`` (rotating only): Johancsik et al. set the normal force equal to the lateral
load ``P`` (the square root above). A rotating pipe's friction ``mu N`` acts along the wall's
circumference, i.e. laterally: the wall's reaction ``N n + mu N t`` balances ``P`` when the pipe
has climbed the wall by ``atan(mu)``, so ``N = P / sqrt(1 + mu^2)`` (a static balance of the
cross-section, used to compare with a model that resolves it).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence

__all__ = ["Element", "soft_string"]


class Element:
    """A piece of string: length [m], weight per length w [N/m] (buoyed), contact radius r [m]."""

    def __init__(self, length: float, weight_per_length: float, contact_radius: float) -> None:
        self.length = length
        self.w = weight_per_length
        self.r = contact_radius


def soft_string(string: Sequence[Element], angles: Callable[[float], tuple[float, float]],
                mu: float, mode: str, step: float = 1.0, bit_force: float = 0.0,
                lateral_friction: bool = False) -> tuple[float, float]:
    """Hook load [N] and surface torque [N m] of ``string`` (top first) in a hole whose
    inclination and azimuth [rad] at measured depth s [m] are ``angles(s)``.

    ``mode``: "out" (tripping out / pulling), "in" (tripping in / running), "rotate" (rotating
    off bottom: no axial drag). ``bit_force``: axial tension at the bit [N] (0 off bottom).
    """
    sign = {"out": 1.0, "in": -1.0, "rotate": 0.0}[mode]
    total = sum(e.length for e in string)
    # element boundaries from the bit up, never straddling two string sections
    cuts = {0.0, total}
    s = 0.0
    for e in string:
        s += e.length
        cuts.add(s)
        k = max(1, int(math.ceil(e.length / step)))
        for i in range(1, k):
            cuts.add(s - e.length + e.length * i / k)
    pts = sorted(cuts, reverse=True)
    F = bit_force
    M = 0.0
    for lo, up in zip(pts[:-1], pts[1:]):
        mid = 0.5 * (lo + up)
        acc = 0.0
        for e in string:  # the section holding this element
            acc += e.length
            if mid <= acc:
                sec = e
                break
        dL = lo - up
        W = sec.w * dL
        th_lo, ph_lo = angles(lo)
        th_up, ph_up = angles(up)
        th = 0.5 * (th_lo + th_up)
        dth = th_up - th_lo
        dph = ph_up - ph_lo
        N = math.hypot(F * dph * math.sin(th), F * dth + W * math.sin(th))
        if lateral_friction and mode == "rotate":
            N /= math.sqrt(1.0 + mu * mu)
        F = F + W * math.cos(th) + sign * mu * N
        if mode == "rotate":
            M += mu * N * sec.r
    return F, M
