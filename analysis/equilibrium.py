"""Static equilibrium of a :class:`DrillstringModel`: the configuration at rest with zero
acceleration (the point the linearization and the modal analysis start from)."""

from __future__ import annotations

import numpy as np

from drillcosim.plant.model import DrillstringModel

__all__ = ["static_equilibrium"]


def static_equilibrium(model: DrillstringModel, y0: np.ndarray | None = None, t: float = 0.0,
                       tol: float = 1e-6, max_iter: int = 20) -> np.ndarray:
    """Configuration with zero acceleration at rest (Newton on the accelerations).

    Parameters
    ----------
    model : DrillstringModel
    y0 : numpy.ndarray, shape (n_state,), optional
        Starting guess (default: the model's initial state).
    t : float
        Time [s] at which loads are evaluated.

    Returns
    -------
    numpy.ndarray, shape (n_state,)
        State with zero velocities whose accelerations are below ``tol`` [m/s^2, rad/s^2], or
        where Newton's update has fallen to round-off (1e-13 of the configuration).

    Raises
    ------
    RuntimeError
        If Newton does not converge (e.g. a mechanism: a string with no support).
    """
    if model.n_state != model.n_body_state:
        raise ValueError(f"static_equilibrium: the model has the auxiliary states "
                         f"{model.aux_names}; use top_drive.mode = 'prescribed'")
    y = model.initial_state() if y0 is None else y0.copy()
    nq = model.n_state // 2
    size = max(1.0, float(np.max(np.abs(y[:nq]))))
    for _ in range(max_iter):
        y[nq:] = 0.0
        acc = model.rhs(t, y)[nq:]
        if np.max(np.abs(acc)) < tol:
            return y
        J = model.jacobian(t, y)[nq:, :nq]
        dq = np.linalg.lstsq(J, -acc, rcond=None)[0]
        y[:nq] += dq
        if np.max(np.abs(dq)) < 1e-13 * size:
            return y
    raise RuntimeError(
        f"static equilibrium did not converge: max acceleration {np.max(np.abs(acc)):.3g} m/s^2"
    )
