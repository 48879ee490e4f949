"""Parameters -> the flat arrays of the compiled kernels (one job: array assembly).

:class:`ArrayAssembly` is the part of :class:`plant.model.DrillstringModel` that fills, once per
model, the parameter array ``p`` (scalars, then one record per body), the integer header and
index array ``ip``, the float tables ``fp`` (stabilizers, step loads, contact points) and the
breakpoints, from the typed parameter tree (:class:`plant.params.PlantParams`), the body
table (:mod:`plant.sections`) and the uniform pipe's per-segment quantities
(:mod:`plant.uniform_pipe`). The layout of the arrays is :mod:`plant.layout`'s.
"""

from __future__ import annotations

import math

import numpy as np

from . import kernels as kern
from . import layout as lay
from .params import BIT_MODELS, TOP_DRIVE_MODES, PlantParams
from .sections import (
    body_fluid,
    chain_first_frequency,
    joint_dampers,
    local_frequencies,
    max_joint_frequency,
)
from .uniform_pipe import Derived, derive, lateral_reference_frequency

__all__ = ["ArrayAssembly", "Derived", "derive", "field_outputs", "framed",
           "lateral_reference_frequency", "series"]


def series(k_boundary: float, k_half: float) -> float:
    """Stiffness [N/m or N m/rad] of a boundary spring in series with a half segment.

    ``inf`` means a rigid boundary (only the half segment remains), 0 a free end.
    """
    if k_boundary <= 0.0:
        return 0.0
    if math.isinf(k_boundary):
        return k_half
    return 1.0 / (1.0 / k_boundary + 1.0 / k_half)

def field_outputs(params: PlantParams) -> bool:
    """Do the outputs include the field summary (a string of sections or a trajectory)?"""
    return not params.uniform or params.trajectory is not None


def framed(params: PlantParams) -> bool:
    """Does the 3D model use per-body reference frames (a curved or inclined hole)?"""
    return params.trajectory is not None and not params.trajectory.vertical


