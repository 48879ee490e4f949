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

__all__ = ["capture", "decode", "encode", "number_problem", "numbers_problem", "restore"]

VARIABLES, INTERNAL = "variables", "internal"

#: variable class -> (the exact Python types a value of it may have, what is allowed); JSON
#: decodes to exactly these (a bool is not an int here)
_TYPES: dict[type, tuple[tuple[type, ...], str]] = {
    Real: ((float, int), "a number"), Integer: ((int,), "an integer"),
    Boolean: ((bool,), "true or false"), String: ((str,), "a string")}


def _table(slave: Any) -> list[tuple[str, Any, Any, tuple[type, ...], str]]:
    """(name, getter, setter, allowed types, what is allowed) of every registered variable, made
    once per instance (the variables are registered in its constructor)."""
    table = slave.__dict__.get("_dcs_state_table")
    if table is None:
        table = [(var.name, var.getter, var.setter,
                  *next(t for cls, t in _TYPES.items() if isinstance(var, cls)))
                 for var in slave.vars.values()]
        slave._dcs_state_table = table
    return table


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
    return {VARIABLES: {name: get() for name, get, *_ in _table(slave)},
            INTERNAL: slave._internal_state()}


def number_problem(name: str, value: Any, finite: bool = True) -> str | None:
    """Why ``value`` is not a (finite) number, or None."""
    if type(value) not in (float, int):
        return f"{name} = {value!r} is not a number"
    if finite and not math.isfinite(value):
        return f"{name} = {value!r} is not finite"
    return None


def numbers_problem(name: str, values: list, finite: bool = True) -> str | None:
    """Why the list ``values`` does not hold only (finite) numbers (naming the first entry that
    is not one, ``name[i]``), or None. Loops in C: a state holds thousands of them."""
    if set(map(type, values)) <= {float, int} and (not finite or all(map(math.isfinite, values))):
        return None
    return next(p for p in (number_problem(f"{name}[{i}]", v, finite)
                            for i, v in enumerate(values)) if p)


def _shape_problem(slave: Any, state: Any) -> str | None:
    """Why ``state`` is not shaped as a state of ``slave``, or None."""
    if not isinstance(state, dict) or set(state) != {VARIABLES, INTERNAL}:
        keys = sorted(state) if isinstance(state, dict) else type(state).__name__
        return f"not a state of this FMU (keys {keys}; expected {VARIABLES!r}, {INTERNAL!r})"
    values, internal = state[VARIABLES], state[INTERNAL]
    if not isinstance(values, dict) or not isinstance(internal, dict):
        return "not a state of this FMU (its variables or internal part is not an object)"
    table = _table(slave)
    if len(values) != len(table) or any(name not in values for name, *_ in table):
        names = {name for name, *_ in table}
        missing, unknown = sorted(names - set(values)), sorted(set(values) - names)
        return (f"its variables do not match this FMU's (missing {missing[:5]}, unknown "
                f"{unknown[:5]})")
    for name, _get, _set, types, allowed in table:
        if type(values[name]) not in types:
            return f"{name} = {values[name]!r} is not {allowed}"
    return None


def _write(slave: Any, values: dict[str, Any]) -> None:
    for name, _get, setter, *_ in _table(slave):
        if setter is not None:
            setter(values[name])


def restore(slave: Any, state: Any) -> str | None:
    """Restore ``state`` into ``slave``, all or nothing; why it was refused, or None.

    An exception from the adapter (a bug) is raised again after the variables were written
    back (the wrapper logs its traceback as fmi2Error).
    """
    problem = _shape_problem(slave, state)
    if problem is not None:
        return problem
    before = {name: get() for name, get, *_ in _table(slave)}
    try:
        _write(slave, state[VARIABLES])
        problem = slave._restore_internal(state[INTERNAL])
    except BaseException:
        _write(slave, before)
        raise
    if problem is not None:
        _write(slave, before)
    return problem
