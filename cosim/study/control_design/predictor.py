"""The sampled Smith predictor around the strain P law: a known delay compensated.

The P law ``G_k = K s_k`` (``K = gain * kron(M, I_2)``: per gauge axis, relative gains ``M``
across the sites; ``M = I``: the paper's one law per channel) sees, instead of the measured
strains alone, the strains plus the model's prediction of what the delay still hides::

    G_k = K (s_k + C e_k),   e_{k+1} = Ad e_k + Bd sum_l (W0_l - W_l) G_{k-l}

``W`` the loop's weights with the actuator delay (:meth:`.plant_model.LoopPlant.weights`),
``W0`` without (the loop's own timing); ``e`` is the difference of the plant model driven
without and with the delay. On the design plant the loop then behaves as the P law without
delay: its eigenvalues are those of the undelayed P loop, the model's (``Ad``: the open-loop
plant, stable) and zeros of the delay line. The controller's state is ``[e, G_{k-1}, ...,
G_{k-D}]``. The classic limits hold: it needs a stable plant, and it compensates the
nominal delay of the nominal plant only.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from drillcosim.cosim.master.errors import UserError

from .plant_model import LoopPlant

__all__ = ["gain_matrix", "predictor_matrices"]


def gain_matrix(gain: float, n_sites: int, relative: Sequence[Sequence[float]] | None = None
                ) -> np.ndarray:
    """``gain * kron(M, I_2)`` [N/strain], channels site by site, gauge C then E."""
    m = np.eye(n_sites) if relative is None else np.asarray(relative, dtype=float)
    if m.shape != (n_sites, n_sites):
        raise UserError(f"gain_matrix is {m.shape}; allowed: {n_sites} x {n_sites}")
    return float(gain) * np.kron(m, np.eye(2))


def predictor_matrices(plant: LoopPlant, step: float, delay: float, K: np.ndarray
                       ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """``(Ac, Bc, Cc, Dc)`` of the Smith predictor (module docstring)."""
    from drillcosim.cosim.study.stability import loop_weights

    Ad, Bd = plant.discrete(step)
    w = plant.weights(delay, step)
    w0 = loop_weights(0.0, 0.0, plant.algorithm, plant.order, plant.coupling)
    dw = {j: w0.get(j, 0.0) - w.get(j, 0.0) for j in set(w) | set(w0)}
    n, m = Bd.shape
    d = max([j for j, v in dw.items() if v != 0.0] + [0])
    if not any(dw.values()):        # nothing to compensate: the P law itself
        return np.zeros((0, 0)), np.zeros((0, K.shape[1])), np.zeros((m, 0)), np.array(K, float)
    nc = n + d * m
    Ac = np.zeros((nc, nc))
    Bc = np.zeros((nc, K.shape[1]))
    Cc = np.zeros((m, nc))
    Cc[:, :n] = K @ plant.C
    Dc = np.array(K, dtype=float)
    Ac[:n, :n] = Ad + dw.get(0, 0.0) * Bd @ Cc[:, :n]
    Bc[:n] = dw.get(0, 0.0) * Bd @ Dc
    for j in range(1, d + 1):
        Ac[:n, n + (j - 1) * m:n + j * m] = dw.get(j, 0.0) * Bd
    if d:
        Ac[n:n + m] = Cc            # G_k into slot 1
        Bc[n:n + m] = Dc
        for j in range(1, d):
            Ac[n + j * m:n + (j + 1) * m, n + (j - 1) * m:n + j * m] = np.eye(m)
    return Ac, Bc, Cc, Dc
