"""Modal analysis of a :class:`DrillstringModel` (static equilibrium: :mod:`.equilibrium`).

Modes are the eigenpairs of the finite-difference Jacobian of the right-hand side at a static
equilibrium (gravity and weight-on-bit prestress included, so axial load stiffens or softens the
lateral modes). A mode is classified axial, torsional or lateral by where its kinetic energy
sits: m v_z^2 (axial), J_p w_z^2 (torsional), m (v_x^2 + v_y^2) + J_t (w_x^2 + w_y^2) (lateral).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from drillcosim.plant.model import DrillstringModel

from .equilibrium import static_equilibrium
from .linearize import inertial_lateral_eigenvalue, linearize

__all__ = ["Mode", "static_equilibrium", "modes", "first_modes", "analytic_reference"]

KINDS = ("axial", "torsional", "lateral")


@dataclass(frozen=True)
class Mode:
    """One vibration mode.

    Attributes
    ----------
    kind : str
        "axial", "torsional" or "lateral".
    frequency_rad_s : float
        Undamped natural frequency |lambda| [rad/s].
    damping_ratio : float
        -Re(lambda) / |lambda| [1].
    energy_share : float
        Fraction of the kinetic energy in the mode's kind [1].
    """

    kind: str
    frequency_rad_s: float
    damping_ratio: float
    energy_share: float


def _energy_shares(model: DrillstringModel, vec: np.ndarray) -> np.ndarray:
    tab = model.bodies
    m, jp, jt = tab.mass, tab.j_polar, tab.j_transverse
    n = model.n
    if model.kind == "full3d":
        v = np.abs(vec[6 * n: 9 * n]).reshape(n, 3) ** 2
        w = np.abs(vec[9 * n: 12 * n]).reshape(n, 3) ** 2
        ax = (m * v[:, 2]).sum()
        to = (jp * w[:, 2]).sum()
        la = (m * (v[:, 0] + v[:, 1])).sum() + (jt * (w[:, 0] + w[:, 1])).sum()
    else:
        ax = (m * np.abs(vec[2 * n: 3 * n]) ** 2).sum()
        to = (jp * np.abs(vec[3 * n: 4 * n]) ** 2).sum()
        la = 0.0
    e = np.array([ax, to, la])
    return e / max(e.sum(), 1e-300)


def modes(model: DrillstringModel, y: np.ndarray | None = None, t: float = 0.0) -> list[Mode]:
    """All oscillatory modes at state ``y`` (default: the static equilibrium), ascending.

    Overdamped (real) eigenvalues and rigid-body (zero) eigenvalues are left out.
    """
    if y is None:
        y = static_equilibrium(model, t=t)
    J = model.jacobian(t, y)
    lam, vecs = np.linalg.eig(J)
    out = []
    lam_max = np.max(np.abs(lam))
    for i in np.flatnonzero(lam.imag > 1e-9 * lam_max):
        mag = abs(lam[i])
        if mag < 1e-9 * lam_max:
            continue
        share = _energy_shares(model, vecs[:, i])
        k = int(np.argmax(share))
        out.append(Mode(KINDS[k], float(mag), float(-lam[i].real / mag), float(share[k])))
    out.sort(key=lambda m: m.frequency_rad_s)
    return out


def first_modes(model: DrillstringModel, y: np.ndarray | None = None) -> dict[str, Mode]:
    """The lowest mode of each kind the model has (``lateral`` only for the 3D model)."""
    res: dict[str, Mode] = {}
    for md in modes(model, y):
        res.setdefault(md.kind, md)
    return res


def operating_modes(params, kind: str = "full3d", spin: float | None = None) -> list[Mode]:
    """Modes about the operating point: the straight string spinning with the top drive.

    Linearized in the top-drive frame (:mod:`analysis.linearize`); lateral eigenvalues are shifted
    back to the inertial frame by their whirl direction, so that frequencies are the ones an
    observer at rest sees. With zero spin this equals :func:`modes` at the unforced equilibrium.
    """
    lm = linearize(params, kind, spin)
    lam, vecs = np.linalg.eig(lm.A)
    lam_max = np.max(np.abs(lam))
    out = []
    for i in range(lam.size):
        share = _energy_shares(lm.model, vecs[:, i])
        k = int(np.argmax(share))
        mu = lam[i]
        if KINDS[k] == "lateral" and lm.spin != 0.0:
            mu = inertial_lateral_eigenvalue(lm, lam[i], vecs[:, i])
        elif mu.imag <= 0.0:
            continue
        mag = abs(mu)
        if mu.imag <= 1e-9 * lam_max or mag < 1e-9 * lam_max:
            continue
        out.append(Mode(KINDS[k], float(mag), float(-mu.real / mag), float(share[k])))
    # each lateral pair was seen twice (lambda and its conjugate map to the same mu)
    uniq: list[Mode] = []
    for md in sorted(out, key=lambda m: (m.kind, m.frequency_rad_s)):
        if uniq and uniq[-1].kind == md.kind and abs(uniq[-1].frequency_rad_s
                                                     - md.frequency_rad_s) < 1e-9 * lam_max:
            continue
        uniq.append(md)
    uniq.sort(key=lambda m: m.frequency_rad_s)
    return uniq


def analytic_reference(model: DrillstringModel) -> dict[str, float]:
    """Continuous-beam reference frequencies [rad/s] for the model's layout.

    axial / torsional: fixed-free rod (2k-1) pi c / (2L) with k = 1 (axial: fixed-fixed pi c / L
    when the bit is axially held by its spring); lateral: first mode of the pinned multi-span
    Euler-Bernoulli beam over the top pin and the stabilizers without axial load (FE solution,
    which equals (pi/L)^2 sqrt(EI/rho A) for one span).
    """
    d = model.derived
    pipe = model.params.pipe
    held = model.params.bit.axial_stiffness > 0.0  # bit axially held: fixed-fixed rod
    return {
        "axial": math.pi * pipe.axial_wave_speed / pipe.length if held else d.w_axial_ref,
        "torsional": d.w_tors_ref,
        "lateral": d.w_lateral_ref if model.kind == "full3d" else math.nan,
    }


# The paper's Table 1 (first natural frequency [rad/s] calculated / measured, damping ratio).
PAPER_TABLE1 = {
    "axial": {"calculated": 101.0, "measured": 102.4, "damping_ratio": 0.015},
    "torsional": {"calculated": 63.0, "measured": 64.1, "damping_ratio": 0.034},
    "lateral": {"calculated": 0.53, "measured": 0.63, "damping_ratio": 0.40},
}
