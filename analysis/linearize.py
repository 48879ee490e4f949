"""Linear state-space model of a spinning drillstring about its operating point.

With the top drive turning at a constant speed Omega, the straight string spinning with it is a
steady motion but not an equilibrium in our coordinates (inertial positions, spin angle psi grows).
For an axisymmetric string the equations are time-invariant in the frame that rotates with the
top drive: positions and velocities rotated by -alpha(t) (alpha the top-drive angle), spin angle
psi' = psi - alpha. Strain gauges and actuators are body-fixed, so the whole loop (plant, gauges,
controller, actuators) is linear time-invariant there: this is what a sampled-data stability
prediction needs. With Omega = 0 the frame is the inertial one.

    d/dt x' = A x' + B u,   strains = C x'

``x'`` has the model's state layout. Lateral eigenvalues seen in the rotating frame are shifted
by +-i Omega with respect to the inertial ones (forward / backward whirl);
:func:`inertial_lateral_eigenvalue` undoes that shift.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from drillcosim.plant.kernels import top_drive
from drillcosim.plant.layout import OMEGA0, T_RAMP
from drillcosim.plant.model import DrillstringModel
from drillcosim.plant.params import PlantParams
from drillcosim.plant.signals import site_channels, strain

from .equilibrium import static_equilibrium

__all__ = ["LinearModel", "operating_params", "linearize", "inertial_lateral_eigenvalue"]


@dataclass(frozen=True)
class LinearModel:
    """Linearization ``dx'/dt = A x' + B u``, ``y = C x'`` in the top-drive frame.

    Attributes
    ----------
    A : numpy.ndarray, shape (N, N)  [1/s]
    B : numpy.ndarray, shape (N, 2 n_sites)  [state units per N per s]
    C : numpy.ndarray, shape (2 n_sites, N)  strains (site 1 C, site 1 E, ...) per state unit
    x_op : numpy.ndarray, shape (N,)  operating point in the inertial layout at ``time``
    time : float  [s]
    spin : float  top-drive speed Omega [rad/s]
    model : DrillstringModel
    """

    A: np.ndarray
    B: np.ndarray
    C: np.ndarray
    x_op: np.ndarray
    time: float
    spin: float
    model: DrillstringModel


def operating_params(params: PlantParams) -> PlantParams:
    """The parameters with forcing removed: no bit displacement, no unbalance, no loads.

    Forcing terms do not enter a linearization; removing them makes the straight spinning string
    a steady motion. A top drive driven by an input (``top_drive.mode`` "speed" or "torque") is
    replaced by the prescribed steady speed ``top_drive.rotary_speed``, and a cutting bit by the
    spring to a fixed rock (``bit.model`` "prescribed"; a drilling bit has no equilibrium): the
    linearization is about a rigidly driven string on a fixed bottom.
    """
    return replace(
        params,
        top_drive=replace(params.top_drive, mode="prescribed", inertia=0.0),
        bit=replace(params.bit, displacement_amplitude=0.0, model="prescribed"),
        unbalance=replace(params.unbalance, enabled=False),
        loads=(),
    )


def _to_inertial(model: DrillstringModel, xr: np.ndarray, alpha: float) -> np.ndarray:
    y = xr.copy()
    n = model.n
    if model.kind == "full3d":
        c, s = math.cos(alpha), math.sin(alpha)
        for off in (0, 6 * n):
            X = xr[off:off + 3 * n:3]
            Y = xr[off + 1:off + 3 * n:3]
            y[off:off + 3 * n:3] = c * X - s * Y
            y[off + 1:off + 3 * n:3] = s * X + c * Y
        y[3 * n:6 * n:3] += alpha
    else:
        y[n:2 * n] += alpha
    return y


def _rotating_rhs(model: DrillstringModel, t: float, xr: np.ndarray,
                  u: np.ndarray) -> np.ndarray:
    """d/dt of the rotating-frame state x' (see the module docstring)."""
    alpha, om = top_drive(t, model.p[OMEGA0], model.p[T_RAMP])
    y = _to_inertial(model, xr, alpha)
    f = model.rhs(t, y, u)
    g = f.copy()
    n = model.n
    if model.kind == "full3d":
        c, s = math.cos(alpha), math.sin(alpha)
        for off in (0, 6 * n):
            fx = f[off:off + 3 * n:3]
            fy = f[off + 1:off + 3 * n:3]
            # R(-alpha) f  - Omega e_z x (x')
            g[off:off + 3 * n:3] = c * fx + s * fy + om * xr[off + 1:off + 3 * n:3]
            g[off + 1:off + 3 * n:3] = -s * fx + c * fy - om * xr[off:off + 3 * n:3]
        g[3 * n:6 * n:3] -= om
    else:
        g[n:2 * n] -= om
    return g


