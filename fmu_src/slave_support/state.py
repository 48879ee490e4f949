"""The FMU state of our pythonfmu adapters: what it holds and how it is restored, all or nothing.

The rules (docs/reliability.md, "FMU state and call order"; the C controller follows the same):

* **What a state is.** ``{"variables": {name: value}, "internal": {...}}``: the value of every
  registered variable (inputs, outputs, parameters) and what the adapter keeps besides them
  (:meth:`DcsSlave._internal_state`: the plant's simulator state, a controller law's state),
  JSON-safe Python scalars and lists, so that serialization is exact. Its payload (UTF-8 JSON,
  :func:`encode`) is sealed by the wrapper with the FMU's identity, the phase it was taken in and
  a SHA-256 (``fmu_src/wrapper/dcs_state.c``, format in ``fmu_src/state_format.py``); the wrapper
  refuses a damaged, foreign or other-build state, and one of another phase, before Python sees
  it.
* **Checked as a parameter set would be.** :func:`restore` checks the shape (exactly the
  registered variables, each of its type; the internal part the adapter expects), writes the
  variables, then lets the adapter check the rest (:meth:`DcsSlave._restore_internal`: after
  initialization the parameters must pass the checks of ``fmi2ExitInitializationMode``; arrays
  must fit the model they are for) and apply it only once every check has passed.
* **All or nothing.** A refused state (or an exception while restoring) writes the variables'
  old values back; the adapter changed nothing else. The refusal is one line through the logger
  and fmi2Error (``DcsSlave._set_fmu_state``); the instance stays usable.
"""

from __future__ import annotations

import json
import math
from typing import Any

from _dcs_pythonfmu_0_7_0 import Boolean, Integer, Real, String

__all__ = ["capture", "decode", "encode", "number_problem", "restore"]

VARIABLES, INTERNAL = "variables", "internal"

#: variable class -> (test of a value of that type, what is allowed)
_TYPES: dict[type, tuple[Any, str]] = {
    Real: (lambda v: isinstance(v, (int, float)) and not isinstance(v, bool), "a number"),
    Integer: (lambda v: isinstance(v, int) and not isinstance(v, bool), "an integer"),
    Boolean: (lambda v: isinstance(v, bool), "true or false"),
    String: (lambda v: isinstance(v, str), "a string"),
}


def encode(state: dict[str, Any]) -> bytes:
    """The payload of a state (compact UTF-8 JSON; floats round-trip exactly)."""
    return json.dumps(state, separators=(",", ":")).encode("utf-8")


def decode(payload: bytes) -> dict[str, Any]:
    """A state from its payload.

    Raises
    ------
    ValueError
        One line: the payload is not a JSON object.
    """
    try:
        state = json.loads(payload.decode("utf-8"))
    except (UnicodeDecodeError, ValueError) as exc:
        raise ValueError(f"its payload is not JSON ({exc})") from None
    if not isinstance(state, dict):
        raise ValueError(f"its payload is a JSON {type(state).__name__}, not an object")
    return state


def capture(slave: Any) -> dict[str, Any]:
    """The state of ``slave`` (a ``DcsSlave``): its variables and its internal part."""
    return {VARIABLES: {var.name: var.getter() for var in slave.vars.values()},
            INTERNAL: slave._internal_state()}


def number_problem(name: str, value: Any, finite: bool = True) -> str | None:
    """Why ``value`` is not a (finite) number, or None."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        return f"{name} = {value!r} is not a number"
    if finite and not math.isfinite(value):
        return f"{name} = {value!r} is not finite"
    return None


def _shape_problem(slave: Any, state: Any) -> str | None:
    """Why ``state`` is not shaped as a state of ``slave``, or None."""
    if not isinstance(state, dict) or set(state) != {VARIABLES, INTERNAL}:
        keys = sorted(state) if isinstance(state, dict) else type(state).__name__
        return f"not a state of this FMU (keys {keys}; expected {VARIABLES!r}, {INTERNAL!r})"
    values, internal = state[VARIABLES], state[INTERNAL]
    if not isinstance(values, dict) or not isinstance(internal, dict):
        return "not a state of this FMU (its variables or internal part is not an object)"
    names = {var.name for var in slave.vars.values()}
    missing, unknown = sorted(names - set(values)), sorted(set(values) - names)
    if missing or unknown:
        return (f"its variables do not match this FMU's (missing {missing[:5]}, unknown "
                f"{unknown[:5]})")
    for var in slave.vars.values():
        test, allowed = next(t for cls, t in _TYPES.items() if isinstance(var, cls))
        if not test(values[var.name]):
            return f"{var.name} = {values[var.name]!r} is not {allowed}"
    return None


def _write(slave: Any, values: dict[str, Any]) -> None:
    for var in slave.vars.values():
        if var.setter is not None:
            var.setter(values[var.name])


def restore(slave: Any, state: Any) -> str | None:
    """Restore ``state`` into ``slave``, all or nothing; why it was refused, or None.

    An exception from the adapter (a bug) is raised again after the variables were written
    back (the wrapper logs its traceback as fmi2Error).
    """
    problem = _shape_problem(slave, state)
    if problem is not None:
        return problem
    before = {var.name: var.getter() for var in slave.vars.values()}
    try:
        _write(slave, state[VARIABLES])
        problem = slave._restore_internal(state[INTERNAL])
    except BaseException:
        _write(slave, before)
        raise
    if problem is not None:
        _write(slave, before)
    return problem
