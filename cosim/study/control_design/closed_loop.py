"""The sampled closed loop of a linearized plant and a discrete state-space controller.

With the plant and its delay line ``z_k = [x_k, G_{k-1}, ..., G_{k-D}]``
(:func:`.plant_model.augment`), strains ``s_k = C x_k`` and the controller of
:mod:`controller.state_space` (``G_k = Cc xc_k + Dc s_k``, ``xc_{k+1} = Ac xc_k + Bc s_k``; its
sample period is the communication step)::

    [z_{k+1} ]   [Az + Bz Dc Cz   Bz Cc] [z_k ]
    [xc_{k+1}] = [Bc Cz           Ac   ] [xc_k]

Stable iff the spectral radius is < 1 (with the modes no channel sees, which feedback leaves
where they are); ``ln(rho) / H`` is the growth rate [1/s]. Saturation is not modelled (linear).
For the P law (``Dc = K I``, no state) this is :meth:`cosim.study.stability.LoopModel.matrix`.
"""

from __future__ import annotations

import math

import numpy as np

from drillcosim.controller.state_space import StateSpaceParams
from drillcosim.cosim.study.stability import spectral_radius

from .plant_model import LoopPlant, augment

__all__ = ["closed_loop_matrix", "growth_rate", "loop_spectral_radius"]


def closed_loop_matrix(plant: LoopPlant, controller: StateSpaceParams, delay: float
                       ) -> np.ndarray:
    """Matrix of the closed loop at actuator delay ``delay`` [s] (step = the controller's
    sample period).

    Raises
    ------
    ValueError
        If the controller's inputs/outputs are not the plant's strains/forces (names, order).
    """
    strains, forces = plant.signals
    if controller.input_names != strains or controller.output_names != forces:
        raise ValueError(f"the controller's inputs {list(controller.input_names)} and outputs "
                         f"{list(controller.output_names)} do not fit the plant: allowed inputs "
                         f"{list(strains)}, outputs {list(forces)}")
    step = controller.sample_period
    Ad, Bd = plant.discrete(step)
    Az, Bz = augment(Ad, Bd, plant.weights(delay, step))
    nz, nc = Az.shape[0], controller.n_states
    Cz = np.zeros((plant.C.shape[0], nz))
    Cz[:, :plant.A.shape[0]] = plant.C
    Ac, Bc, Cc, Dc = controller.A, controller.B, controller.C, controller.D
    T = np.empty((nz + nc, nz + nc))
    T[:nz, :nz] = Az + Bz @ Dc @ Cz
    T[:nz, nz:] = Bz @ Cc
    T[nz:, :nz] = Bc @ Cz
    T[nz:, nz:] = Ac
    return T


def loop_spectral_radius(plant: LoopPlant, controller: StateSpaceParams, delay: float) -> float:
    """Spectral radius of :func:`closed_loop_matrix`, the dropped modes included."""
    rho = spectral_radius(closed_loop_matrix(plant, controller, delay))
    if plant.dropped.size:
        rho = max(rho, float(np.max(np.abs(np.exp(plant.dropped * controller.sample_period)))))
    return rho


def growth_rate(plant: LoopPlant, controller: StateSpaceParams, delay: float) -> float:
    """``ln(rho) / H`` [1/s] of the closed loop: > 0 unstable."""
    rho = loop_spectral_radius(plant, controller, delay)
    return math.log(rho) / controller.sample_period if rho > 0 else -math.inf
