"""The controllers of a run: each law table of a scene validated once into a
:class:`ControllerSetting`.

A law table (``[controller]``, ``[top_drive_controller]``: the tables of the registered laws,
:data:`controller.registry.TABLES`) holds

* ``kind``: the law (:func:`controller.registry.kinds`; default the table's first law:
  ``"proportional"``, ``"pi"``);
* ``enabled``: whether the system has this controller (default false);
* the law's parameters: the fields of its ``PARAMS`` (``gain``, ``p_gain``, ...); a key of
  another law of the same table, inherited from a scene this one ``extends``, is not read (set
  as an override it is an error: it would change nothing);
* ``matrices``: a law with a resource file (``kind = "state_space"``): the file, relative to
  the scene file;
* ``fmu``: a controller FMU of any maker instead of the project's;
* ``[<table>.parameters]``: that FMU's own parameters, ``NAME = value`` (checked against its
  modelDescription before the first step, :mod:`.build`).

Only numpy-free checks happen here; whether a foreign FMU takes the keys is decided when the
system is built (it knows the FMU).
"""

from __future__ import annotations

import difflib
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import Any

from drillcosim.controller import Law, default_kind, kinds, law_named
from drillcosim.controller.state_space import load_state_space
from drillcosim.cosim.master.errors import UserError
from drillcosim.cosim.master.timegrid import integer_multiple

__all__ = ["EXTRA_KEYS", "ControllerSetting", "check_fmu_parameters", "law_keys",
           "parse_controller", "table_keys"]

#: Keys of a law table besides the law's parameters.
EXTRA_KEYS = ("kind", "enabled", "fmu", "matrices", "parameters")


class _Error(UserError):
    """A bad law table (raised as :class:`.config.ConfigError` by the caller's type)."""


@dataclass(frozen=True)
class ControllerSetting:
    """One controller of a run: a law table of the scene, validated.

    Attributes
    ----------
    instance : str
        The scene table = the system instance (``"controller"``, ``"top_drive_controller"``).
    kind : str
        The law (:func:`controller.registry.law_named`).
    params : object
        The law's validated parameters (its ``PARAMS``; a state-space law's matrices).
    enabled : bool
    set_keys : tuple of str
        The law's keys the table sets explicitly (file and overrides): a foreign FMU given
        for this instance is passed those of them it has.
    matrices : Path or None
        The resource file of a law that has one (``kind = "state_space"``).
    parameters : dict of str -> scalar
        A foreign FMU's own parameters (``[<table>.parameters]``), by variable name.
    """

    instance: str
    kind: str
    params: Any
    enabled: bool
    set_keys: tuple[str, ...] = ()
    matrices: Path | None = None
    parameters: dict[str, Any] = field(default_factory=dict)

    @property
    def law(self) -> type[Law]:
        """The law class."""
        return law_named(self.kind)

    def layout(self, n_sites: int) -> dict[str, Any]:
        """The interface the law needs for a plant of ``n_sites`` sites (``Law.layout_for``)."""
        return self.law.layout_for(self.params, n_sites)

    @property
    def switch_on_time(self) -> float | None:
        """When an enabled law with a switch-on time switches on [s]; None otherwise."""
        t = getattr(self.params, "switch_on_time", None)
        return float(t) if self.enabled and t is not None else None

    def record(self) -> dict[str, Any]:
        """The setting as JSON-ready data (``summary.json``): kind, enabled, the law's
        parameters (a resource file's name and shape instead of its numbers)."""
        out: dict[str, Any] = {"kind": self.kind, "enabled": self.enabled}
        if self.matrices is not None:
            p = self.params
            out.update({"matrices": str(self.matrices), "n_states": p.n_states,
                        "inputs": list(p.input_names), "outputs": list(p.output_names),
                        "sample_period": p.sample_period, "description": p.description})
        else:
            out.update({f: getattr(self.params, f) for f in law_keys(self.kind)})
        if self.parameters:
            out["parameters"] = dict(self.parameters)
        return out


def law_keys(kind: str) -> tuple[str, ...]:
    """The scene keys of law ``kind``: the fields of its parameters (none for a law whose
    parameters are a file's)."""
    params = law_named(kind).PARAMS
    return tuple(f.name for f in fields(params)) if hasattr(params, "__dataclass_fields__") \
        and not law_named(kind).RESOURCE else ()


def table_keys(table: str) -> list[str]:
    """Every key of law table ``table``: the keys of all its laws, then :data:`EXTRA_KEYS`."""
    keys: dict[str, None] = {}
    for kind in kinds(table):
        keys.update(dict.fromkeys(law_keys(kind)))
    keys.update(dict.fromkeys(EXTRA_KEYS))
    return list(keys)


