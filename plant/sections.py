"""The string's bodies and joints: per-body masses and inertias, per-joint springs and dampers.

A string is a list of sections (:class:`~plant.params.SectionParams`, top first); the paper's
uniform ``[pipe]`` is one section. Each section is cut into equal rigid bodies. Body k of length
``dx_k`` and mass ``m_k = m'_k dx_k`` (``m'`` the mass per length) has the polar inertia
``m (r_o^2 + r_i^2) / 2`` and the transverse inertia ``m (3 (r_o^2 + r_i^2) + dx^2) / 12`` about
its mass centre. The joint between bodies a and b joins their half segments in series:
``k = 1 / (h_a / (EA)_a + h_b / (EA)_b)`` axially (likewise shear ``kappa G A``, bending ``E I``
and torsion ``G J``), which is ``EA / dx`` inside a section. For one section every value is
computed exactly as the paper's uniform model (bit-identical).

Damping: stiffness-proportional joint dampers ``c = beta k`` with ``beta = 2 zeta / w_1`` for the
first axial / torsional mode (uniform pipe: the continuous rod's ``w_1``; sections: the lumped
chain's, fixed at the top drive, free at the bit). ``damping.max_joint_rate`` caps each joint's
``beta`` so that its overdamped local mode decays no faster than that rate (see
:func:`joint_dampers`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from . import fluid as fl
from .params import PlantParams, SectionParams

__all__ = ["BodyTable", "string_sections", "body_table", "joint_dampers", "local_frequencies",
           "max_joint_frequency", "chain_first_frequency", "body_fluid"]


def string_sections(params: PlantParams) -> tuple[SectionParams, ...]:
    """The string's sections, top first: ``params.sections`` or the pipe as one section."""
    if params.sections:
        return params.sections
    p = params.pipe
    return (SectionParams(kind="collar", length=p.length, outer_diameter=p.outer_diameter,
                          inner_diameter=p.inner_diameter, youngs_modulus=p.youngs_modulus,
                          shear_modulus=p.shear_modulus, density=p.density,
                          shear_coefficient=p.shear_coefficient,
                          segment_length=p.segment_length),)


@dataclass(frozen=True)
class BodyTable:
    """Per-body (shape (n,)) and per-joint (shape (n - 1,), joint k below body k) values, SI.

    Attributes
    ----------
    section : int array
        Section index of each body.
    length, half : [m]
        Body length and half length.
    top : [m]
        Distance of each body's top end from the top of the string (undeformed).
    mass : [kg]
    j_transverse, j_polar : [kg m^2]
        About the mass centre.
    outer_radius, inner_radius, contact_radius : [m]
    k_axial, k_shear : [N/m] (per joint)
    k_bend, k_tors : [N m/rad] (per joint)
    joint_length : [m] (per joint)
        Distance between the two mass centres, ``h_a + h_b``.
    """

    section: np.ndarray
    length: np.ndarray
    half: np.ndarray
    top: np.ndarray
    mass: np.ndarray
    j_transverse: np.ndarray
    j_polar: np.ndarray
    outer_radius: np.ndarray
    inner_radius: np.ndarray
    contact_radius: np.ndarray
    k_axial: np.ndarray
    k_shear: np.ndarray
    k_bend: np.ndarray
    k_tors: np.ndarray
    joint_length: np.ndarray

    @property
    def n(self) -> int:
        """Number of bodies."""
        return int(self.mass.size)


def _series(ha: float, pa: float, hb: float, pb: float) -> float:
    """Spring of two half segments in series: lengths ``ha``, ``hb`` [m], rigidities ``pa``,
    ``pb`` (EA [N], E I [N m^2], ...)."""
    return 1.0 / (ha / pa + hb / pb)


def body_table(params: PlantParams) -> BodyTable:
    """Masses, inertias and joint stiffnesses of every body / joint of the string."""
    secs = string_sections(params)
    sec_of = np.array(params.body_sections(), dtype=np.int64)
    lengths = np.array(params.body_lengths())
    n = lengths.size
    mass = np.empty(n)
    jp = np.empty(n)
    jt = np.empty(n)
    ro = np.empty(n)
    ri = np.empty(n)
    rc = np.empty(n)
    for k in range(n):
        s = secs[sec_of[k]]
        dx = lengths[k]
        ro[k] = s.outer_diameter / 2.0
        ri[k] = s.inner_diameter / 2.0
        rc[k] = s.contact_radius
        m = s.mass_per_length * dx
        mass[k] = m
        jp[k] = 0.5 * m * (ro[k] ** 2 + ri[k] ** 2)
        jt[k] = m * (3.0 * (ro[k] ** 2 + ri[k] ** 2) + dx**2) / 12.0
    kax = np.empty(n - 1)
    ksh = np.empty(n - 1)
    kbe = np.empty(n - 1)
    kto = np.empty(n - 1)
    jl = np.empty(n - 1)
    for a in range(n - 1):
        b = a + 1
        sa, sb = secs[sec_of[a]], secs[sec_of[b]]
        jl[a] = 0.5 * lengths[a] + 0.5 * lengths[b]
        if sec_of[a] == sec_of[b]:  # inside a section: exactly the uniform model's springs
            dx = lengths[a]
            A = sa.area
            kax[a] = sa.youngs_modulus * A / dx
            ksh[a] = sa.kappa * sa.shear_modulus * A / dx
            kbe[a] = sa.youngs_modulus * sa.second_moment / dx
            kto[a] = sa.shear_modulus * sa.polar_moment / dx
        else:  # two half segments in series
            ha, hb = 0.5 * lengths[a], 0.5 * lengths[b]
            kax[a] = _series(ha, sa.youngs_modulus * sa.area, hb, sb.youngs_modulus * sb.area)
            ksh[a] = _series(ha, sa.kappa * sa.shear_modulus * sa.area,
                             hb, sb.kappa * sb.shear_modulus * sb.area)
            kbe[a] = _series(ha, sa.youngs_modulus * sa.second_moment,
                             hb, sb.youngs_modulus * sb.second_moment)
            kto[a] = _series(ha, sa.shear_modulus * sa.polar_moment,
                             hb, sb.shear_modulus * sb.polar_moment)
    top = np.concatenate([[0.0], np.cumsum(lengths)[:-1]])
    return BodyTable(sec_of, lengths, 0.5 * lengths, top, mass, jt, jp, ro, ri, rc, kax, ksh,
                     kbe, kto, jl)


