"""Low-order torsional references written from the formulas of docs/physics.md (not from the
plant code): the cutting bit's torque law and a two-degree-of-freedom model of a string between
a top-drive rotor and the bit, with a PI speed controller on the rotor.

Two-DOF model (Rayleigh-Ritz): the bodies of the string turn by ``alpha + phi_k (theta -
alpha)``, ``phi_k = (k + 1/2) / (n - 1/2)`` (the static twist shape between the drive angle
alpha and the bit angle theta: half a segment from the drive to body 1). Mass matrix
``j_seg [[sum (1 - phi)^2, sum phi (1 - phi)], [., sum phi^2]]`` plus the rotor inertia J_td on
the drive and the bottom-hole assembly on the bit; stiffness k = G J_p / (L - dx/2); the
stiffness-proportional joint damping c = beta k (beta = 2 zeta_t / w_t, w_t the first
fixed-free rod frequency). The top torque (what the drive applies to the string) is
``T_s = k (alpha - theta) + c (Omega - omega)``; the rotor: ``J_td dOmega/dt = T_m - T_s``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

__all__ = ["TwoDof", "bit_torque", "two_dof"]


def bit_torque(bit, w: float, weight: float) -> float:
    """T(omega) [N m] at weight on bit ``weight`` [N] (docs/physics.md, section 4)."""
    wf = min(weight, bit.wearflat_force)
    wc = weight - wf
    mu = bit.friction_coefficient * (1 + (bit.static_friction_ratio - 1)
                                     * math.exp(-abs(w) / bit.weakening_speed))
    return 0.5 * bit.radius * (wc / bit.cutting_force_ratio + mu * wf) \
        * math.tanh(w / bit.slip_speed)


@dataclass(frozen=True)
class TwoDof:
    """Mass matrix M (2, 2) [kg m^2] (drive, bit), stiffness k [N m/rad], damping c [N m s/rad]."""

    mass: np.ndarray
    k: float
    c: float


def two_dof(plant) -> TwoDof:
    """The two-DOF model of ``plant`` (a :class:`plant.params.PlantParams` with a top drive in
    mode "torque")."""
    pipe = plant.pipe
    n, dx = pipe.n_segments, pipe.segment_length
    gj = pipe.shear_modulus * pipe.polar_moment
    ro, ri = pipe.outer_diameter / 2, pipe.inner_diameter / 2
    j_seg = 0.5 * pipe.density * pipe.area * dx * (ro**2 + ri**2)
    phi = (np.arange(n) + 0.5) / (n - 0.5)
    cross = float(np.sum(phi * (1 - phi)))
    mass = j_seg * np.array([[float(np.sum((1 - phi) ** 2)), cross],
                             [cross, float(np.sum(phi**2))]])
    mass[0, 0] += plant.top_drive.inertia
    mass[1, 1] += plant.bit.inertia
    k = gj / ((n - 0.5) * dx)
    beta = 2 * plant.damping.torsional_ratio / (math.pi * pipe.torsional_wave_speed
                                                 / (2 * pipe.length))
    return TwoDof(mass, k, beta * k)
