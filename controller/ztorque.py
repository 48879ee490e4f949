"""ZTorque: a top drive that absorbs the torsional waves of the string (Dwars 2015).

Source: S. Dwars, "Recent Advances in Soft Torque Rotary Systems", SPE/IADC-173037-MS, SPE/IADC
Drilling Conference, London, 2015 (Shell's ZTorque, the successor of SoftTorque and of
Kyllingstad & Nessjoen's SoftSpeed, SPE-119660, 2009). NORCE's Simulator4nDOF
(``TopdriveController.cs``) implements it with an estimated pipe torque; here the top torque is
an input (the plant's ``top_torque``).

The law
-------
A stiff PI speed controller follows a speed set point that gives way to the torque:

    T_hp  = high-pass of the top torque T_s,   T_lp' = (T_s - T_lp) / tau_hp,  T_hp = T_s - T_lp
    e     = Omega_ref(t) - k T_hp / zeta - Omega
    T_m   = P e + I integral(e) dt

``zeta`` = ``impedance`` [N m s/rad], ``k`` = ``torque_factor`` [1], ``tau_hp`` =
``highpass_time_constant`` [s], ``P`` = ``p_gain`` [N m s/rad], ``I`` = ``i_gain`` [N m/rad];
``Omega_ref`` ramps to ``target_speed`` over ``ramp_time`` as in the PI law (``top_drive.py``).

Why it damps stick-slip: while the speed loop is stiff (its bandwidth above the torsional
modes) the drive speed follows the set point, so for torque fluctuations in the high-pass band
``delta Omega = -k delta T / zeta``: the drive is a damper of impedance ``Z_d = zeta / k``
seen from the string. A torsional wave arriving at the top of a pipe of characteristic
impedance ``zeta`` is reflected with the coefficient ``(zeta - Z_d) / (zeta + Z_d)``: zero for
``k = 1``, the drive absorbs it (where a stiff speed controller, ``Z_d`` -> infinity, reflects
it whole and the bit's falling friction feeds the mode). The high-pass keeps the mean torque out
of the set point, so the mean speed is the target. With the drive's inertia ``J`` and the
finite loop gain ``C(i w) = P + I / (i w)`` the impedance is

    Z_d(i w) = (i w J + C) / (1 + C k H(i w) / zeta),      H(i w) = i w tau_hp / (1 + i w tau_hp),

which tends to ``zeta / k`` for ``|C| >> w J, zeta`` and ``w tau_hp >> 1``
(``tests/test_ztorque.py`` checks the sampled law against this formula).

Tuning rule (Dwars 2015; NORCE's defaults in brackets): ``zeta = J_p sqrt(G rho)`` of the drill
pipe at the top (J_p its polar second moment of area: 300 N m s/rad for 5-in, 19.5 ppf pipe);
``k = 1`` (matched; NORCE 0.25 for margin); a stiff speed loop, ``P`` tens of ``zeta`` [50 zeta]
and ``I`` a few ``J`` per s^2 [5 J]; ``tau_hp`` several stick-slip periods (the high-pass corner
``1 / tau_hp`` well below the stick-slip frequency) [20 / (2 pi) s].

Time discretisation
-------------------
As the PI law: the speed and torque sampled at ``t`` are held over ``[t, t + h]``, the error is
taken at ``t`` and integrated exactly, and the motor torque at ``t + h`` is ``P e + I x(t + h)``;
the high-pass's low-pass state takes the exact step ``T_lp <- T_s + (T_lp - T_s) exp(-h /
tau_hp)`` after ``T_hp`` was taken from it. The filter starts at the first torque it sees (no
set-point jump at the start). The state is ``[x, T_m, T_lp, started]``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from .acceleration import FALLBACK, OK, REFUSED, compiled_law
from .law import Settings, setting
from .top_drive import TopDriveController, speed_reference

__all__ = ["ZTorqueController", "ZTorqueParams", "ztorque_core"]


@dataclass(frozen=True)
class ZTorqueParams(Settings):
    """Parameters of the ZTorque law (see the module docstring); ValueError naming a bad one."""

    target_speed: float = setting(2.0, "rad/s", "Target rotary speed of the drive; "
                                  "|target_speed| <= 1e3", range=(-1e3, 1e3))
    ramp_time: float = setting(1.0, "s", "The speed reference ramps from 0 to target_speed over "
                               "this time; >= 0", range=(0.0, math.inf), open=(False, True))
    impedance: float = setting(300.0, "N.m.s/rad", "Characteristic torsional impedance zeta = "
                               "J sqrt(G rho) of the drill pipe at the top (5-in pipe: 300); > 0",
                               range=(0.0, math.inf), open=(True, True))
    torque_factor: float = setting(1.0, "1", "k: the drive's impedance is zeta / k for torsional "
                                   "waves (1 = matched, no reflection); 0 <= k <= 1",
                                   range=(0.0, 1.0))
    highpass_time_constant: float = setting(
        10.0, "s", "Time constant of the high-pass on the top torque (keeps its mean out of the "
        "speed set point); > 0", range=(0.0, math.inf), open=(True, True))
    p_gain: float = setting(15000.0, "N.m.s/rad", "P of the stiff speed loop (Dwars: tens of "
                            "zeta); 0 <= P < inf", range=(0.0, math.inf), open=(False, True))
    i_gain: float = setting(2500.0, "N.m/rad", "I of the stiff speed loop (a few drive "
                            "inertias per s^2); 0 <= I < inf", range=(0.0, math.inf),
                            open=(False, True))
    enabled: bool = setting(True, "", "false = zero motor torque at all times", fixed=True)


class ZTorqueController(TopDriveController):
    """The ZTorque law of the module docstring (inputs: drive speed, top torque; output: the
    motor torque), a top-drive law like :class:`controller.TopDriveController`."""

    KIND = "ztorque"
    FMU = "ZTorqueController"
    DESCRIPTION = ("ZTorque top-drive controller (Dwars 2015): a stiff PI speed loop whose set "
                   "point gives way to the high-passed top torque, speed_ref - k T_hp / zeta: "
                   "the drive absorbs the string's torsional waves; drives a plant in "
                   "top_drive.mode 'torque'")
    PARAMS = ZTorqueParams
    COMPILED = ("ztorque_core", (1, 1, 1, 1, 1))
    STATE = ("x", "T_m", "T_lp", "started")

    def __init__(self, params: ZTorqueParams | None = None) -> None:
        super().__init__(params)
        #: [dt, exp(-dt / tau_hp)]: the high-pass's decay factor and the step [s] it is for
        self._decay = np.array([math.nan, 0.0])

    @TopDriveController.params.setter
    def params(self, params: ZTorqueParams) -> None:
        TopDriveController.params.fset(self, params)
        if hasattr(self, "_decay"):
            self._decay[0] = math.nan

    def step(self, t: float, dt: float, speed: float, torque: float) -> float:
        """Advance over ``[t, t + dt]`` with the speed [rad/s] and top torque [N m] held; the
        motor torque at ``t + dt`` [N m] (ValueError for non-finite values or ``dt < 0``,
        state unchanged)."""
        if not (math.isfinite(t) and math.isfinite(dt) and dt >= 0.0):
            raise ValueError(f"need finite t and finite dt >= 0, got t = {t!r}, dt = {dt!r}")
        if not (math.isfinite(speed) and math.isfinite(torque)):
            raise ValueError(f"non-finite input: top_rotary_speed = {speed!r} rad/s, "
                             f"top_torque = {torque!r} N m")
        p, s, d = self._params, self._state, self._decay
        if not p.enabled:
            s[1] = 0.0
            return 0.0
        if s[3] == 0.0:
            s[2], s[3] = torque, 1.0
        if dt != d[0]:
            d[:] = dt, math.exp(-dt / p.highpass_time_constant)
        high = torque - s[2]
        error = (speed_reference(p.target_speed, p.ramp_time, t)
                 - p.torque_factor * high / p.impedance - speed)
        x = s[0] + dt * error
        motor = p.p_gain * error + p.i_gain * x
        s[0], s[1] = x, motor
        s[2] = torque + (s[2] - torque) * d[1]
        return float(motor)

    def compiled_step(self, inputs: np.ndarray, outputs: np.ndarray) -> Any:
        """The compiled step (core :func:`ztorque_core`) on ``inputs`` (speed, torque) and
        ``outputs`` (motor torque); None without numba or with compiled steps switched off."""
        def pack() -> tuple[object, list[np.ndarray]]:
            p = self._params
            params = np.array([p.target_speed, p.ramp_time, p.impedance, p.torque_factor,
                               p.p_gain, p.i_gain, float(p.enabled)])
            return p, [params, self._decay, self._state, inputs, outputs]

        return compiled_law(self.KIND, pack)


# ------------------------------------------------------------------------ compiled core
TARGET, RAMP, ZETA, K, P, I, ENABLED = range(7)


def ztorque_core(t, dt, params, decay, state, inputs, outputs):
    """:meth:`ZTorqueController.step` on the law's arrays."""
    if not (math.isfinite(t) and math.isfinite(dt) and dt >= 0.0):
        return REFUSED
    speed = inputs[0]
    torque = inputs[1]
    if not (math.isfinite(speed) and math.isfinite(torque)):
        return REFUSED
    if params[ENABLED] == 0.0:
        state[1] = 0.0
        outputs[0] = 0.0
        return OK
    if dt != decay[0]:
        return FALLBACK  # the Python law computes exp(-dt / tau_hp) and keeps it
    if state[3] == 0.0:
        state[2] = torque
        state[3] = 1.0
    ramp = params[RAMP]
    target = params[TARGET]
    if ramp == 0.0 or t >= ramp:
        reference = target
    else:
        reference = target * (0.0 if 0.0 > t else t) / ramp  # Python's max(t, 0.0)
    high = torque - state[2]
    error = reference - params[K] * high / params[ZETA] - speed
    x = state[0] + dt * error
    motor = params[P] * error + params[I] * x
    state[0] = x
    state[1] = motor
    state[2] = torque + (state[2] - torque) * decay[1]
    outputs[0] = motor
    return OK