def _suggest(word: str, choices: Sequence[str]) -> str:
    close = difflib.get_close_matches(word, list(choices), n=1)
    return f" (did you mean '{close[0]}'?)" if close else f"; allowed: {', '.join(choices)}"


def check_fmu_parameters(where: str, value: Any) -> dict[str, Any]:
    """``[<table>.parameters]``: a table of scalars (bool, int, float, str), by name."""
    if not isinstance(value, Mapping):
        raise _Error(f"{where} = {value!r} must be a table of NAME = value (a foreign FMU's own "
                     "parameters)")
    for name, v in value.items():
        if isinstance(v, Mapping) or not isinstance(v, (bool, int, float, str)):
            raise _Error(f"{where}.{name} = {v!r}: a parameter value is a number, a boolean or "
                         "a string")
    return dict(value)


def _matrices(where: str, table: Mapping[str, Any], source: str, period: float
              ) -> tuple[Path, Any]:
    """The resource file of ``table`` (relative to the scene file) and its parameters."""
    value = table.get("matrices")
    if not isinstance(value, str) or not value:
        raise _Error(f"{where} kind = \"state_space\" needs matrices = \"FILE.json\" (a "
                     f"controller.state_space JSON file, relative to the scene file), "
                     f"got {value!r}")
    path = Path(value).expanduser()
    if not path.is_absolute() and Path(source).is_file():
        path = Path(source).resolve().parent / path
    try:
        params = load_state_space(path)
    except ValueError as exc:
        raise _Error(f"{where} matrices: {exc}") from None
    ts = params.sample_period
    if integer_multiple(period, ts) is None:
        raise _Error(f"{where} matrices {path.name}: sample period {ts!r} s does not "
                     f"divide the controllers' period {period!r} s (cosim.step or "
                     "cosim.controller_sample_period): allowed a whole number of samples")
    return path, params


def parse_controller(name: str, table: Mapping[str, Any], source: str,
                     overrides: Mapping[str, Any], period: float) -> ControllerSetting:
    """The law table ``name`` of a scene, validated.

    Parameters
    ----------
    name : str
        The table (= instance).
    table : mapping
        Its keys (file and overrides merged).
    source : str
        The scene file (messages; a relative ``matrices`` path is relative to it).
    overrides : mapping
        The key-path overrides of the run (a key of another law set there is an error).
    period : float
        The controllers' sample period [s] (a state-space law's samples must divide it).

    Raises
    ------
    UserError
        One line naming the file or the override, the key and what is allowed.
    """
    where = f"{source}: [{name}]"
    choices = kinds(name)
    kind = table.get("kind", default_kind(name))
    if kind not in choices:
        raise _Error(f"{where} kind = {kind!r} is not allowed{_suggest(str(kind), choices)}")
    law = law_named(kind)
    own = law_keys(kind)
    every = table_keys(name)
    for key in table:
        if key not in every:
            raise _Error(f"{where} unknown key '{key}'{_suggest(key, [*own, *EXTRA_KEYS])}")
    foreign = sorted(p for p in overrides if p.split(".")[0] == name and
                     p.split(".")[1] not in (*own, *EXTRA_KEYS))
    if foreign:
        raise _Error(f"override {', '.join(foreign)}: not a key of a controller of kind = "
                     f"{kind!r}; allowed: {', '.join(f'{name}.{k}' for k in (*own, *EXTRA_KEYS))}")
    enabled = table.get("enabled", False)
    if not isinstance(enabled, bool):
        raise _Error(f"{where} enabled = {enabled!r} is not allowed; allowed: true or false")
    if "matrices" in table and not law.RESOURCE:
        raise _Error(f"{where} matrices applies to kind = \"state_space\" only")
    parameters = check_fmu_parameters(f"{where} parameters", table.get("parameters", {}))
    if law.RESOURCE:
        matrices, params = _matrices(where, table, source, period)
        return ControllerSetting(name, kind, params, enabled, (), matrices, parameters)
    given = {k: table[k] for k in own if k in table}
    if "enabled" in own:
        given["enabled"] = enabled
    try:
        params = law.PARAMS(**given)
    except (TypeError, ValueError) as exc:
        raise _Error(f"{where} {exc}") from None
    set_keys = tuple(k for k in own if k in table and k != "enabled")
    return ControllerSetting(name, kind, params, enabled, set_keys, None, parameters)

