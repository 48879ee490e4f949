"""Well trajectory: minimum-curvature survey interpolation and the string laid along the hole.

Inertial axes: X north, Y east, Z down (true vertical depth); the top drive sits at the origin
at measured depth (MD) 0. Between two survey stations the hole is a circular arc (the
minimum-curvature method, the industry standard): the unit tangent turns in one plane by the
dogleg angle ``beta``; the station-to-station displacement is ``L/2 RF (t1 + t2)`` with the
ratio factor ``RF = 2 / beta tan(beta / 2)``. Beyond the last station the hole goes on straight.

:func:`lay_string` places the rigid bodies of the string along the hole (the model's initial
state): each body is a chord of the hole axis whose lower end lies on the axis, separated from
the next body by its joint's static stretch, so that every joint starts without shear offset and
the string starts bent to the hole's curvature. Body frames are carried down the string by
parallel transport (the rotation-minimizing frame): consecutive frames differ by pure bending,
no twist.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

__all__ = ["WellPath", "StringLay", "lay_string", "rotation_between"]


def _direction(inc_deg: float, azi_deg: float) -> np.ndarray:
    """Unit tangent (X north, Y east, Z down) of inclination / azimuth [deg]."""
    i = math.radians(inc_deg)
    a = math.radians(azi_deg)
    return np.array([math.sin(i) * math.cos(a), math.sin(i) * math.sin(a), math.cos(i)])


def rotation_between(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The smallest rotation (3, 3) taking unit vector ``a`` to unit vector ``b`` (Rodrigues).

    Its axis is ``a x b``; ``a == b`` gives the identity. Antiparallel vectors have no unique
    smallest rotation and are refused.
    """
    c = float(np.dot(a, b))
    v = np.cross(a, b)
    s2 = float(np.dot(v, v))
    if s2 < 1e-30:
        if c > 0.0:
            return np.eye(3)
        raise ValueError("rotation_between: opposite directions (a 180 deg dogleg)")
    vx = np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])
    return np.eye(3) + vx + vx @ vx * ((1.0 - c) / s2)


