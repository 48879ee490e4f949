"""The string at rest (one job: statics and the initial state).

:class:`StaticState` is the part of :class:`plant.model.DrillstringModel` that lays the string
along the hole at its static axial stretch (a curved hole), solves the static axial chain under
gravity, weight on bit and the loads acting from t = 0, and builds the initial state from them.
"""

from __future__ import annotations

import math

import numpy as np

from . import layout as lay
from .trajectory import StringLay, WellPath, lay_string

__all__ = ["StaticState"]


class StaticState:
    """Mixin of :class:`plant.model.DrillstringModel`: static tensions and displacements, the
    laid string and the initial state.

    Uses the model's ``params``, ``kind``, ``bodies``, ``derived``, ``n``, ``n_state``,
    ``n_body_state``, ``aux_names``, ``framed`` and the parameter array ``p`` (whose bit
    reference positions :meth:`initial_state` sets).
    """

    def static_tensions(self, axis: np.ndarray, weight: np.ndarray) -> np.ndarray:
        """Static effective tension [N] in the top spring and each joint (shape (n,): entry k is
        the spring above body k), without wall friction, for body axes ``axis`` (n, 3).

        From the bit up: ``T_k = T_{k+1} (a_{k+1} . a_k) + W_k a_k,Z + F_k . a_k`` with ``W`` the
        (buoyed) weight [N] (``weight``, per body), ``F`` the axial loads acting for good from
        t = 0 and ``T_n`` minus the weight on bit: the joint forces act along the lower body's
        axis (the joints start without shear), so that the laid string is in exact axial
        balance. Once released the joints shear slightly and the hook load settles at the soft
        string's (~1 % higher in a 60 deg build).
        """
        n = self.n
        f = np.zeros((n, 3))
        f[:, 2] = weight
        for ld in self.params.loads:
            if ld.kind == "force" and ld.start <= 0.0 and math.isinf(ld.duration):
                f[ld.body - 1, "xyz".index(ld.direction)] += ld.magnitude
        T = np.zeros(n)
        below = -self.params.bit.weight_on_bit
        for k in range(n - 1, -1, -1):
            c = float(np.dot(axis[k + 1], axis[k])) if k < n - 1 else 1.0
            T[k] = below * c + float(np.dot(f[k], axis[k]))
            below = T[k]
        return T

    def _lay_string(self, weight: np.ndarray) -> StringLay:
        """The string along the hole at its static (frictionless) axial stretch."""
        prm = self.params
        tab = self.bodies
        path = WellPath(prm.trajectory.survey)
        n = self.n
        k_spring = np.concatenate([[self.p[lay.KT_AX]], tab.k_axial])
        gaps = np.zeros(n)
        lz = lay_string(path, tab.length, gaps)
        for _ in range(2):  # the stretch barely turns the axes: two passes settle it
            T = self.static_tensions(lz.axis, weight)
            gaps = np.where(k_spring > 0.0, T / np.where(k_spring > 0.0, k_spring, 1.0), 0.0)
            lz = lay_string(path, tab.length, gaps)
        return lz

    def _bit_end_z(self, y: np.ndarray) -> float:
        """Depth [m] of the bit end along the hole (local to the bit body when framed)."""
        h = self.bodies.half[-1]
        if self.kind == "full3d":
            n = self.n
            ang = y[3 * n + 3 * (n - 1): 3 * n + 3 * n]
            # R[2, 2] of kern.cardan (the same libm calls, the same bits), without a numba
            # dispatch: a model built only to declare an FMU's layout sets no numba up
            r22 = math.cos(float(ang[1])) * math.cos(float(ang[2]))
            return float(y[3 * (n - 1) + 2] + h * r22)
        return float(y[self.n - 1] + h)

    def static_axial_displacement(self) -> np.ndarray:
        """Static axial displacements [m] of the bodies under gravity and weight on bit.

        Solves the linear axial chain (top spring, joints; the bit force is the prescribed weight
        on bit; axial step loads acting from t = 0 are included). Returns shape (n,).
        """
        n = self.n
        p = self.p
        f = p[lay.NP + lay.B_W: lay.NP + lay.NB * n: lay.NB].copy()  # weights [N]
        f[-1] -= self.params.bit.weight_on_bit
        for ld in self.params.loads:  # axial forces acting from t = 0 on, for good
            if ld.kind == "force" and ld.direction == "z" and ld.start <= 0.0 \
                    and math.isinf(ld.duration):
                f[ld.body - 1] += ld.magnitude
        if not np.any(f):
            return np.zeros(n)
        kt = p[lay.KT_AX]
        if kt == 0.0:
            if abs(f.sum()) > 1e-9 * max(1.0, np.abs(f).max()):
                raise ValueError(
                    "top_drive.axial_stiffness = 0 with a net axial load: the weight "
                    f"{math.fsum(f) + self.params.bit.weight_on_bit:.6g} N (with the axial "
                    "loads) must equal bit.weight_on_bit"
                )
        kj = self.bodies.k_axial
        Kd = np.zeros((n, n))
        for a in range(n - 1):
            ka = kj[a]
            Kd[a, a] += ka
            Kd[a + 1, a + 1] += ka
            Kd[a, a + 1] -= ka
            Kd[a + 1, a] -= ka
        Kd[0, 0] += kt
        if kt == 0.0:
            Kd[0, 0] += kj[0] * 1e-12  # fix the floating chain's mean; the shape is what matters
        return np.linalg.solve(Kd, f)

    def initial_state(self) -> np.ndarray:
        """The string at rest along the hole axis in static axial equilibrium (without wall
        friction); shape (n_state,).

        A vertical hole: body positions are inertial (depths of the mass centres). A curved
        hole (``framed``): each body sits at its reference frame's origin (local position 0;
        the stretched string laid along the hole, :func:`plant.trajectory.lay_string`), and the
        string settles onto the low side once released.
        """
        n = self.n
        y = np.zeros(self.n_state)
        if self.framed:
            z = np.zeros(n)
        else:
            if self.params.uniform:
                z = (np.arange(n) + 0.5) * self.derived.dx + self.static_axial_displacement()
            else:
                tab = self.bodies
                z = tab.top + tab.half + self.static_axial_displacement()
            if self.kind == "full3d":
                y[2:3 * n:3] = z
            else:
                y[:n] = z
        if self.params.bit.axial_stiffness > 0.0:
            zb = z[-1] + self.bodies.half[-1]
            kb = self.p[lay.KB_AX]
            self.p[lay.ZBIT0] = zb - self.params.bit.weight_on_bit / kb
            if self.params.bit.model == "cutting":  # the hole bottom under the pressed bit
                self.p[lay.BIT_ZH0] = self.p[lay.ZBIT0]
                y[self.aux_names.index("bit.hole_bottom") + self.n_body_state] = self.p[lay.ZBIT0]
        return y
