"""The linearized, sampled plant a controller is designed on and judged against.

The stability module's model (:mod:`cosim.study.stability`) with two channels more: the
plant is :func:`analysis.linearize.linearize`'s (top-drive frame, where the loop is linear
time-invariant) and is reduced by :func:`cosim.study.stability.reduce_loop` to the modes the
loop and the two extra channels see; it is sampled exactly (ZOH) over the communication step
by :func:`cosim.study.stability.discretize` and closed with the master's loop timing
(:func:`cosim.study.stability.loop_weights`). The extra channels:

* ``Cd`` (performance): the lateral displacements X', Y' of every body [m] (top-drive frame);
* ``Bw`` (disturbance): a lateral force on every body [N], in X' and Y' (the unknown loads:
  unbalance, wall contact, the bit), entering the body's velocity as F / m.

Signals (as the plant FMU names them): inputs ``actuator<s>_force_<C|E>`` [N], outputs
``strain<s>_<C|E>`` [1], site by site, gauge C then E.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import scipy.linalg

from drillcosim.cosim.study.stability import discretize, loop_weights, modal_bases, reduce_loop
from drillcosim.plant.signals import actuator_force, site_channels, strain

__all__ = ["LoopPlant", "augment", "site_signals"]


def site_signals(n_sites: int) -> tuple[tuple[str, ...], tuple[str, ...]]:
    """(strains, forces): the plant's output and input names of ``n_sites`` sites, site by
    site, gauge C then E (:mod:`plant.signals`)."""
    ch = site_channels(range(1, n_sites + 1))
    return tuple(strain(s, a) for s, a in ch), tuple(actuator_force(s, a) for s, a in ch)


@dataclass
class LoopPlant:
    """Continuous reduced plant ``dx/dt = A x + B u + Bw w``, strains ``s = C x``, lateral
    displacements ``d = Cd x``, with the loop timing of a scene.

    Attributes
    ----------
    A : numpy.ndarray, shape (N, N)  [1/s]
    B : numpy.ndarray, shape (N, M)  actuator forces [N] -> state rates
    C : numpy.ndarray, shape (M, N)  strains [1]
    Bw : numpy.ndarray, shape (N, 2 n)  lateral body forces [N] -> state rates
    Cd : numpy.ndarray, shape (2 n, N)  lateral displacements [m]
    dropped : numpy.ndarray  continuous eigenvalues [1/s] of the modes no channel sees
    joints : tuple of int  the actuator joints (sites top to bottom)
    algorithm, order, coupling, sensor_delay : the scene's loop timing (``[cosim]``)
    source : str  the scene it came from
    """

    A: np.ndarray
    B: np.ndarray
    C: np.ndarray
    Bw: np.ndarray
    Cd: np.ndarray
    dropped: np.ndarray
    joints: tuple[int, ...]
    algorithm: str = "gauss_seidel"
    order: tuple[str, ...] = ("plant", "controller")
    coupling: str = "zoh"
    sensor_delay: float = 0.0
    source: str = ""
    _cache: dict[tuple[float, bool], tuple[np.ndarray, np.ndarray]] = field(
        default_factory=dict, repr=False)

    @classmethod
    def from_scene(cls, scene: Any, joints: Sequence[int] | None = None,
                   overrides: Mapping[str, Any] | None = None) -> LoopPlant:
        """Linearize a scene's plant.

        Parameters
        ----------
        scene : str, path or SceneConfig
            A scene (name or file) or a loaded :class:`cosim.scenario.config.SceneConfig`.
        joints : sequence of int, optional
            Actuator joints (default: the scene's ``[actuators] joints``).
        overrides : mapping, optional
            Scene keys by key path (:func:`cosim.scenario.config.load_config`).

        Raises
        ------
        ConfigError
            A scene without the full3d model or without actuator sites (one line).
        """
        from drillcosim.analysis.linearize import linearize
        from drillcosim.cosim.scenario.config import ConfigError, SceneConfig, load_config

        if isinstance(scene, SceneConfig):
            if joints is not None or overrides:
                raise ValueError("joints/overrides need a scene name or path, not a "
                                 "SceneConfig")
            config = scene
        else:
            ov = dict(overrides or {})
            if joints is not None:
                ov["actuators.joints"] = [int(j) for j in joints]
            config = load_config(scene, ov)
        sc = config.scene
        if sc.model != "full3d" or not sc.plant.actuator_joints:
            raise ConfigError(f"scene {sc.name!r} (model {sc.model}, actuator joints "
                              f"{list(sc.plant.actuator_joints)}): a lateral controller needs "
                              "the full3d model with actuator sites")
        st = config.cosim
        lin = linearize(sc.plant, "full3d")
        model = lin.model
        n, N = model.n, lin.A.shape[0]
        Cd = np.zeros((2 * n, N))
        Bw = np.zeros((N, 2 * n))
        for i in range(n):
            for k in (0, 1):
                Cd[2 * i + k, 3 * i + k] = 1.0
                Bw[6 * n + 3 * i + k, 2 * i + k] = 1.0 / model.derived.mass
        m, p = lin.B.shape[1], lin.C.shape[0]
        Ar, Bx, Cx, dropped = reduce_loop(lin.A, np.hstack([lin.B, Bw]),
                                          np.vstack([lin.C, Cd]))
        return cls(Ar, Bx[:, :m], Cx[:p], Bx[:, m:], Cx[p:], dropped,
                   tuple(sc.plant.actuator_joints), st.algorithm, tuple(st.order),
                   st.coupling, st.sensor_delay, str(sc.source))

    def truncated(self, max_frequency: float) -> LoopPlant:
        """The plant with only its modes of ``|lambda| <= max_frequency`` [rad/s] (modal
        truncation, for a smaller design model; judge a design on the full plant).

        The drillstring's lateral bending modes (56 pairs for the paper's string, up to ~170
        rad/s) lie below a gap (to ~2000 rad/s, the shear modes): the default of the designs,
        :data:`.design.MAX_FREQUENCY` = 1000 rad/s, keeps them all (240 -> 112 states).

        Raises
        ------
        UserError
            No mode at or below ``max_frequency``.
        """
        from drillcosim.cosim.master.errors import UserError

        lam, V = scipy.linalg.eig(self.A)
        keep = np.abs(lam) <= max_frequency
        if keep.all():
            return self
        if not keep.any():
            raise UserError(f"max_frequency = {max_frequency!r} rad/s keeps no mode (the "
                            f"slowest is at {np.abs(lam).min():.4g} rad/s)")
        qk, qd = modal_bases(lam, V, keep)
        T = np.hstack([qk, qd])
        Ti = np.linalg.inv(T)
        r = qk.shape[1]
        return dataclasses.replace(
            self, A=(Ti @ self.A @ T)[:r, :r], B=(Ti @ self.B)[:r], C=(self.C @ T)[:, :r],
            Bw=(Ti @ self.Bw)[:r], Cd=(self.Cd @ T)[:, :r], _cache={})

    @property
    def n_sites(self) -> int:
        return self.B.shape[1] // 2

    @property
    def signals(self) -> tuple[tuple[str, ...], tuple[str, ...]]:
        """(strain names, force names), the controller's inputs and outputs."""
        return site_signals(self.n_sites)

    def discrete(self, step: float, disturbance: bool = False) -> tuple[np.ndarray, np.ndarray]:
        """``(Ad, Bd)`` over one step [s] (``Bd`` of the disturbance with ``disturbance``)."""
        key = (float(step), disturbance)
        if key not in self._cache:
            self._cache[key] = discretize(self.A, self.Bw if disturbance else self.B, step)
        return self._cache[key]

    def weights(self, delay: float, step: float) -> dict[int, float]:
        """``W_l`` of ``u_k = sum_l W_l G_{k-l}`` for actuator delay ``delay`` [s]."""
        return loop_weights(delay / step, self.sensor_delay / step, self.algorithm, self.order,
                            self.coupling)


