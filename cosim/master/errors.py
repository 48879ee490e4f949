"""Exceptions of the co-simulation master.

This is the one place where FMI status codes returned by fmpy's low-level calls
become exceptions: :func:`raise_for_status` turns a status
of ``fmi2Discard``, ``fmi2Error``, ``fmi2Fatal`` or ``fmi2Pending`` into a
:class:`CosimError` naming the FMU instance, the FMI function and the simulated
time of the call. :class:`UserError` is the one type of bad input.
"""

from __future__ import annotations

import math

FMI2_STATUS_NAMES = ("fmi2OK", "fmi2Warning", "fmi2Discard", "fmi2Error", "fmi2Fatal",
                     "fmi2Pending")
FMI2_WARNING = 1
FMI2_DISCARD = 2
FMI2_ERROR = 3
FMI2_FATAL = 4


def status_name(status: int) -> str:
    """Name of an FMI 2 status code (``'illegal status 7'`` if out of range)."""
    if 0 <= status < len(FMI2_STATUS_NAMES):
        return FMI2_STATUS_NAMES[status]
    return f"illegal status {status}"


class UserError(ValueError):
    """Bad input from the user: a file, a key, a value, or FMUs that do not fit.

    The message is complete in itself (one line per problem, naming what is wrong and what is
    allowed); the command line prints it without a traceback and exits with code 2. Anything
    else that escapes is an internal error and keeps its traceback.
    """


class CosimError(RuntimeError):
    """A co-simulation step failed.

    Parameters
    ----------
    fmu_name : str
        Instance name of the FMU involved ('' if none).
    call : str
        FMI function (e.g. ``'fmi2DoStep'``) or master operation that failed.
    time : float
        Simulated time of the call [s] (``nan`` if not applicable).
    message : str
        What went wrong.

    Attributes
    ----------
    status : int or None
        FMI status code when the error comes from an FMI call.
    fmu_message : str or None
        The component's own message about the failure (its newest Discard/Error/Fatal log
        message, one line), also the end of ``message``.
    result : object or None
        Set by :class:`cosim.master.Master` to the partial result recorded
        until the failure.
    """

    def __init__(self, fmu_name: str, call: str, time: float, message: str,
                 status: int | None = None, fmu_message: str | None = None):
        self.fmu_name = fmu_name
        self.call = call
        self.time = time
        self.message = message
        self.status = status
        self.fmu_message = fmu_message
        self.result = None
        when = "" if math.isnan(time) else f" at t = {time:.9g} s"
        super().__init__(f"FMU '{fmu_name}': {call} failed{when}: {message}")

    def __reduce__(self):
        return (type(self), (self.fmu_name, self.call, self.time, self.message, self.status,
                             self.fmu_message))


class DivergenceError(CosimError):
    """A non-finite value was read from an FMU output.

    Parameters
    ----------
    quantity : str
        Variable as ``'fmu.variable'``.
    time : float
        Simulated time at which it was read [s].
    value : float
        The offending value (nan or +-inf).
    """

    def __init__(self, quantity: str, time: float, value: float):
        self.quantity = quantity
        self.value = value
        fmu_name = quantity.split(".", 1)[0]
        super().__init__(fmu_name, "fmi2GetReal", time,
                         f"non-finite value {value!r} of output '{quantity}'")

    def __reduce__(self):
        return (type(self), (self.quantity, self.time, self.value))


def raise_for_status(status: int, fmu_name: str, call: str, time: float,
                     detail: str | None = None) -> None:
    """Raise :class:`CosimError` for an FMI status worse than ``fmi2Warning``.

    Called from hot loops only after the cheap test ``status > 1`` failed. ``detail`` is the
    component's own message (from its FMI logger callback), appended to the message.
    """
    if status <= FMI2_WARNING:
        return
    hint = {
        2: "the FMU discarded the step (fmi2Discard)",
        3: "the FMU reported an error (fmi2Error)",
        4: "the FMU reported a fatal error (fmi2Fatal); the instance is unusable",
        5: "asynchronous stepping (fmi2Pending) is not supported",
    }.get(status, f"{status_name(status)} returned")
    raise CosimError(fmu_name, call, time, f"{hint}: {detail}" if detail else hint,
                     status=status, fmu_message=detail)
