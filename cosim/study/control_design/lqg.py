"""LQG: LQR on the sampled plant with the delay line in the state, Kalman filter on the strains.

Design model: the sampled plant with the controller outputs' delay line
(:func:`.plant_model.augment`, ``z_k = [x_k, G_{k-1}, ..., G_{k-D}]``), so the known
actuator delay (and the loop's own timing) is part of the state. MIMO across all sites and
both gauge axes: every force sees every strain (the paper's "coupling between the orthogonal
modes").

* **LQR** (``control.dlqr``): ``G_k = -K z_k`` minimizing
  ``sum_k |Cd x_k|^2 / d0^2 + |G_k|^2 / F0^2``: the lateral displacements of all bodies
  against the actuator forces (Bryson's scaling: ``d0`` = deflection scale [m], ``F0`` = force
  scale [N]).
* **Kalman filter** (``control.dlqe``, current-estimator form): process noise = a lateral
  force on every body, held over a step, standard deviation ``force_noise`` [N] per axis;
  measurement noise = ``strain_noise`` [1] per gauge. The delay-line states carry no noise
  (the controller knows its own past outputs).

Controller (input: the strains ``s_k``, output ``G_k``; state: the predicted estimate
``xc_k = z_{k|k-1}``)::

    z_{k|k}  = xc_k + M (s_k - Cz xc_k),    M = P Cz' (Cz P Cz' + V)^-1
    G_k      = -K z_{k|k}
    xc_{k+1} = Az z_{k|k} + Bz G_k

i.e. ``Ac = (Az - Bz K)(I - M Cz)``, ``Bc = (Az - Bz K) M``, ``Cc = -K (I - M Cz)``,
``Dc = -K M``. By the separation principle the closed loop on the design plant has the
eigenvalues of ``Az - Bz K`` and of ``Az - L Cz`` (``L = Az M``, dlqe's gain).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from drillcosim.cosim.master.errors import UserError

from .plant_model import LoopPlant, augment

__all__ = ["LqgGains", "LqgWeights", "lqg_gains", "lqg_matrices"]


@dataclass(frozen=True)
class LqgWeights:
    """Weights of the LQG design (all > 0, finite).

    Attributes
    ----------
    deflection_scale : float
        d0 [m]: a lateral displacement of d0 at every body costs as much as ...
    force_scale : float
        F0 [N]: ... a force of F0 at every actuator channel.
    force_noise : float
        Standard deviation of the unknown lateral force on each body, per axis, held over a
        step [N].
    strain_noise : float
        Standard deviation of the strain measurement noise [1].
    """

    deflection_scale: float = 1e-3
    force_scale: float = 1e4
    force_noise: float = 1.0
    strain_noise: float = 1e-7

    def __post_init__(self) -> None:
        for name in ("deflection_scale", "force_scale", "force_noise", "strain_noise"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not (
                    math.isfinite(v) and v > 0):
                raise UserError(f"{name} = {v!r}; allowed: a finite number > 0")


@dataclass(frozen=True)
class LqgGains:
    """The pieces of an LQG design (shapes with Nz = N + D M states, M forces, P strains)."""

    Az: np.ndarray      # (Nz, Nz)
    Bz: np.ndarray      # (Nz, M)
    Cz: np.ndarray      # (P, Nz)
    Q: np.ndarray       # (Nz, Nz) state weight
    R: np.ndarray       # (M, M) force weight
    K: np.ndarray       # (M, Nz) LQR gain
    S: np.ndarray       # (Nz, Nz) DARE solution of the regulator
    E_lqr: np.ndarray   # eigenvalues of Az - Bz K
    Gz: np.ndarray      # (Nz, 2 n) disturbance input
    W: np.ndarray       # process noise covariance
    V: np.ndarray       # measurement noise covariance
    L: np.ndarray       # (Nz, P) predictor-form Kalman gain (dlqe)
    P: np.ndarray       # (Nz, Nz) prior error covariance (filter DARE)
    E_kf: np.ndarray    # eigenvalues of Az - L Cz
    M: np.ndarray       # (Nz, P) current-estimator gain


def lqg_gains(plant: LoopPlant, step: float, delay: float, weights: LqgWeights) -> LqgGains:
    """LQR and Kalman gains of the augmented sampled plant (module docstring)."""
    import control

    Ad, Bd = plant.discrete(step)
    _, Bwd = plant.discrete(step, disturbance=True)
    Az, Bz = augment(Ad, Bd, plant.weights(delay, step))
    n, nz, m = Ad.shape[0], Az.shape[0], Bd.shape[1]
    Cz = np.zeros((plant.C.shape[0], nz))
    Cz[:, :n] = plant.C
    Q = np.zeros((nz, nz))
    Q[:n, :n] = plant.Cd.T @ plant.Cd / weights.deflection_scale ** 2
    R = np.eye(m) / weights.force_scale ** 2
    try:
        K, S, E_lqr = control.dlqr(Az, Bz, Q, R)
    except np.linalg.LinAlgError as exc:
        raise UserError(f"LQR on joints {list(plant.joints)} (delay {delay:g} s, step {step:g} s):"
                        f" no stabilizing solution of the Riccati equation ({exc}): the plant is "
                        "not stabilizable from these sites; choose other joints") from None
    Gz = np.zeros((nz, Bwd.shape[1]))
    Gz[:n] = Bwd
    W = weights.force_noise ** 2 * np.eye(Gz.shape[1])
    V = weights.strain_noise ** 2 * np.eye(Cz.shape[0])
    try:
        L, P, E_kf = control.dlqe(Az, Gz, Cz, W, V)
    except np.linalg.LinAlgError as exc:
        raise UserError(f"Kalman filter on joints {list(plant.joints)} (step {step:g} s): no "
                        f"stabilizing solution of the filter Riccati equation ({exc}): the plant "
                        "is not detectable from these strain gauges; choose other joints") from None
    M = P @ Cz.T @ np.linalg.inv(Cz @ P @ Cz.T + V)
    return LqgGains(Az, Bz, Cz, Q, R, np.asarray(K), np.asarray(S), np.asarray(E_lqr), Gz, W,
                    V, np.asarray(L), np.asarray(P), np.asarray(E_kf), M)


def lqg_matrices(g: LqgGains) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """``(Ac, Bc, Cc, Dc)`` of the controller (module docstring)."""
    eye = np.eye(g.Az.shape[0])
    closed = g.Az - g.Bz @ g.K
    filt = eye - g.M @ g.Cz
    return closed @ filt, closed @ g.M, -g.K @ filt, -g.K @ g.M
