"""Guarded FMI get/set for our pythonfmu slaves, shared by both FMU adapters.

Vendored into every FMU as ``_dcs_slave_support_0_1_0`` (see ``fmu_src/build.py``). A bad value
reference, a wrong type or writing a non-settable variable must never raise (an exception in a
callback is fmi2Error under our native wrapper and fmi2Fatal under pythonfmu's): the call is
rejected with a logged message naming it, the value is skipped (get returns a neutral value).

An adapter defines ``_accessible(vr, kind, call) -> bool`` (usually :func:`access_problem` plus
its own rules, ending in :func:`reject`) and decorates its class with :func:`guarded_access`,
which adds every ``get_*``/``set_*`` method the class does not define itself.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

from _dcs_pythonfmu_0_7_0 import Boolean, Integer, Real, String
from _dcs_pythonfmu_0_7_0.enums import Fmi2Causality

__all__ = ["access_problem", "reject", "guarded_access"]

_KINDS: tuple[tuple[type, Callable[[Any], Any], Any], ...] = (
    (Real, float, math.nan),
    (Integer, int, 0),
    (Boolean, bool, False),
    (String, str, ""),
)


def access_problem(slave: Any, vr: int, kind: type, call: str) -> str | None:
    """Why ``call`` (e.g. ``"setReal"``) may not access ``vr``, or None if it may."""
    var = slave.vars.get(vr)
    if var is None:
        return f"unknown value reference {vr} (valid: 0..{len(slave.vars) - 1})"
    if not isinstance(var, kind):
        return f"value reference {vr} ({var.name}) is not of type {kind.__name__}"
    if call.startswith("set") and var.causality not in (Fmi2Causality.input,
                                                        Fmi2Causality.parameter):
        return f"{var.name} (value reference {vr}) is an {var.causality.name}: not settable"
    return None


def reject(slave: Any, call: str, problem: str) -> bool:
    """Log a rejected access; under pythonfmu's wrapper also fail the next doStep. Returns False.

    The native wrapper fails the call itself (the error status of the logged message); pythonfmu's
    ignores get/set problems, so the adapter reports them at the next doStep instead.
    """
    if slave._fmi2_wrapper != "native":
        slave._call_error = f"{call}: {problem}"
    slave._error(f"{call}: {problem}")
    return False


def _getter(kind: type, convert: Callable[[Any], Any], default: Any, call: str):
    def get(self, vrs: list[int]) -> list[Any]:
        return [convert(self.vars[vr].getter()) if self._accessible(vr, kind, call) else default
                for vr in vrs]

    get.__name__ = f"get_{kind.__name__.lower()}"
    return get


def _setter(kind: type, convert: Callable[[Any], Any], call: str):
    def set_(self, vrs: list[int], values: list[Any]) -> None:
        for vr, value in zip(vrs, values):
            if self._accessible(vr, kind, call):
                self.vars[vr].setter(convert(value))

    set_.__name__ = f"set_{kind.__name__.lower()}"
    return set_


def guarded_access(cls: type) -> type:
    """Class decorator: add the guarded ``get_*``/``set_*`` methods ``cls`` lacks."""
    for kind, convert, default in _KINDS:
        name = kind.__name__
        if f"get_{name.lower()}" not in cls.__dict__:
            setattr(cls, f"get_{name.lower()}", _getter(kind, convert, default, f"get{name}"))
        if f"set_{name.lower()}" not in cls.__dict__:
            setattr(cls, f"set_{name.lower()}", _setter(kind, convert, f"set{name}"))
    return cls