def chain_first_frequency(inertia: np.ndarray, k_joint: np.ndarray, k_top: float) -> float:
    """First natural frequency [rad/s] of a lumped chain: spring ``k_top`` to the ground above
    the first inertia, ``k_joint[k]`` between inertias k and k + 1, the last one free."""
    from scipy.linalg import eigh_tridiagonal

    n = inertia.size
    kl = np.concatenate([[k_top], k_joint])  # spring above each body
    kb = np.concatenate([k_joint, [0.0]])  # spring below
    d = (kl + kb) / inertia
    e = -k_joint / np.sqrt(inertia[:-1] * inertia[1:])
    lam = eigh_tridiagonal(d, e, select="i", select_range=(0, 0), eigvals_only=True)
    return math.sqrt(max(float(lam[0]), 0.0)) if n else math.nan


def joint_dampers(beta: float, k: np.ndarray, w2: np.ndarray, max_rate: float) -> np.ndarray:
    """Joint damper coefficients ``c = beta_j k`` [N s/m or N m s/rad] per joint.

    ``beta_j = min(beta, max_rate / w_j^2)`` with ``w_j^2`` (``w2`` [rad^2/s^2]) the joint's
    highest local frequency squared (:func:`local_frequencies`): a stiffness-proportional damper
    makes a mode of frequency ``w`` decay at ``~beta w^2`` once overdamped, so short stiff
    segments (``w ~ 1/dx``) would set the explicit time step through their damping alone; the
    cap keeps that rate below ``max_rate``. ``max_rate = inf``: ``c = beta k`` (no cap).
    """
    if math.isinf(max_rate):
        return beta * k
    cap = np.divide(max_rate, w2, out=np.full(w2.shape, math.inf), where=w2 > 0.0)
    return np.minimum(beta, cap) * k


def local_frequencies(tab: BodyTable) -> dict[str, np.ndarray]:
    """Squared highest local frequency [rad^2/s^2] of every joint spring (shape (n - 1,)).

    ``4 k / I`` with the smaller neighbour's inertia: mass for the axial spring, polar inertia
    for torsion, transverse inertia for bending; the shear spring also turns its neighbours
    about their mass centres at the arm h (``4 k max(1/m, h^2 / J_t)``).
    """
    m = np.minimum(tab.mass[:-1], tab.mass[1:])
    rot = np.maximum(tab.half[:-1] ** 2 / tab.j_transverse[:-1],
                     tab.half[1:] ** 2 / tab.j_transverse[1:])
    return {
        "axial": 4.0 * tab.k_axial / m,
        "shear": 4.0 * tab.k_shear * np.maximum(1.0 / m, rot),
        "bend": 4.0 * tab.k_bend / np.minimum(tab.j_transverse[:-1], tab.j_transverse[1:]),
        "tors": 4.0 * tab.k_tors / np.minimum(tab.j_polar[:-1], tab.j_polar[1:]),
    }


def max_joint_frequency(tab: BodyTable) -> float:
    """Highest local undamped joint frequency [rad/s] of the string (the automatic
    ``damping.max_joint_rate``): the largest of :func:`local_frequencies`."""
    if tab.n < 2:
        return 0.0
    return float(math.sqrt(max(float(w.max()) for w in local_frequencies(tab).values())))


def body_fluid(params: PlantParams, tab: BodyTable, hole_diameter: np.ndarray
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Per body: buoyancy factor [1], lateral added mass [kg], linear drag [N s/m] and
    quadratic drag [N s^2/m^2] (:mod:`plant.fluid`); ``hole_diameter`` [m] per body (nan: none).
    """
    secs = string_sections(params)
    fluid = params.fluid
    n = tab.n
    buoy = np.ones(n)
    madd = np.zeros(n)
    clin = np.zeros(n)
    cq = np.zeros(n)
    if not fluid.enabled:
        return buoy, madd, clin, cq
    for k in range(n):
        s = secs[tab.section[k]]
        buoy[k] = fl.buoyancy_factor(fluid, s.density)
        madd[k] = fl.lateral_added_mass(fluid, s, tab.length[k], hole_diameter[k])
        clin[k], cq[k] = fl.drag_coefficients(fluid, s, tab.length[k])
    return buoy, madd, clin, cq
