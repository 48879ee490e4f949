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

__all__ = ["TwoDof", "bit_torque", "sampled_loop_growth", "two_dof"]


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


def sampled_loop_growth(plant, controller: dict, p_gain: float, delay: float, step: float
                        ) -> float:
    """Growth rate [1/s] of the linearized two-DOF loop about steady rotation at the target
    speed, sampled as the co-simulation runs it.

    The plant (states alpha, theta, Omega, omega; the bit torque replaced by its slope at the
    target speed) is discretized exactly over ``step`` with the motor torque held (ZOH); the PI
    law is the sampled one of ``controller/top_drive.py`` (``x += step e``,
    ``T_m = P e + I x + k_T T_s``); the torque reaches the plant one step later (Jacobi) plus
    ``delay / step`` steps (the actuator delay, a whole number of steps). The rigid rotation
    (eigenvalue 1) is left out; ``ln(max |eigenvalue|) / step``.
    """
    import scipy.linalg

    m = two_dof(plant)
    minv = np.linalg.inv(m.mass)
    om, d = controller["target_speed"], 1e-6
    weight = plant.bit.weight_on_bit
    slope = (bit_torque(plant.bit, om + d, weight) - bit_torque(plant.bit, om - d, weight)) / (2 * d)
    ts = np.array([m.k, -m.k, m.c, -m.c])
    a = np.vstack([[0, 0, 1, 0], [0, 0, 0, 1],
                   minv @ np.vstack([-ts, ts - np.array([0, 0, 0, slope])])])
    b = np.concatenate([[0, 0], minv @ np.array([1.0, 0.0])])
    aug = np.zeros((5, 5))
    aug[:4, :4], aug[:4, 4] = a * step, b * step
    e = scipy.linalg.expm(aug)
    nd = round(delay / step)
    n = 6 + nd          # z (4), x, outputs q_0 (newest) .. q_nd (applied)
    mat = np.zeros((n, n))
    mat[:4, :4], mat[:4, 5 + nd] = e[:4, :4], e[:4, 4]
    mat[4, 4], mat[4, 2] = 1.0, -step                       # x += step e, e = -Omega
    i_gain = controller["i_gain"]
    mat[5, 2] = -p_gain - i_gain * step
    mat[5, 4] = i_gain
    mat[5, :4] += controller["torque_feedback"] * ts
    for j in range(1, nd + 1):
        mat[5 + j, 4 + j] = 1.0
    ev = np.linalg.eigvals(mat)
    ev = ev[np.abs(ev - 1.0) > 1e-9]
    return float(np.log(np.abs(ev).max()) / step)
