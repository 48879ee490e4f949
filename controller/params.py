"""Validated, immutable parameters of the strain-feedback controller.

Only numpy and the standard library are imported (the package is vendored into
the controller FMU and must run in a Python that has nothing but numpy).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from numbers import Real
from typing import Literal

import numpy as np

__all__ = ["MODES", "ControllerParams", "Mode", "check_gain_matrix"]

Mode = Literal["unrestricted", "compressive_only"]
#: Allowed values of :attr:`ControllerParams.mode`, in the order of the FMU's
#: integer encoding (0 = ``"unrestricted"``, 1 = ``"compressive_only"``).
MODES: tuple[str, ...] = ("unrestricted", "compressive_only")


def _check_real(name: str, value: object, low: float, high: float, *, low_open: bool = False,
                high_open: bool = False) -> float:
    """Return ``value`` as float if it lies in the interval, else raise ValueError.

    Parameters
    ----------
    name : str
        Parameter name, quoted in the error message.
    value : object
        Candidate value; must be a real number (``bool`` is rejected).
    low, high : float
        Interval bounds (may be infinite).
    low_open, high_open : bool
        Whether the respective bound is excluded.

    Returns
    -------
    float
        The validated value.

    Raises
    ------
    ValueError
        If the value is not a real number, is NaN or lies outside the interval.
        The message names the parameter, the value and the allowed range.
    """
    left = "<" if low_open else "<="
    right = "<" if high_open else "<="
    allowed = f"allowed: {low:g} {left} {name} {right} {high:g}"
    if isinstance(value, bool) or not isinstance(value, Real):
        raise ValueError(f"{name} = {value!r} is not a real number; {allowed}")
    x = float(value)
    if math.isnan(x):
        raise ValueError(f"{name} = nan is not allowed; {allowed}")
    too_low = x <= low if low_open else x < low
    too_high = x >= high if high_open else x > high
    if too_low or too_high:
        raise ValueError(f"{name} = {x!r} is out of range; {allowed}")
    return x


def check_gain_matrix(value: object) -> tuple[tuple[float, ...], ...]:
    """``value`` as a validated square matrix of relative gains; ``()`` for none or the identity.

    Parameters
    ----------
    value : sequence of sequences of real numbers, shape (n, n)
        Row i = force of site i, column j = strain of site j [1]. An empty sequence means none.

    Returns
    -------
    tuple of tuple of float
        The matrix, or ``()`` when it is empty or the identity (the identity is the SISO law:
        one representation for one law, so every implementation computes it the same way).

    Raises
    ------
    ValueError
        Not a square matrix of finite real numbers (the message names ``gain_matrix``).
    """
    if isinstance(value, (str, bytes)) or not hasattr(value, "__len__"):
        raise ValueError(f"gain_matrix = {value!r} is not allowed; allowed: a square matrix "
                         "(list of rows) of finite real numbers, or [] for none")
    rows = list(value)  # type: ignore[call-overload]
    n = len(rows)
    out = []
    for i, row in enumerate(rows):
        if isinstance(row, (str, bytes)) or not hasattr(row, "__len__") or len(row) != n:
            raise ValueError(f"gain_matrix row {i + 1} = {row!r} is not allowed; allowed: a "
                             f"square matrix, here {n} rows of {n} finite real numbers")
        for j, x in enumerate(row):
            if isinstance(x, bool) or not isinstance(x, Real) or not math.isfinite(float(x)):
                raise ValueError(f"gain_matrix[{i + 1}][{j + 1}] = {x!r} is not allowed; "
                                 "allowed: a finite real number")
        out.append(tuple(float(x) for x in row))
    if all(out[i][j] == (1.0 if i == j else 0.0) for i in range(n) for j in range(n)):
        return ()
    return tuple(out)


@dataclass(frozen=True)
class ControllerParams:
    """Parameters of the proportional strain-feedback law (paper section 4).

    Parameters
    ----------
    gain : float
        Proportional gain k_p [N per unit strain]; ``0 <= gain < inf``.
        The paper uses 1e9 (kN of force per microstrain).
    mode : {"unrestricted", "compressive_only"}
        ``"unrestricted"``: the actuator may push or pull (force clipped to
        ``+-symmetric_force_limit``). ``"compressive_only"``: it can only push,
        the force is clipped to ``[0, force_limit]``.
    force_limit : float
        Peak push force [N] in ``"compressive_only"`` mode; ``0 <= force_limit <= inf``.
        The paper's restricted actuator uses 5000 N.
    symmetric_force_limit : float
        Limit on ``|F|`` [N] in ``"unrestricted"`` mode; ``0 <= value <= inf``,
        default ``inf`` (no limit, as in the paper).
    switch_on_time : float
        Time [s] from which the controller acts; the output is zero before it.
        ``0 <= switch_on_time < inf``. The paper also switches on at 25 s.
    lag_time_constant : float
        Time constant T [s] of a first-order actuator lag; ``0`` means no lag.
        ``0 <= lag_time_constant < inf``.
    enabled : bool
        ``False`` forces a zero output at all times (open loop).
    gain_matrix : tuple of tuple of float, shape (n_sites, n_sites), optional
        Relative gains [1] of a MIMO law across the sites, the same for both axes:
        ``F_axis = gain * gain_matrix @ strain_axis`` (row i = force of site i, column j =
        strain of site j), i.e. the gain matrix ``G = gain * gain_matrix`` [N per unit
        strain]. ``()`` (default) or the identity: the SISO law ``F = gain * strain`` per
        channel (the identity is stored as ``()``).

    Raises
    ------
    ValueError
        From ``__post_init__`` for any invalid value; the message names the
        parameter, the offending value and the allowed range. NaN is rejected.
    """

    gain: float = 1e9
    mode: Mode = "unrestricted"
    force_limit: float = 5000.0
    symmetric_force_limit: float = math.inf
    switch_on_time: float = 0.0
    lag_time_constant: float = 0.0
    enabled: bool = True
    gain_matrix: tuple = ()

    def __post_init__(self) -> None:
        inf = math.inf
        checked = {
            "gain": _check_real("gain", self.gain, 0.0, inf, high_open=True),
            "force_limit": _check_real("force_limit", self.force_limit, 0.0, inf),
            "symmetric_force_limit": _check_real(
                "symmetric_force_limit", self.symmetric_force_limit, 0.0, inf),
            "switch_on_time": _check_real(
                "switch_on_time", self.switch_on_time, 0.0, inf, high_open=True),
            "lag_time_constant": _check_real(
                "lag_time_constant", self.lag_time_constant, 0.0, inf, high_open=True),
        }
        if self.mode not in MODES:
            choices = ", ".join(map(repr, MODES))
            raise ValueError(f"mode = {self.mode!r} is not allowed; allowed: one of {choices}")
        if not isinstance(self.enabled, (bool, np.bool_)):
            raise ValueError(f"enabled = {self.enabled!r} is not allowed; allowed: True or False")
        checked["enabled"] = bool(self.enabled)
        checked["gain_matrix"] = check_gain_matrix(self.gain_matrix)
        for name, value in checked.items():
            object.__setattr__(self, name, value)

    @property
    def lower_limit(self) -> float:
        """Lowest force the actuator can produce [N] (``0`` or ``-symmetric_force_limit``)."""
        return 0.0 if self.mode == "compressive_only" else -self.symmetric_force_limit

    @property
    def upper_limit(self) -> float:
        """Highest force the actuator can produce [N]."""
        return self.force_limit if self.mode == "compressive_only" else self.symmetric_force_limit