def augment(Ad: np.ndarray, Bd: np.ndarray, weights: Mapping[int, float]
            ) -> tuple[np.ndarray, np.ndarray]:
    """The sampled plant with the controller outputs' delay line in the state.

    ``z_k = [x_k, G_{k-1}, ..., G_{k-D}]``, input ``G_k`` (the controller's output of sample
    k), ``x_{k+1} = Ad x_k + Bd sum_l W_l G_{k-l}``; as
    :func:`cosim.study.stability.closed_loop_matrix` builds it for the P law.

    Returns
    -------
    Az : numpy.ndarray, shape (N + D M, N + D M)
    Bz : numpy.ndarray, shape (N + D M, M)
    """
    n, m = Bd.shape
    d = max([j for j, w in weights.items() if w != 0.0] + [0])
    size = n + d * m
    Az = np.zeros((size, size))
    Bz = np.zeros((size, m))
    Az[:n, :n] = Ad
    Bz[:n] = weights.get(0, 0.0) * Bd
    for j in range(1, d + 1):
        Az[:n, n + (j - 1) * m:n + j * m] = weights.get(j, 0.0) * Bd
    if d:
        Bz[n:n + m] = np.eye(m)
        for j in range(1, d):
            Az[n + j * m:n + (j + 1) * m, n + (j - 1) * m:n + j * m] = np.eye(m)
    return Az, Bz