class ArrayAssembly:
    """Mixin of :class:`plant.model.DrillstringModel`: the kernel arrays from the parameters.

    Uses the model's ``params``, ``kind``, ``bodies``, ``derived``, ``n``, ``n_body_state``,
    ``aux_names``, ``extended_outputs`` and its statics (``_lay_string``); sets ``p``, ``ip``,
    ``fp``, ``breakpoints``, ``framed``, ``field_outputs``, ``lay``, ``contact_bodies``,
    ``sites`` and ``n_sites``.
    """

    def _damping_rates(self) -> tuple[float, float, float, float, float]:
        """(beta_axial, beta_tors, beta_bend [s], alpha_lateral [1/s], max_joint_rate [1/s]).

        The uniform pipe: :func:`derive`'s values. Sections: ``beta = 2 zeta / w_1`` with ``w_1``
        the first mode of the lumped axial / torsional chain (fixed at the top drive, free at
        the bit); lateral drag or bending dampers only at a given
        ``damping.lateral_reference_frequency`` (the mud's drag damps a field string laterally).
        """
        prm = self.params
        dmp = prm.damping
        tab = self.bodies
        rate = dmp.max_joint_rate
        if rate == 0.0:
            rate = max_joint_frequency(tab)
        if prm.uniform:
            d = self.derived
            return d.beta_axial, d.beta_tors, d.beta_bend, d.alpha_lateral, rate
        seg_ax = self._segment_stiffness("axial")
        seg_to = self._segment_stiffness("tors")
        jp = tab.j_polar.copy()
        jp[-1] += prm.bit.inertia
        w_ax = chain_first_frequency(tab.mass, tab.k_axial, 2.0 * seg_ax[0])
        w_to = chain_first_frequency(jp, tab.k_tors, 2.0 * seg_to[0])
        b_ax = 2.0 * dmp.axial_ratio / w_ax
        b_to = 2.0 * dmp.torsional_ratio / w_to
        w_lat = dmp.lateral_reference_frequency
        if w_lat > 0.0 and dmp.lateral_model == "joint":
            return b_ax, b_to, 2.0 * dmp.lateral_ratio / w_lat, 0.0, rate
        alpha = 2.0 * dmp.lateral_ratio * w_lat if w_lat > 0.0 else 0.0
        return b_ax, b_to, b_ax, alpha, rate

    def _segment_stiffness(self, kind: str) -> np.ndarray:
        """Per body: the spring of its whole segment [N/m or N m/rad]: ``EA / dx`` (axial),
        ``kappa G A / dx`` (shear) or ``G J / dx`` (tors)."""
        from .sections import string_sections

        secs = string_sections(self.params)
        tab = self.bodies
        out = np.empty(tab.n)
        for k in range(tab.n):
            s = secs[tab.section[k]]
            if kind == "axial":
                out[k] = s.youngs_modulus * s.area / tab.length[k]
            elif kind == "shear":
                out[k] = s.kappa * s.shear_modulus * s.area / tab.length[k]
            else:
                out[k] = s.shear_modulus * s.polar_moment / tab.length[k]
        return out

    def _hole_diameters(self, md: np.ndarray) -> np.ndarray:
        """Hole diameter [m] at each measured depth (nan without a trajectory)."""
        traj = self.params.trajectory
        if traj is None:
            return np.full(md.size, np.nan)
        return np.array([traj.hole_diameter(float(x)) for x in md])

    def _build_arrays(self) -> None:
        prm = self.params
        tab = self.bodies
        n = self.n
        uniform = prm.uniform
        beta_ax, beta_to, beta_be, alpha_lat, max_rate = self._damping_rates()
        if uniform:  # the springs of a body's own segment (the top and bit joints' halves)
            d = self.derived
            k_ax0, k_sh0, k_to0 = (np.full(n, d.k_axial), np.full(n, d.k_shear),
                                   np.full(n, d.k_tors))
        else:
            k_ax0, k_sh0, k_to0 = (self._segment_stiffness(s) for s in ("axial", "shear", "tors"))
        p = np.zeros(lay.NP + lay.NB * n)
        # scalars of the uniform model (the top body's values for a string of sections: what
        # code written for a uniform string reads)
        p[lay.DX] = tab.length[0]
        p[lay.HALF] = tab.half[0]
        p[lay.MASS] = tab.mass[0]
        p[lay.JT] = tab.j_transverse[0]
        p[lay.JP] = tab.j_polar[0]
        p[lay.GRAV] = prm.gravity
        if n > 1:
            p[lay.K_AX] = tab.k_axial[0]
            p[lay.K_SH] = tab.k_shear[0]
            p[lay.K_BE] = tab.k_bend[0]
            p[lay.K_TO] = tab.k_tors[0]
            p[lay.C_AX] = beta_ax * tab.k_axial[0]
            p[lay.C_SH] = beta_ax * tab.k_shear[0]
            p[lay.C_BE] = beta_be * tab.k_bend[0]
            p[lay.C_TO] = beta_to * tab.k_tors[0]
            p[lay.G1] = tab.k_tors[0]
            p[lay.G3] = 2.0 * tab.k_bend[0] - tab.k_tors[0]
        td = prm.top_drive
        p[lay.KT_AX] = series(td.axial_stiffness, 2.0 * k_ax0[0])
        p[lay.KT_LAT] = series(td.lateral_stiffness, 2.0 * k_sh0[0])
        p[lay.KT_TO] = series(td.torsional_stiffness, 2.0 * k_to0[0])
        def end_damper(beta: float, k: float, inertia: float) -> float:
            return float(joint_dampers(beta, np.array([k]), np.array([4.0 * k / inertia]),
                                       max_rate)[0])

        h0 = tab.half[0]
        rot0 = max(1.0 / tab.mass[0], h0 * h0 / tab.j_transverse[0])
        p[lay.CT_AX] = end_damper(beta_ax, p[lay.KT_AX], tab.mass[0])
        p[lay.CT_LAT] = end_damper(beta_ax, p[lay.KT_LAT], 1.0 / rot0)
        p[lay.CT_TO] = end_damper(beta_to, p[lay.KT_TO], tab.j_polar[0])
        p[lay.OMEGA0] = td.rotary_speed
        p[lay.T_RAMP] = td.ramp_time
        p[lay.TD_INERTIA] = td.inertia
        p[lay.HOIST] = td.hoisting_speed
        p[lay.TD_R: lay.TD_R + 9] = np.eye(3).ravel()
        bit = prm.bit
        p[lay.KB_AX] = series(bit.axial_stiffness, 2.0 * k_ax0[-1])
        p[lay.CB_AX] = end_damper(beta_ax, p[lay.KB_AX], tab.mass[-1])
        p[lay.BIT_AMP] = bit.displacement_amplitude if bit.axial_stiffness > 0.0 else 0.0
        p[lay.BIT_LOBES] = bit.lobes
        p[lay.BIT_TORQUE] = bit.torque
        p[lay.BIT_EPS] = bit.slip_speed
        p[lay.BIT_A] = bit.radius
        p[lay.BIT_EPSI] = bit.intrinsic_specific_energy
        p[lay.BIT_ZETA] = bit.cutting_force_ratio
        p[lay.BIT_WF] = bit.wearflat_force
        p[lay.BIT_MU] = bit.friction_coefficient
        p[lay.BIT_WEAK] = bit.static_friction_ratio - 1.0
        p[lay.BIT_WSPD] = bit.weakening_speed
        p[lay.BIT_JX] = bit.inertia
        st = prm.stabilizers
        p[lay.K_STAB] = st.stiffness
        p[lay.C_STAB] = beta_ax * st.stiffness if st.damping < 0.0 else st.damping
        ct = prm.contact
        p[lay.K_CONT] = ct.stiffness if ct.enabled else 0.0
        p[lay.C_CONT] = ct.damping if ct.enabled else 0.0
        p[lay.CLEAR] = ct.clearance
        p[lay.MU_WALL] = ct.friction_coefficient if ct.enabled else 0.0
        p[lay.V_SLIP] = ct.friction_velocity
        ro = tab.outer_radius
        p[lay.R_OUT] = ro[0]
        ub = prm.unbalance
        p[lay.UNB] = ub.moment if ub.enabled else 0.0
        p[lay.ALPHA_LAT] = alpha_lat
        act = prm.actuators
        p[lay.ACT_ARM] = 2.0 * (act.radius or ro[0])
        p[lay.GAUGE_R] = act.gauge_radius or ro[0]
        self.p = p
        self.framed = framed(prm) and self.kind == "full3d"
        #: the outputs include the field summary (a string of sections or a trajectory)
        self.field_outputs = field_outputs(prm)

        # per-body records
        g = prm.gravity
        mass = tab.mass
        buoy = body_fluid(prm, tab, np.full(n, np.nan))[0]
        weight = np.where(buoy == 1.0, mass * g, mass * g * buoy)
        body_md = tab.top + tab.half
        if self.framed:
            self.lay = self._lay_string(weight)
            body_md = self.lay.md
        hole = self._hole_diameters(body_md)
        buoy, madd, clin, cq = body_fluid(prm, tab, hole)
        w2 = local_frequencies(tab)
        c_ax = joint_dampers(beta_ax, tab.k_axial, w2["axial"], max_rate)
        c_sh = joint_dampers(beta_ax, tab.k_shear, w2["shear"], max_rate)
        c_be = joint_dampers(beta_be, tab.k_bend, w2["bend"], max_rate)
        c_to = joint_dampers(beta_to, tab.k_tors, w2["tors"], max_rate)
        if prm.trajectory is None:
            clear = np.full(n, ct.clearance)
            rcon = np.full(n, p[lay.R_OUT]) if uniform else tab.contact_radius
        else:
            rcon = tab.contact_radius
            clear = 0.5 * hole - rcon
            bad = np.flatnonzero(clear < 0.0)
            if bad.size:
                k = int(bad[0])
                raise ValueError(
                    f"sections: body {k + 1} (contact diameter {2 * rcon[k]:g} m) does not fit "
                    f"the hole (diameter {hole[k]:g} m at measured depth {body_md[k]:.1f} m): "
                    "check trajectory.hole and the sections' contact_diameter")
        for k in range(n):
            o = lay.NP + lay.NB * k
            m = mass[k]
            p[o + lay.B_M] = m
            p[o + lay.B_IM] = 1.0 / m
            p[o + lay.B_ML] = m + madd[k] if madd[k] > 0.0 else m
            # the mud's added mass also follows a segment's rotation: + m_a dx^2 / 12
            p[o + lay.B_JT] = (tab.j_transverse[k] if madd[k] == 0.0 else
                               tab.j_transverse[k] + madd[k] * tab.length[k] ** 2 / 12.0)
            p[o + lay.B_JP] = tab.j_polar[k]
            p[o + lay.B_IJP] = 1.0 / tab.j_polar[k]
            p[o + lay.B_H] = tab.half[k]
            p[o + lay.B_W] = weight[k]
            p[o + lay.B_CLIN] = alpha_lat * m if clin[k] == 0.0 else alpha_lat * m + clin[k]
            p[o + lay.B_CQ] = cq[k]
            p[o + lay.B_R: o + lay.B_R + 9] = np.eye(3).ravel()
            p[o + lay.B_CLR] = clear[k]
            p[o + lay.B_RC] = rcon[k]
            if k < n - 1:
                p[o + lay.J_KAX] = tab.k_axial[k]
                p[o + lay.J_KSH] = tab.k_shear[k]
                p[o + lay.J_G1] = tab.k_tors[k]
                p[o + lay.J_G3] = 2.0 * tab.k_bend[k] - tab.k_tors[k]
                p[o + lay.J_CAX] = c_ax[k]
                p[o + lay.J_CSH] = c_sh[k]
                p[o + lay.J_CBE] = c_be[k]
                p[o + lay.J_CTO] = c_to[k]
                p[o + lay.J_LEN] = tab.joint_length[k]
                p[o + lay.J_RG] = act.gauge_radius or ro[k]
                p[o + lay.J_ARM] = 2.0 * (act.radius or ro[k])
                # the divergence guard's strain per radian: outer radius (the thinner body's)
                # over the joint's length (the uniform pipe: the pipe's radius / dx)
                p[o + lay.J_SF] = (0.5 * prm.pipe.outer_diameter / self.derived.dx if uniform
                                   else min(ro[k], ro[k + 1]) / tab.joint_length[k])
        if self.lay is not None:
            lz = self.lay
            p[lay.TD_R: lay.TD_R + 9] = lz.top_frame.ravel()
            for k in range(n):
                o = lay.NP + lay.NB * k
                F = lz.frame[k]
                p[o + lay.B_P: o + lay.B_P + 3] = lz.centre[k]
                p[o + lay.B_R: o + lay.B_R + 9] = F.ravel()
                kap = F.T @ lz.curvature[k]
                p[o + lay.B_K1] = kap[0]
                p[o + lay.B_K2] = kap[1]

        # stabilizers at material points: arc length s from the top
        L = prm.string_length
        tops = tab.top
        stab_body, stab_z = [], []
        for hgt in st.heights:
            s = L - hgt
            if uniform:
                dx = tab.length[0]
                k = min(int(math.floor(s / dx + 1e-9)), n - 1)
                stab_body.append(k)
                stab_z.append(s - (k + 0.5) * dx)
            else:
                k = min(int(np.searchsorted(tops, s + 1e-9, side="right")) - 1, n - 1)
                stab_body.append(k)
                stab_z.append(s - (tops[k] + tab.half[k]))
        if st.stiffness == 0.0:
            stab_body, stab_z = [], []
        self.contact_bodies = prm.contact_bodies
        self.sites = prm.actuator_joints
        self.n_sites = len(self.sites)
        # contact points: the monitored bodies (no trajectory), or every body and the bit's
        # gauge (a trajectory: a radial check against the local hole axis everywhere)
        if prm.trajectory is None:
            cps = [(b - 1, 0.0, ct.clearance, p[lay.R_OUT]) for b in self.contact_bodies]
        else:
            cps = [(k, 0.0, clear[k], rcon[k]) for k in range(n)]
            cps += self._stabilizer_points(hole)
            e = n - 1
            hole_bit = hole[e]
            cps.append((e, tab.half[e], max(0.0, 0.5 * hole_bit - bit.radius), bit.radius))
        unb = prm.unbalance_body - 1 if (ub.enabled and ub.moment > 0.0) else -1
        aux = {name: self.n_body_state + i for i, name in enumerate(self.aux_names)}
        ip = [n, len(stab_body), len(self.contact_bodies), self.n_sites, unb, len(prm.loads),
              TOP_DRIVE_MODES.index(td.mode), aux.get("top_drive.angle", -1),
              BIT_MODELS.index(prm.bit.model), aux.get("bit.hole_bottom", -1),
              int(self.extended_outputs), len(cps), int(self.framed), int(self.field_outputs)]
        assert len(ip) == kern.IP_HDR
        ip += stab_body + [b - 1 for b in self.contact_bodies] + [j - 1 for j in self.sites]
        self.ip = np.array(ip, dtype=np.int64)
        rows = []
        for ld in prm.loads:
            rows.append(
                [0.0 if ld.kind == "force" else 1.0, ld.body - 1, "xyz".index(ld.direction),
                 ld.magnitude, ld.start, ld.start + ld.duration, 0.0]
            )
        self.fp = np.concatenate([np.array(stab_z, dtype=float),
                                  np.array(rows, dtype=float).ravel(),
                                  np.array(cps, dtype=float).ravel()])
        # times [s] where an input of the model jumps (loads) or kinks (end of the speed ramp):
        # integrators step exactly to them (see integrators.next_breakpoint)
        bps = [t for ld in prm.loads for t in (ld.start, ld.start + ld.duration)]
        if td.ramp_time > 0.0 and (
                (td.mode == "prescribed" and td.rotary_speed != 0.0) or td.hoisting_speed != 0.0):
            bps.append(td.ramp_time)
        self.breakpoints = np.unique(np.array([t for t in bps if math.isfinite(t) and t > 0.0],
                                              dtype=float))

    def _stabilizer_points(self, hole: np.ndarray) -> list[tuple[int, float, float, float]]:
        """Contact points (body, offset from its centre [m], clearance [m], radius [m]) of the
        sections' stabilizer blades; ``hole`` [m] the hole diameter at every body."""
        from .sections import string_sections

        tab = self.bodies
        out = []
        top = 0.0
        for i, sec in enumerate(string_sections(self.params)):
            ks = np.flatnonzero(tab.section == i)
            for z in sec.stabilizers:
                s = top + z  # from the top of the string
                k = int(ks[min(np.searchsorted(tab.top[ks], s + 1e-9, side="right") - 1,
                               ks.size - 1)])
                r = 0.5 * sec.stabilizer_diameter
                clr = 0.5 * hole[k] - r
                if clr < 0.0:
                    raise ValueError(
                        f"sections ({sec.kind}): stabilizer_diameter {sec.stabilizer_diameter:g}"
                        f" m does not fit the hole (diameter {hole[k]:g} m)")
                out.append((k, s - (tab.top[k] + tab.half[k]), clr, r))
            top += sec.length
        return out