class WellPath:
    """The hole axis from a survey table.

    Parameters
    ----------
    survey : sequence of (md [m], inclination [deg], azimuth [deg])
        Stations in rising MD, the first at MD 0; empty: a vertical hole.
    """

    def __init__(self, survey) -> None:
        rows = list(survey) or [(0.0, 0.0, 0.0)]
        self.md = np.array([r[0] for r in rows], dtype=float)
        self.t = np.array([_direction(r[1], r[2]) for r in rows])
        n = len(rows)
        self.pos = np.zeros((n, 3))
        self.beta = np.zeros(max(n - 1, 0))
        for i in range(n - 1):
            t1, t2 = self.t[i], self.t[i + 1]
            beta = math.acos(min(1.0, max(-1.0, float(np.dot(t1, t2)))))
            if beta > math.radians(179.0):
                raise ValueError(f"trajectory.survey: dogleg of {math.degrees(beta):.1f} deg "
                                 f"between MD {self.md[i]:g} and {self.md[i + 1]:g} m: the hole "
                                 "cannot turn back on itself")
            self.beta[i] = beta
            L = self.md[i + 1] - self.md[i]
            rf = 1.0 if beta < 1e-9 else 2.0 / beta * math.tan(0.5 * beta)
            self.pos[i + 1] = self.pos[i] + 0.5 * L * rf * (t1 + t2)

    def _segment(self, md: float) -> int:
        """Index of the station at or above ``md`` (the last one beyond the survey)."""
        return int(np.searchsorted(self.md, md, side="right")) - 1

    def evaluate(self, md: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Point [m], unit tangent and curvature vector dt/ds [1/m] of the axis at ``md`` [m]."""
        md = max(0.0, float(md))
        i = self._segment(md)
        s = md - self.md[i]
        if i >= len(self.md) - 1 or self.beta[i] < 1e-9:
            t = self.t[i]
            return self.pos[i] + s * t, t.copy(), np.zeros(3)
        t1, t2 = self.t[i], self.t[i + 1]
        L = self.md[i + 1] - self.md[i]
        b = self.beta[i]
        f = s / L
        sb = math.sin(b)
        p = self.pos[i] + L / (b * sb) * ((math.cos((1.0 - f) * b) - math.cos(b)) * t1
                                          + (1.0 - math.cos(f * b)) * t2)
        t = (math.sin((1.0 - f) * b) * t1 + math.sin(f * b) * t2) / sb
        k = b / L * (-math.cos((1.0 - f) * b) * t1 + math.cos(f * b) * t2) / sb
        return p, t / np.linalg.norm(t), k

    def point(self, md: float) -> np.ndarray:
        """Point [m] of the hole axis at measured depth ``md`` [m]."""
        return self.evaluate(md)[0]

    def tangent(self, md: float) -> np.ndarray:
        """Unit tangent of the hole axis at ``md`` [m] (pointing down the hole)."""
        return self.evaluate(md)[1]

    def md_at_distance(self, md0: float, q: np.ndarray, dist: float) -> float:
        """The MD > ``md0`` whose axis point lies at distance ``dist`` [m] from point ``q``.

        The straight distance from ``q`` (on or next to the axis at ``md0``) grows
        monotonically with MD along a hole that turns less than 180 deg over ``dist``; solved by
        Newton from ``md0 + dist`` with a bisection fallback.
        """
        def g(md: float) -> tuple[float, float]:
            p, t, _ = self.evaluate(md)
            r = p - q
            d = float(np.linalg.norm(r))
            return d - dist, float(np.dot(t, r)) / max(d, 1e-300)

        md = md0 + dist
        for _ in range(50):
            f, df = g(md)
            if abs(f) < 1e-12 * max(1.0, dist):
                return md
            if df <= 0.1:
                break
            md -= f / df
        lo, hi = md0, md0 + 2.0 * dist + 1.0
        while g(hi)[0] < 0.0:
            hi += dist
        for _ in range(200):
            mid = 0.5 * (lo + hi)
            if g(mid)[0] < 0.0:
                lo = mid
            else:
                hi = mid
        return 0.5 * (lo + hi)


@dataclass(frozen=True)
class StringLay:
    """The string laid along the hole: per body (top first), shapes (n, 3) or (n,).

    Attributes
    ----------
    centre : ndarray (n, 3)
        Mass centres G [m] (inertial).
    axis : ndarray (n, 3)
        Unit axis of each body (from its top end A to its bottom end B).
    frame : ndarray (n, 3, 3)
        Reference rotation body -> inertial of each body (``frame[k] @ e_z = axis[k]``), carried
        down by parallel transport from ``top_frame``.
    top_frame : ndarray (3, 3)
        Frame of the top drive: the smallest rotation from the vertical to the hole at MD 0.
    md : ndarray (n,)
        Measured depth [m] of each body's centre along the hole axis.
    curvature : ndarray (n, 3)
        Curvature vector of the hole axis dt/ds [1/m] at each body's centre (inertial).
    """

    centre: np.ndarray
    axis: np.ndarray
    frame: np.ndarray
    top_frame: np.ndarray
    md: np.ndarray
    curvature: np.ndarray


def lay_string(path: WellPath, lengths: np.ndarray, gaps: np.ndarray) -> StringLay:
    """Place rigid bodies of ``lengths`` [m] along ``path``, joint ``gaps`` [m] between them.

    ``gaps[0]`` is the static stretch of the top spring (between the top drive at MD 0 and the
    top of body 1), ``gaps[k]`` that of the joint above body k. Each body runs from
    ``A_k = Q + gaps[k] a_k`` to ``B_k`` on the hole axis with ``|B_k - A_k| = lengths[k]``, where
    ``Q`` is the previous body's bottom end (the top drive for body 1) and ``a_k`` the body's
    axis: a chord of the hole whose bottom end lies on the axis.
    """
    n = len(lengths)
    centre = np.zeros((n, 3))
    axis = np.zeros((n, 3))
    frame = np.zeros((n, 3, 3))
    md = np.zeros(n)
    curv = np.zeros((n, 3))
    t0 = path.tangent(0.0)
    top = rotation_between(np.array([0.0, 0.0, 1.0]), t0)
    q = np.zeros(3)
    md_q = 0.0
    prev_axis, prev_frame = t0, top
    for k in range(n):
        span = float(gaps[k] + lengths[k])
        md_b = path.md_at_distance(md_q, q, span)
        b = path.point(md_b)
        a_k = (b - q) / span
        a_k /= np.linalg.norm(a_k)
        A = q + gaps[k] * a_k
        centre[k] = 0.5 * (A + b)
        axis[k] = a_k
        frame[k] = rotation_between(prev_axis, a_k) @ prev_frame
        md[k] = md_b - 0.5 * lengths[k]
        curv[k] = path.evaluate(md[k])[2]
        prev_axis, prev_frame = a_k, frame[k]
        q, md_q = b, md_b
    return StringLay(centre, axis, frame, top, md, curv)
