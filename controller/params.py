"""Validated, immutable parameters of the strain-feedback controller.

Only numpy and the standard library are imported (the package is vendored into
the controller FMU and must run in a Python that has nothing but numpy).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from numbers import Real
from typing import Literal

from .law import Settings, setting

__all__ = ["MODES", "ControllerParams", "Mode", "check_gain_matrix"]

Mode = Literal["unrestricted", "compressive_only"]
#: Allowed values of :attr:`ControllerParams.mode`, in the order of the FMU's
#: integer encoding (0 = ``"unrestricted"``, 1 = ``"compressive_only"``).
MODES: tuple[str, ...] = ("unrestricted", "compressive_only")


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
class ControllerParams(Settings):
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

    gain: float = setting(1e9, "N", "Proportional gain, N per unit strain; 0 <= gain < inf "
                          "(paper: 1e9)", range=(0.0, math.inf), open=(False, True))
    force_limit: float = setting(5000.0, "N", "Peak push force in compressive_only mode; "
                                 "0 <= force_limit <= inf", range=(0.0, math.inf))
    symmetric_force_limit: float = setting(
        math.inf, "N", "Limit on |force| in unrestricted mode; >= 0 (1e30 = effectively none)",
        range=(0.0, math.inf))
    switch_on_time: float = setting(0.0, "s", "Controller output is zero before this time; >= 0",
                                    range=(0.0, math.inf), open=(False, True))
    mode: Mode = setting("unrestricted", "", "Actuator: push and pull, or push only",
                         choices=MODES, fixed=True)
    lag_time_constant: float = setting(0.0, "s", "First-order actuator lag time constant; 0 = no "
                                       "lag", range=(0.0, math.inf), open=(False, True),
                                       fixed=True)
    enabled: bool = setting(True, "", "false = open loop (zero force at all times)", fixed=True)
    gain_matrix: tuple = field(default=(), metadata={
        "unit": "1", "doc": "relative gains M (n_sites x n_sites, row i = force of site i from "
        "the strain of site j), the same for both axes: F_axis = gain * M @ strain_axis (MIMO "
        "across the sites); [] or the identity = one P law per channel. Its FMU has the "
        "parameters gain_matrix_<i>_<j>"})

    def __post_init__(self) -> None:
        super().__post_init__()
        object.__setattr__(self, "gain_matrix", check_gain_matrix(self.gain_matrix))

    @property
    def lower_limit(self) -> float:
        """Lowest force the actuator can produce [N] (``0`` or ``-symmetric_force_limit``)."""
        return 0.0 if self.mode == "compressive_only" else -self.symmetric_force_limit

    @property
    def upper_limit(self) -> float:
        """Highest force the actuator can produce [N]."""
        return self.force_limit if self.mode == "compressive_only" else self.symmetric_force_limit
