"""Top-drive speed controller on top-torque feedback (soft-torque style).

The top drive in mode ``"torque"`` (``docs/physics.md`` section 1) is a rotor of inertia
J_td [kg m^2] driven by the motor torque T_m [N m] and braked by the string's top torque
T_s [N m]: ``J_td dOmega/dt = T_m - T_s``. This controller sets T_m from the measured drive
speed Omega [rad/s] and top torque T_s:

    e(t)  = Omega_ref(t) - Omega(t),      Omega_ref(t) = target_speed * min(t / ramp_time, 1)
    x(t)  = integral_0^t e dt              [rad]
    T_m   = P e + I x + k_T T_s

a PI speed controller (P [N m s/rad], I [N m/rad]) with an optional top-torque feedback
gain k_T [1].

Why it damps stick-slip (Jansen & van den Steen 1995, "Active damping of self-excited
torsional vibrations in oil well drillstrings", J. Sound Vib. 179(4): the top drive tuned to
absorb the torsional waves coming up the string instead of reflecting them). Linearised about a
steady speed, the drive offers the string the impedance

    Z_d(i w) = -T_s / Omega = (i w J_td + P + I / (i w)) / (1 - k_T)      [N m s/rad]

(k_T < 1). A stiff speed controller (large P, I) is a fixed end: a wave arriving at the top is
reflected whole, and the string's lowest torsional mode, driven by the bit's falling friction,
grows into stick-slip. Tuned with I = J_td w_s^2 (inertia and integral cancel at the
stick-slip frequency w_s) the drive is a pure damper P / (1 - k_T) there; with that damping
near the string's characteristic impedance zeta = J sqrt(G rho) (J the polar second moment of
area) the reflection coefficient (zeta - Z_d) / (zeta + Z_d) is small and the energy the bit
feeds into the mode leaves through the drive. That is the picture of a long string; a short
one with a heavy bottom-hole assembly (scene ``stick_slip``: 1000 m, 400 kg m^2) has a
pendulum-like lowest mode, and the damping it needs is that mode's: there P = zeta = 300
N m s/rad still sticks and slips, P >= 600 does not (docs/physics.md section 6).

The steady state (constant bit torque T_b, when the steady rotation is stable) is
Omega = target_speed, T_m = T_s = T_b and x = (1 - k_T) T_b / I.

Time discretisation
-------------------
``step(t, dt, speed, torque)`` holds the measured speed and torque over ``[t, t + dt]`` (as the
co-simulation delivers them), integrates the held error exactly, ``x(t + dt) = x(t) + dt e(t)``,
and returns the motor torque at ``t + dt``: ``P e(t) + I x(t + dt) + k_T T_s(t)``. The state is
``(x, T_m)``.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from .acceleration import OK, REFUSED, compiled_law
from .law import Law, Settings, setting
from .ports import Port, real_input, real_output

__all__ = ["TopDriveController", "TopDriveControllerParams", "drive_ports", "speed_reference",
           "top_drive_core"]


def drive_ports() -> tuple[Port, ...]:
    """The inputs and output of a top-drive law: the drive speed and the top torque (plant
    outputs), the motor torque (the plant's input in top_drive.mode "torque")."""
    return (real_input("top_rotary_speed", "rad/s", "Rotary speed of the top drive"),
            real_input("top_torque", "N.m", "Torque the top drive applies to the string"),
            real_output("top_drive_torque", "N.m", "Motor torque on the top-drive rotor"))


@dataclass(frozen=True)
class TopDriveControllerParams(Settings):
    """Parameters of the top-drive speed controller (see the module docstring).

    Parameters
    ----------
    target_speed : float
        Target rotary speed of the drive [rad/s], ``|target_speed| <= 1e3``.
    p_gain : float
        Proportional gain P [N m s/rad], ``0 <= P < inf``.
    i_gain : float
        Integral gain I [N m/rad], ``0 <= I < inf``.
    torque_feedback : float
        Top-torque feedback gain k_T [1], ``-10 <= k_T < 1`` (0: a plain PI speed controller;
        the drive's impedance is scaled by ``1 / (1 - k_T)``).
    ramp_time : float
        The speed reference ramps from 0 to ``target_speed`` over this time [s], ``>= 0``.
    enabled : bool
        ``False``: zero motor torque at all times.

    Raises
    ------
    ValueError
        For any invalid value; the message names the parameter and the allowed range.
    """

    target_speed: float = setting(2.0, "rad/s", "Target rotary speed of the drive; "
                                  "|target_speed| <= 1e3", range=(-1e3, 1e3))
    p_gain: float = setting(300.0, "N.m.s/rad", "Proportional gain P of the speed controller; "
                            "0 <= P < inf", range=(0.0, math.inf), open=(False, True))
    i_gain: float = setting(1000.0, "N.m/rad", "Integral gain I of the speed controller; "
                            "0 <= I < inf", range=(0.0, math.inf), open=(False, True))
    torque_feedback: float = setting(0.0, "1", "Top-torque feedback gain k_T: T_m += k_T "
                                     "top_torque; -10 <= k_T < 1 (0 = plain PI)",
                                     range=(-10.0, 1.0), open=(False, True))
    ramp_time: float = setting(1.0, "s", "The speed reference ramps from 0 to target_speed over "
                               "this time; >= 0", range=(0.0, math.inf), open=(False, True))
    enabled: bool = setting(True, "", "false = zero motor torque at all times", fixed=True)

    def reference(self, t: float) -> float:
        """Speed reference Omega_ref(t) [rad/s]: the ramp to ``target_speed``."""
        return speed_reference(self.target_speed, self.ramp_time, t)


def speed_reference(target: float, ramp_time: float, t: float) -> float:
    """The speed reference [rad/s] at ``t`` [s]: from 0 to ``target`` over ``ramp_time`` [s]."""
    if ramp_time == 0.0 or t >= ramp_time:
        return target
    return target * max(t, 0.0) / ramp_time


class TopDriveController(Law):
    """The sampled PI speed controller with top-torque feedback.

    Parameters
    ----------
    params : TopDriveControllerParams, optional
        Defaults to ``TopDriveControllerParams()``.

    Notes
    -----
    The state is ``[x, T_m]``: the integral of the speed error [rad] and the motor torque of
    the last step [N m] (:meth:`get_state` / :meth:`set_state`). A call that fails validation
    raises ``ValueError`` and leaves the state unchanged.
    """

    KIND = "pi"
    TABLE = "top_drive_controller"
    FMU = "TopDriveController"
    DESCRIPTION = ("Top-drive speed controller (PI on the drive speed with top-torque feedback, "
                   "soft-torque style): motor torque = P e + I integral(e) + k_T top_torque, e = "
                   "speed reference - drive speed; drives a plant in top_drive.mode 'torque'")
    PARAMS = TopDriveControllerParams
    COMPILED = ("top_drive_core", (1, 1, 1, 1))

    @classmethod
    def io_ports(cls, layout: Mapping[str, Any]) -> tuple[Port, ...]:
        return drive_ports()

    #: What the state holds, in order (:meth:`get_state`).
    STATE: tuple[str, ...] = ("x", "T_m")

    def __init__(self, params: TopDriveControllerParams | None = None) -> None:
        self._params = self.PARAMS()
        self.params = self.PARAMS() if params is None else params
        self._state = np.zeros(len(self.STATE))

    @property
    def params(self) -> TopDriveControllerParams:
        """The current parameters (:attr:`PARAMS`); assigning keeps the state."""
        return self._params

    @params.setter
    def params(self, params: TopDriveControllerParams) -> None:
        if not isinstance(params, self.PARAMS):
            raise TypeError(f"params must be a {self.PARAMS.__name__}, got "
                            f"{type(params).__name__}")
        self._params = params

    def reset(self) -> None:
        """The state (integral, motor torque, ...) back to zero."""
        self._state[:] = 0.0

    def get_state(self) -> np.ndarray:
        """numpy.ndarray: a copy of the state (:attr:`STATE`; here ``[x [rad], T_m [N m]]``)."""
        return self._state.copy()

    def set_state(self, state: np.ndarray) -> None:
        """Restore a state of :meth:`get_state` (its shape, finite; else ValueError)."""
        arr = np.asarray(state, dtype=float)
        if arr.shape != self._state.shape or not np.all(np.isfinite(arr)):
            raise ValueError(f"state must be {self._state.size} finite numbers "
                             f"[{', '.join(self.STATE)}], got {arr.tolist()}")
        self._state[:] = arr

    @property
    def torque(self) -> float:
        """Motor torque of the last step [N m]."""
        return float(self._state[1])

    def step(self, t: float, dt: float, speed: float, torque: float) -> float:
        """Advance over ``[t, t + dt]`` with the measurements held; the motor torque at ``t + dt``.

        Parameters
        ----------
        t : float
            Start of the step [s] (when speed and torque were sampled).
        dt : float
            Step [s], finite, ``>= 0``.
        speed : float
            Drive speed Omega [rad/s], finite.
        torque : float
            Top torque T_s [N m], finite.

        Returns
        -------
        float
            Motor torque T_m [N m] at ``t + dt`` (0 when disabled).

        Raises
        ------
        ValueError
            Non-finite time, step, speed or torque, or ``dt < 0`` (state unchanged).
        """
        if not (math.isfinite(t) and math.isfinite(dt) and dt >= 0.0):
            raise ValueError(f"need finite t and finite dt >= 0, got t = {t!r}, dt = {dt!r}")
        if not (math.isfinite(speed) and math.isfinite(torque)):
            raise ValueError(f"non-finite input: top_rotary_speed = {speed!r} rad/s, "
                             f"top_torque = {torque!r} N m")
        p = self._params
        if not p.enabled:
            self._state[1] = 0.0
            return 0.0
        error = p.reference(t) - speed
        x = self._state[0] + dt * error
        motor = p.p_gain * error + p.i_gain * x + p.torque_feedback * torque
        self._state[:] = (x, motor)
        return float(motor)

    def initial_outputs(self) -> np.ndarray:
        """The motor torque [N m]."""
        return np.array([self.torque])

    def advance(self, t: float, h: float, inputs: np.ndarray, outputs: np.ndarray) -> None:
        """:meth:`step` with ``inputs = [speed, torque]``, the motor torque into ``outputs``."""
        outputs[0] = self.step(t, h, float(inputs[0]), float(inputs[1]))

    def compiled_step(self, inputs: np.ndarray, outputs: np.ndarray) -> Any:
        """This law's compiled step (:class:`controller.compiled.CompiledLaw`, core
        :func:`top_drive_core`) reading
        ``[speed, torque]`` from ``inputs`` (shape (2,)) and writing the motor torque into
        ``outputs`` (shape (1,)); None without numba or with compiled steps switched off."""
        def pack() -> tuple[object, list[np.ndarray]]:
            p = self._params
            params = np.array([p.target_speed, p.p_gain, p.i_gain, p.torque_feedback,
                               p.ramp_time, float(p.enabled)])
            return p, [params, self._state, inputs, outputs]

        return compiled_law(self.KIND, pack)


# ------------------------------------------------------------------------ compiled core
# slots of the params array
T_TARGET, T_P, T_I, T_KT, T_RAMP, T_ENABLED = range(6)


def top_drive_core(t, dt, params, state, inputs, outputs):
    """:meth:`controller.TopDriveController.step` on the buffers (see the module docstring)."""
    if not (math.isfinite(t) and math.isfinite(dt) and dt >= 0.0):
        return REFUSED
    speed = inputs[0]
    torque = inputs[1]
    if not (math.isfinite(speed) and math.isfinite(torque)):
        return REFUSED
    if params[T_ENABLED] == 0.0:
        state[1] = 0.0
        outputs[0] = 0.0
        return OK
    ramp = params[T_RAMP]
    target = params[T_TARGET]
    if ramp == 0.0 or t >= ramp:
        reference = target
    else:
        reference = target * (0.0 if 0.0 > t else t) / ramp  # Python's max(t, 0.0)
    error = reference - speed
    x = state[0] + dt * error
    motor = params[T_P] * error + params[T_I] * x + params[T_KT] * torque
    state[0] = x
    state[1] = motor
    outputs[0] = motor
    return OK
