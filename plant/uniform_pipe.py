"""The uniform pipe's per-segment quantities (SI) and its lateral reference frequency.

A string of one uniform pipe (no ``[[sections]]``) is built from these: segment mass and
inertias, joint stiffnesses, and the damping factors that make the axial, torsional and lateral
damping ratios of the scene at the reference frequencies (the first fixed-free rod modes; the
first bending mode of the pinned multi-span beam between the top and the stabilizers).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache

from .beam_fe import pinned_beam_frequencies
from .blas import threadpool_limits
from .params import PlantParams

__all__ = ["Derived", "derive", "lateral_reference_frequency"]


@dataclass(frozen=True)
class Derived:
    """Derived per-segment quantities (SI)."""

    dx: float  # [m]
    mass: float  # [kg]
    j_transverse: float  # [kg m^2]
    j_polar: float  # [kg m^2]
    k_axial: float  # [N/m]
    k_shear: float  # [N/m]
    k_bend: float  # [N m/rad]
    k_tors: float  # [N m/rad]
    beta_axial: float  # [s]
    beta_tors: float  # [s]
    beta_bend: float  # [s] bending joint dampers
    alpha_lateral: float  # [1/s] lateral drag
    w_axial_ref: float  # [rad/s] first fixed-free axial rod frequency
    w_tors_ref: float  # [rad/s]
    w_lateral_ref: float  # [rad/s]

def derive(params: PlantParams) -> Derived:
    """Compute segment masses, inertias, joint stiffnesses and damping factors."""
    pipe = params.pipe
    dx = pipe.segment_length
    A = pipe.area
    I = pipe.second_moment
    rho = pipe.density
    ro = pipe.outer_diameter / 2.0
    ri = pipe.inner_diameter / 2.0
    mass = rho * A * dx
    j_polar = 0.5 * mass * (ro**2 + ri**2)
    j_trans = mass * (3.0 * (ro**2 + ri**2) + dx**2) / 12.0
    E = pipe.youngs_modulus
    G = pipe.shear_modulus
    w_ax = math.pi * pipe.axial_wave_speed / (2.0 * pipe.length)
    w_to = math.pi * pipe.torsional_wave_speed / (2.0 * pipe.length)
    d = params.damping
    if d.lateral_reference_frequency > 0.0:
        w_lat = d.lateral_reference_frequency
    else:
        w_lat = lateral_reference_frequency(params)
    return Derived(
        dx=dx,
        mass=mass,
        j_transverse=j_trans,
        j_polar=j_polar,
        k_axial=E * A / dx,
        k_shear=pipe.kappa * G * A / dx,
        k_bend=E * I / dx,
        k_tors=G * pipe.polar_moment / dx,
        beta_axial=2.0 * d.axial_ratio / w_ax,
        beta_tors=2.0 * d.torsional_ratio / w_to,
        beta_bend=(2.0 * d.lateral_ratio / w_lat if d.lateral_model == "joint"
                   else 2.0 * d.axial_ratio / w_ax),
        alpha_lateral=2.0 * d.lateral_ratio * w_lat if d.lateral_model == "drag" else 0.0,
        w_axial_ref=w_ax,
        w_tors_ref=w_to,
        w_lateral_ref=w_lat,
    )

@lru_cache(maxsize=64)
def lateral_reference_frequency(params: PlantParams) -> float:
    """First bending frequency [rad/s] of the pinned multi-span Euler-Bernoulli beam.

    Supports: the top (when its lateral spring is > 0) and every stabilizer. With fewer than two
    supports the string has no pinned span; the first fixed-free axial frequency is returned as a
    harmless placeholder (the lateral damping then acts at that rate).
    """
    pipe = params.pipe
    Lp = pipe.length
    sup = sorted({Lp - h for h in params.stabilizers.heights})
    if params.top_drive.lateral_stiffness > 0.0:
        sup = sorted({0.0, *sup})
    if len(sup) < 2 or params.stabilizers.stiffness == 0.0:
        return math.pi * pipe.axial_wave_speed / (2.0 * Lp)
    ei = pipe.youngs_modulus * pipe.second_moment
    rho_a = pipe.density * pipe.area
    with threadpool_limits(1):  # small dense problems: one BLAS thread is fastest
        return float(pinned_beam_frequencies(Lp, sup, ei, rho_a, n_elements=48, count=1)[0])