def _strains(model: DrillstringModel, t: float, xr: np.ndarray) -> np.ndarray:
    alpha, _ = top_drive(t, model.p[OMEGA0], model.p[T_RAMP])
    out = model.outputs(t, _to_inertial(model, xr, alpha))
    idx = [model.output_names.index(strain(s, a))
           for s, a in site_channels(range(1, model.n_sites + 1))]
    return out[idx].copy()


def linearize(params: PlantParams, kind: str = "full3d", spin: float | None = None,
              rel_step: float = 1e-7, time: float | None = None) -> LinearModel:
    """Linearize the plant about the straight string spinning at the top-drive speed.

    Parameters
    ----------
    params : PlantParams
        Plant parameters (forcing is removed, see :func:`operating_params`).
    kind : {"full3d", "axial_torsional"}
    spin : float, optional
        Top-drive speed [rad/s]; default ``params.top_drive.rotary_speed``.
    rel_step : float
        Relative finite-difference step.
    time : float, optional
        Time [s] of the linearization (default: 1 s after the ramp); ``A`` is the same for any
        time after the ramp, which the tests use to check the frame transformation.

    Returns
    -------
    LinearModel
    """

    prm = operating_params(params)
    if spin is not None:
        prm = replace(prm, top_drive=replace(prm.top_drive, rotary_speed=float(spin)))
    omega = prm.top_drive.rotary_speed
    model = DrillstringModel(prm, kind)
    if model.framed:
        raise ValueError("linearize: the spinning straight string needs a vertical hole; this "
                         "trajectory curves it (use analysis.modal.modes about a state instead)")
    rest = DrillstringModel(replace(prm, top_drive=replace(prm.top_drive, rotary_speed=0.0)), kind)
    x0 = static_equilibrium(rest)
    n = model.n
    if kind == "full3d":
        x0[9 * n + 2::3] = omega
    else:
        x0[3 * n:] = omega
    t = prm.top_drive.ramp_time + 1.0 if time is None else float(time)
    nu = 2 * model.n_sites
    u0 = np.zeros(nu)
    N = model.n_state
    A = np.empty((N, N))
    C = np.empty((nu, N)) if kind == "full3d" else np.zeros((0, N))
    xp = x0.copy()
    for i in range(N):
        h = rel_step * max(1.0, abs(x0[i]))
        xp[i] = x0[i] + h
        fp = _rotating_rhs(model, t, xp, u0)
        sp = _strains(model, t, xp) if kind == "full3d" else None
        xp[i] = x0[i] - h
        fm = _rotating_rhs(model, t, xp, u0)
        sm = _strains(model, t, xp) if kind == "full3d" else None
        xp[i] = x0[i]
        A[:, i] = (fp - fm) / (2 * h)
        if kind == "full3d":
            C[:, i] = (sp - sm) / (2 * h)
    B = np.empty((N, nu))
    for j in range(nu):
        up = u0.copy()
        up[j] = 1.0
        um = u0.copy()
        um[j] = -1.0
        B[:, j] = (_rotating_rhs(model, t, x0, up) - _rotating_rhs(model, t, x0, um)) / 2.0
    alpha, _ = top_drive(t, model.p[OMEGA0], model.p[T_RAMP])
    return LinearModel(A, B, C, _to_inertial(model, x0, alpha), t, omega, model)


def inertial_lateral_eigenvalue(lm: LinearModel, lam: complex, vec: np.ndarray) -> complex:
    """Inertial-frame eigenvalue of a lateral mode found in the rotating frame.

    The mode's lateral positions X' + iY' (forward whirl) or X' - iY' (backward whirl) carry it;
    the inertial eigenvalue is lam + i Omega or lam - i Omega respectively. Returns the one with
    positive imaginary part (its conjugate is the other of the pair).
    """
    n = lm.model.n
    X = vec[0:3 * n:3]
    Y = vec[1:3 * n:3]
    fwd = np.linalg.norm(X + 1j * Y)
    bwd = np.linalg.norm(X - 1j * Y)
    mu = lam + 1j * lm.spin if fwd >= bwd else lam - 1j * lm.spin
    return mu if mu.imag >= 0 else np.conj(mu)
