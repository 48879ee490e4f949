"""The typed configuration of a run: a scene parsed and validated once.

:func:`load_config` reads a scene file (and the files it ``extends``), applies the overrides
and validates everything, once, into a :class:`SceneConfig`:

* ``scene`` - the plant's data (:class:`plant.scene.Scene`: parameters, model kind, outputs);
* ``controllers`` - per law table (``[controller]``, ``[top_drive_controller]``) the law's
  kind and typed parameters (:class:`.controllers.ControllerSetting`: ``[controller] kind =
  "..."`` picks a registered law, :mod:`controller.registry`; ``enabled`` false when the scene
  has none);
* ``cosim`` - the co-simulation settings (:class:`CosimSettings`): the base step [s], and the
  stop time, the controllers' period and the recording interval as integer numbers of base
  steps (decided here, by one rule: :func:`cosim.master.timegrid.grid_ticks`);
* ``fmu_files`` - FMU files a user chose for an instance (``[plant] fmu``, ...), and
  ``plant_parameters`` - a foreign plant FMU's own parameters (``[plant.parameters]``).

Below this module nothing reads a raw table: the builder (:mod:`.build`), the studies and the
API take a :class:`SceneConfig`.

Overrides
---------
One mechanism serves the command line's ``--set``, the API's keyword arguments, the sweeps
and the calibration: a mapping of *key paths* to values, ``{"cosim.actuator_delay": 2e-3,
"top_drive_controller.p_gain": 150.0, "gravity": 0.0}`` (nested mappings are accepted and
flattened: ``{"cosim": {"step": 1e-4}}`` is ``{"cosim.step": 1e-4}``). A key path names a
top-level scene key (``gravity``, ``model``, ``outputs``, ``description``, ``loads``) or
``<table>.<key>`` of a plant section (``pipe``, ``bit``, ...; :data:`plant.scene.SECTIONS`),
``plant.fmu``, ``controller.<key>``, ``top_drive_controller.<key>`` or ``cosim.<key>``
(:data:`COSIM_KEYS`), or ``<table>.parameters.<NAME>`` (``plant``, ``controller``,
``top_drive_controller``): a parameter of a foreign FMU of that instance, by its variable name.
An unknown key path, or a bad value, is a :class:`ConfigError`: one line naming the key and what
is allowed.
"""

from __future__ import annotations

import difflib
import math
import re
import sys
import zipfile
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, fields, replace
from pathlib import Path
from typing import Any

from drillcosim.controller import TABLES
from drillcosim.cosim.master.errors import UserError
from drillcosim.cosim.master.system import ALGORITHMS, COUPLINGS
from drillcosim.cosim.master.timegrid import grid_ticks, integer_multiple, seconds
from drillcosim.plant.scene import (
    PLANT_KEYS,
    SECTIONS,
    Scene,
    SceneError,
    read_scene_tables,
    scene_from_dict,
)
from drillcosim.plant.signals import CONTROLLER, PLANT, TOP_DRIVE

from .controllers import ControllerSetting, check_fmu_parameters, parse_controller, table_keys

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

__all__ = ["COSIM_KEYS", "ConfigError", "ControllerSetting", "CosimSettings", "SceneConfig",
           "derive_config", "key_paths", "load_config", "parse_set", "plant_parameter_paths",
           "split_assignment"]

#: ``[cosim]`` keys: (default, unit, meaning). ``None`` defaults are derived.
COSIM_KEYS: dict[str, tuple[Any, str, str]] = {
    "step": (1e-3, "s", "base communication step H, > 0"),
    "stop_time": (30.0, "s", "default stop time, > 0, an integer multiple of step"),
    "algorithm": ("jacobi", "-", "'jacobi' (parallel) or 'gauss_seidel' (sequential)"),
    "order": (None, "-", "Gauss-Seidel stepping order, a permutation of "
              "['plant', 'controller'] (and 'top_drive_controller' when enabled; default "
              "plant first)"),
    "coupling": ("zoh", "-", "'zoh' (hold) or 'linear' (extrapolation) on every connection"),
    "actuator_delay": (0.0, "s", "transport delay of the forces controller -> plant, >= 0 "
                       "(any value: between samples the delay line interpolates)"),
    "sensor_delay": (0.0, "s", "transport delay of the strains plant -> controller, >= 0"),
    "controller_sample_period": (None, "s", "the controllers' step, an integer multiple of "
                                 "step (default: step)"),
    "output_interval": (None, "s", "recording interval, an integer multiple of step "
                        "(default: the smallest multiple of step >= 1 ms)"),
}

#: Top-level scene keys that are plain values (the others are tables).
TOP_VALUES = tuple(k for k in PLANT_KEYS if k not in SECTIONS)


class ConfigError(UserError):
    """A scene, a key or a value that is not allowed: one line naming the file or the override,
    the key, and what is allowed.

    Attributes
    ----------
    given_as : str or None
        How the value blamed was given when not by the scene file: the name
        :func:`load_config` got for it in ``given_as`` (the API's keyword, e.g. ``stop_time``,
        ``overrides``, ``controller_fmu``), or ``override``. The message is then
        ``"<given_as>: <detail>"``; a command line names its own option with :attr:`detail`.
    detail : str
        The message without the ``given_as`` prefix (the whole message when None).
    """

    def __init__(self, message: str, given_as: str | None = None) -> None:
        super().__init__(f"{given_as}: {message}" if given_as else message)
        self.given_as = given_as
        self.detail = message


def _suggest(word: str, choices: Sequence[str]) -> str:
    close = difflib.get_close_matches(word, list(choices), n=1)
    return f" (did you mean '{close[0]}'?)" if close else f"; allowed: {', '.join(choices)}"


# -- key paths ---------------------------------------------------------------------------------
def _table_keys(table: str) -> list[str] | None:
    """Keys of scene table ``table`` (None: not a table)."""
    if table in SECTIONS:
        return [f.name for f in fields(SECTIONS[table])]
    if table in TABLES:
        return table_keys(table)
    if table == "cosim":
        return list(COSIM_KEYS)
    if table == "plant":
        return ["fmu", "parameters"]
    return None


def _tables() -> list[str]:
    return [*SECTIONS, "plant", *TABLES, "cosim"]


def check_key_path(path: str, where: str = "override") -> tuple[str, ...]:
    """``path`` split at its dots, if it names a scene key (module docstring), else
    :class:`ConfigError` naming it and what is allowed."""
    parts = tuple(path.split(".", 2)) if isinstance(path, str) else ()
    if len(parts) == 1 and parts[0] in TOP_VALUES:
        return parts
    if len(parts) == 3 and parts[0] in ("plant", *TABLES) and parts[1] == "parameters" \
            and parts[2]:
        return parts
    if len(parts) != 2 or not all(parts):
        allowed = [*TOP_VALUES, *(f"{t}.KEY" for t in _tables()),
                   *(f"{t}.parameters.NAME" for t in ("plant", *TABLES))]
        raise ConfigError(f"{where} {path!r}: not a key path; allowed: {', '.join(allowed)}")
    table, key = parts
    keys = _table_keys(table)
    if keys is None:
        raise ConfigError(f"{where} '{path}': unknown table '{table}'"
                          f"{_suggest(table, [*TOP_VALUES, *_tables()])}")
    if key not in keys:
        raise ConfigError(f"{where} '{path}': [{table}] unknown key '{key}'{_suggest(key, keys)}")
    return parts


def key_paths(overrides: Mapping[str, Any] | None) -> dict[str, Any]:
    """Overrides as ``{key path: value}``: nested mappings flattened (``{"cosim": {"step":
    1e-4}}`` -> ``{"cosim.step": 1e-4}``), every path checked (:func:`check_key_path`).

    Raises
    ------
    ConfigError
        An unknown key path (one line, with a suggestion).
    """
    flat: dict[str, Any] = {}

    def walk(prefix: str, node: Mapping[str, Any]) -> None:
        for key, value in node.items():
            path = f"{prefix}.{key}" if prefix else str(key)
            if isinstance(value, Mapping) and path.count(".") < 2:
                walk(path, value)
            else:
                flat[path] = value

    walk("", overrides or {})
    for path in flat:
        check_key_path(path)
    return flat


def _toml_value(text: str) -> Any:
    try:
        return tomllib.loads(f"v = {text}")["v"]
    except tomllib.TOMLDecodeError:
        return text  # a bare word: take it as a string (e.g. mode=compressive_only)


def parse_set(items: Sequence[str]) -> dict[str, Any]:
    """``["key.path=value", ...]`` (the command line's ``--set``) -> ``{key path: value}``,
    values parsed as TOML (a bare word is a string), every path checked.

    Raises
    ------
    ConfigError
        An item without ``=``, or an unknown key path.
    """
    out: dict[str, Any] = {}
    for item in items:
        key, text = split_assignment(item, "--set", "KEY=VALUE",
                                     "cosim.actuator_delay=0.002 (value in TOML syntax)")
        out[key] = _toml_value(text)
    return out


def split_assignment(item: str, flag: str, form: str, example: str) -> tuple[str, str]:
    """``"key.path=text"`` of a command-line option -> (checked key path, text), else
    :class:`ConfigError` naming the option, the form and an example."""
    key, sep, text = item.partition("=")
    key = key.strip()
    if not sep or not key:
        raise ConfigError(f"{flag} {item!r}: expected {form}, e.g. {example}")
    check_key_path(key, flag)
    return key, text.strip()


def plant_parameter_paths(overrides: Mapping[str, Any]) -> dict[str, Any]:
    """The overrides that set plant parameters (``gravity``, ``model`` and the plant sections'
    keys), e.g. to pass to a plant FMU as its parameters."""
    return {p: v for p, v in overrides.items()
            if p in ("gravity", "model") or p.split(".", 1)[0] in SECTIONS}


def _apply(data: dict[str, Any], overrides: Mapping[str, Any]) -> dict[str, Any]:
    out = {k: dict(v) if isinstance(v, dict) else v for k, v in data.items()}
    for path, value in overrides.items():
        parts = path.split(".", 2)
        node = out
        for depth, key in enumerate(parts[:-1]):
            inner = node.setdefault(key, {})
            if not isinstance(inner, dict):
                raise ConfigError(f"override '{path}': "
                                  f"[{'.'.join(parts[:depth + 1])}] of the scene is not a table")
            node[key] = inner = dict(inner)
            node = inner
        node[parts[-1]] = value
    return out


# -- the typed settings -------------------------------------------------------------------------
@dataclass(frozen=True)
class CosimSettings:
    """The co-simulation settings of a run (the ``[cosim]`` table, validated).

    Attributes
    ----------
    step : float
        Base communication step H [s].
    stop_ticks : int
        Default stop time in base steps.
    algorithm : {"jacobi", "gauss_seidel"}
    order : tuple of str
        Gauss-Seidel stepping order of ``plant``, ``controller`` (and
        ``top_drive_controller`` when enabled); the system steps the instances it has in it.
    coupling : {"zoh", "linear"}
    actuator_delay, sensor_delay : float
        Transport delays [s] of what the plant receives (forces, torque) and of what the
        controllers receive (strains, speeds); any value >= 0: the master's delay lines
        interpolate between the samples of the source.
    controller_ticks : int
        The controllers' period in base steps.
    output_ticks : int
        The recording interval in base steps.
    """

    step: float
    stop_ticks: int
    algorithm: str
    order: tuple[str, ...]
    coupling: str
    actuator_delay: float
    sensor_delay: float
    controller_ticks: int
    output_ticks: int

    def seconds(self, ticks: int) -> float:
        """``ticks`` base steps in seconds, as the master counts time (an exact rational
        product, rounded once: 120000 steps of 0.25 ms are 30.0 s)."""
        return seconds(ticks, self.step)

    @property
    def stop_time(self) -> float:
        """Default stop time [s]."""
        return self.seconds(self.stop_ticks)

    @property
    def output_interval(self) -> float:
        """Recording interval [s]."""
        return self.seconds(self.output_ticks)

    @property
    def controller_sample_period(self) -> float:
        """The controllers' period [s]."""
        return self.seconds(self.controller_ticks)

    def ticks(self, seconds: float, what: str) -> int:
        """``seconds`` [s] as a positive integer number of base steps, else
        :class:`ConfigError` naming ``what`` (the one rule: :func:`integer_multiple`)."""
        n = integer_multiple(seconds, self.step) if _finite_positive(seconds) else None
        if n is None:
            raise ConfigError(f"{what} = {seconds!r} s: must be a positive integer multiple of "
                              f"the step {self.step!r} s")
        return n

    def as_dict(self) -> dict[str, Any]:
        """Seconds and ticks, JSON-ready (``summary.json``)."""
        return {"step": self.step, "stop_time": self.stop_time, "algorithm": self.algorithm,
                "order": list(self.order), "coupling": self.coupling,
                "actuator_delay": self.actuator_delay, "sensor_delay": self.sensor_delay,
                "controller_sample_ticks": self.controller_ticks,
                "controller_sample_period": self.controller_sample_period,
                "output_ticks": self.output_ticks, "output_interval": self.output_interval}


def _finite_positive(x: Any) -> bool:
    return not isinstance(x, bool) and isinstance(x, (int, float)) and math.isfinite(x) and x > 0


@dataclass(frozen=True)
class _Source:
    """What a configuration was made of: the scene's tables (file and the files it extends,
    merged; before overrides), its file, and the FMU files given as arguments."""

    tables: dict[str, Any]
    path: Path
    plant_fmu: Path | None = None
    controller_fmu: Path | None = None
    #: how each override was given (key path -> name, :func:`load_config`'s ``given_as``)
    given: dict[str, str] = field(default_factory=dict)


@dataclass(frozen=True)
class SceneConfig:
    """A scene validated into typed settings: what :func:`.build.build_system` builds.

    Attributes
    ----------
    scene : plant.scene.Scene
        The plant's data.
    controllers : dict of str -> ControllerSetting
        Per law table (= instance, in the system's order: ``controller``,
        ``top_drive_controller``) the law and its parameters (``enabled`` false: none).
    cosim : CosimSettings
    fmu_files : dict of str -> Path
        FMU files a user chose, by instance (``[plant] fmu``, ``[controller] fmu``,
        ``[top_drive_controller] fmu`` or the ``plant_fmu`` / ``controller_fmu`` arguments);
        the others run the project's FMUs.
    overrides : dict of str -> value
        The key-path overrides applied on top of the scene file (:func:`key_paths`).
    plant_parameters : dict of str -> scalar
        A foreign plant FMU's own parameters (``[plant.parameters]``), by variable name.
    origin : object
        What it was made of (the scene's tables before overrides, its file, the FMU files
        given as arguments): :func:`cosim.scenario.config.derive_config` makes another configuration from it.
    """

    scene: Scene
    controllers: dict[str, ControllerSetting]
    cosim: CosimSettings
    fmu_files: dict[str, Path] = field(default_factory=dict)
    overrides: dict[str, Any] = field(default_factory=dict)
    plant_parameters: dict[str, Any] = field(default_factory=dict)
    origin: _Source | None = field(default=None, repr=False, compare=False)

    @property
    def name(self) -> str:
        """The scene's name."""
        return self.scene.name

    @property
    def source(self) -> str:
        """The scene's file."""
        return self.scene.source

    @property
    def controller(self) -> ControllerSetting:
        """The strain controller's setting (``[controller]``)."""
        return self.controllers[CONTROLLER]

    @property
    def top_drive(self) -> ControllerSetting:
        """The top-drive controller's setting (``[top_drive_controller]``)."""
        return self.controllers[TOP_DRIVE]

    @property
    def instances(self) -> tuple[str, ...]:
        """The system's instances: the plant, then each enabled controller."""
        return (PLANT, *(i for i, c in self.controllers.items() if c.enabled))

    @property
    def n_sites(self) -> int:
        """Actuator sites of the plant."""
        return len(self.scene.plant.actuator_joints)

    @property
    def switch_on_time(self) -> float | None:
        """When the enabled strain controller switches on [s] (None: none, or a law without a
        switch-on time)."""
        return self.controller.switch_on_time


def _number(where: str, value: Any, *, positive: bool) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise ConfigError(f"{where} = {value!r} must be a finite number [s]")
    if (value <= 0) if positive else (value < 0):
        raise ConfigError(f"{where} = {value!r} must be {'> 0' if positive else '>= 0'} [s]")
    return float(value)


def _cosim(table: Mapping[str, Any], instances: Sequence[str], source: str) -> CosimSettings:
    where = f"{source}: [cosim]"
    for key in table:
        if key not in COSIM_KEYS:
            raise ConfigError(f"{where} unknown key '{key}'{_suggest(key, list(COSIM_KEYS))}")
    get = table.get
    step = _number(f"{where} step", get("step", COSIM_KEYS["step"][0]), positive=True)
    for key, choices in (("algorithm", ALGORITHMS), ("coupling", COUPLINGS)):
        value = get(key, COSIM_KEYS[key][0])
        if value not in choices:
            raise ConfigError(f"{where} {key} = {value!r} is not allowed"
                              f"{_suggest(str(value), choices)}")
    names = [PLANT, CONTROLLER] + ([TOP_DRIVE] if TOP_DRIVE in instances else [])
    order = get("order", names)
    if not isinstance(order, (list, tuple)) or sorted(order) != sorted(names):
        raise ConfigError(f"{where} order = {order!r} must be a permutation of {names}")
    delays = {k: _number(f"{where} {k}", get(k, 0.0), positive=False)
              for k in ("actuator_delay", "sensor_delay")}
    partial = CosimSettings(step, 1, get("algorithm", "jacobi"), tuple(order),
                            get("coupling", "zoh"),
                            delays["actuator_delay"], delays["sensor_delay"], 1, 1)
    stop = _number(f"{where} stop_time", get("stop_time", COSIM_KEYS["stop_time"][0]),
                   positive=True)
    stop_ticks = partial.ticks(stop, f"{where} stop_time")
    period = _number(f"{where} controller_sample_period",
                     get("controller_sample_period", step), positive=True)
    controller_ticks = partial.ticks(period, f"{where} controller_sample_period")
    if "output_interval" in table:
        interval = _number(f"{where} output_interval", table["output_interval"], positive=True)
        output_ticks = partial.ticks(interval, f"{where} output_interval")
    else:
        # the fewest steps that span 1 ms (exactly 1 ms where it is on the grid)
        output_ticks = max(1, grid_ticks(1e-3, step) or math.ceil(1e-3 / step))
    return CosimSettings(step, stop_ticks, partial.algorithm, partial.order, partial.coupling,
                         partial.actuator_delay, partial.sensor_delay, controller_ticks,
                         output_ticks)


def _not_an_fmu(path: Path) -> str | None:
    """Why the file ``path`` is not an FMU (None: a zip archive with a ``modelDescription.xml``;
    its content is read when the system is built)."""
    if not zipfile.is_zipfile(path):
        return "not an FMU (an FMU is a zip archive with a modelDescription.xml)"
    with zipfile.ZipFile(path) as archive:
        if "modelDescription.xml" not in archive.namelist():
            return "not an FMU: the zip archive has no modelDescription.xml"
    return None


def _fmu_file(table_name: str, table: Mapping[str, Any], source: str) -> Path | None:
    if "fmu" not in table:
        return None
    value = table["fmu"]
    if not isinstance(value, str) or not value:
        raise ConfigError(f"{source}: [{table_name}] fmu = {value!r} must be the path of an "
                          ".fmu file")
    path = Path(value).expanduser()
    src = Path(source)
    if not path.is_absolute() and src.is_file():
        path = src.resolve().parent / path
    if not path.is_file():
        raise ConfigError(f"{source}: [{table_name}] fmu = {value!r}: no file '{path}'")
    if (why := _not_an_fmu(path)) is not None:
        raise ConfigError(f"{source}: [{table_name}] fmu = {value!r}: {why}")
    return path


def load_config(scene: str | Path = "paper_closed_loop",
                overrides: Mapping[str, Any] | None = None, *,
                plant_fmu: str | Path | None = None, controller_fmu: str | Path | None = None,
                folder: Path | None = None,
                given_as: Mapping[str, str] | None = None) -> SceneConfig:
    """Read a scene, apply overrides, validate everything once.

    Parameters
    ----------
    scene : str or path
        A shipped scene's name (``scenes/<name>.toml``) or a scene file.
    overrides : mapping, optional
        Key paths -> values (module docstring), applied over the file.
    plant_fmu, controller_fmu : path-like, optional
        FMU files (any maker) for the plant / the strain controller instead of the project's;
        they take precedence over the scene's ``[plant] fmu`` / ``[controller] fmu``.
    folder : Path, optional
        Where scene names are looked up (default: the shipped scenes).
    given_as : mapping, optional
        How each override was given (key path -> name, e.g. ``{"cosim.stop_time":
        "stop_time"}``; ``plant.fmu`` / ``controller.fmu`` for ``plant_fmu`` /
        ``controller_fmu``): an error about an overridden value names it so (default:
        ``override``, ``plant_fmu``, ``controller_fmu``), not the scene file.

    Returns
    -------
    SceneConfig

    Raises
    ------
    ConfigError
        Any bad input, one line naming the file or override, the key and what is allowed.
    """
    over = key_paths(overrides)
    given = {"plant.fmu": "plant_fmu", "controller.fmu": "controller_fmu",
             **{p: "override" for p in over}, **(given_as or {})}
    try:
        data, path = read_scene_tables(scene, folder)
    except SceneError as exc:
        raise ConfigError(str(exc)) from None
    return _from_tables(_Source(data, path, _fmu_arg(plant_fmu), _fmu_arg(controller_fmu),
                                given), over)


def derive_config(base: SceneConfig, overrides: Mapping[str, Any], *,
                  controller_fmu: bool = True) -> SceneConfig:
    """``base`` with more key-path overrides (they win over ``base.overrides``): the typed
    configuration of a sweep point, made from the scene tables ``base`` was made of (no file
    is read again), every new value validated here, once. Where the overrides touch only the
    co-simulation and the law tables (and leave the strain controller on or off as in
    ``base``, which the plant model's choice reads), the point keeps ``base.scene``, the plant
    validated once for the whole sweep; the loop settings and laws are made anew and checked
    against it. ``controller_fmu=False`` leaves out the controller FMU given as an argument
    (an open-loop reference runs without it).

    Raises
    ------
    ConfigError
        An unknown key path or a bad value (one line).
    """
    origin = base.origin if controller_fmu else replace(base.origin, controller_fmu=None)
    new = key_paths(overrides)
    over = {**base.overrides, **new}
    loop_only = all(p.split(".", 1)[0] in ("cosim", *TABLES) for p in new)
    enabled = new.get(f"{CONTROLLER}.enabled", base.controller.enabled)
    if loop_only and enabled is base.controller.enabled:
        return _from_tables(origin, over, scene=base.scene)
    return _from_tables(origin, over)


def _fmu_arg(path: str | Path | None) -> Path | None:
    return None if not path else Path(path)


def _from_tables(origin: _Source, over: dict[str, Any], scene: Scene | None = None
                 ) -> SceneConfig:
    """The configuration of the scene tables ``origin.tables`` with the overrides ``over``
    (``scene``: the plant of these tables, made already)."""
    source = str(origin.path)
    given = {**{p: "override" for p in over}, **origin.given}
    try:
        data = _apply(origin.tables, over)
        if scene is None:
            scene = scene_from_dict(data, name=origin.path.stem, source=source)
        return _validate(data, scene, over, origin, given)
    except ConfigError as exc:
        if exc.given_as:  # named already
            raise
        raise _name_override(str(exc), source, over, given) from None
    except SceneError as exc:
        raise _name_override(str(exc), source, over, given) from None


#: ``[table] key`` or ``table.key`` / ``key`` followed by `` = ``: the key a message blames
_BLAMED = re.compile(r"\[(\w+)\] (\w+)\b|(\w+(?:\.\w+)?) =")


def _name_override(message: str, source: str, over: Mapping[str, Any],
                   given: Mapping[str, str]) -> ConfigError:
    """The error of ``message``; one that blames the scene file ``source`` for a key whose
    value is an override names how the override was given instead (``given``)."""
    prefix = f"{source}: "
    match = _BLAMED.match(message, len(prefix)) if message.startswith(prefix) else None
    if match is None:
        return ConfigError(message)
    path = f"{match[1]}.{match[2]}" if match[1] else match[3]
    if path not in over:
        return ConfigError(message)
    return ConfigError(f"{path}{message[match.end(2 if match[1] else 3):]}", given[path])


def _validate(data: dict[str, Any], sc: Scene, over: Mapping[str, Any], origin: _Source,
              given: Mapping[str, str]) -> SceneConfig:
    """The typed configuration of the scene ``sc`` (its tables ``data``, overrides applied)."""
    source = sc.source
    plant_fmu, controller_fmu = origin.plant_fmu, origin.controller_fmu
    tables = {key: data.get(key, {}) for key in ("plant", *TABLES, "cosim")}
    for key in tables["plant"]:
        if key not in ("fmu", "parameters"):
            raise ConfigError(f"{source}: [plant] unknown key '{key}'; allowed: fmu, parameters "
                              "(a foreign plant FMU's own parameters; the plant's parameters are "
                              "top-level tables)")
    enabled = [t for t in TABLES if tables[t].get("enabled", False) is True]
    cosim = _cosim(tables["cosim"], (PLANT, *enabled), source)
    try:
        plant_parameters = check_fmu_parameters(f"{source}: [plant] parameters",
                                                tables["plant"].get("parameters", {}))
        controllers = {t: parse_controller(t, tables[t], source, over,
                                           cosim.controller_sample_period) for t in TABLES}
    except UserError as exc:
        raise ConfigError(str(exc)) from None
    ctrl, drive = controllers[CONTROLLER], controllers[TOP_DRIVE]
    n_sites = len(sc.plant.actuator_joints)
    matrix = getattr(ctrl.params, "gain_matrix", ())
    if matrix and len(matrix) != n_sites:
        size = len(matrix)
        raise ConfigError(f"{source}: [controller] gain_matrix is {size} x {size}; the scene "
                          f"has {n_sites} actuator sites: allowed an {n_sites} x {n_sites} matrix")
    if ctrl.enabled and sc.model != "full3d":
        raise ConfigError(f"{source}: the controller needs model = 'full3d', got '{sc.model}'")
    mode = sc.plant.top_drive.mode
    if drive.enabled and mode != "torque":
        raise ConfigError(f"{source}: [top_drive_controller] drives the motor torque of a top "
                          f"drive in mode 'torque', but top_drive.mode = {mode!r}: set "
                          "[top_drive] mode = \"torque\" and inertia")
    if ctrl.matrices is not None and (controller_fmu or "fmu" in tables[CONTROLLER]):
        raise ConfigError(f"{source}: [controller] kind = \"state_space\" runs the matrices in "
                          "a StateSpaceController FMU built for the scene: a controller FMU "
                          "file cannot be given too")
    if controller_fmu and not ctrl.enabled:
        raise ConfigError(f"{source}: a controller FMU was given ({controller_fmu}) but the "
                          "scene's controller is off: set controller.enabled=true")
    instances = (PLANT, *enabled)
    files: dict[str, Path] = {}
    for instance, fmu in ((PLANT, plant_fmu), (CONTROLLER, controller_fmu), (TOP_DRIVE, None)):
        if instance not in instances:
            continue
        if fmu:
            name = given[f"{instance}.fmu"]
            if not Path(fmu).is_file():
                raise ConfigError(f"no file '{fmu}'", name)
            if (why := _not_an_fmu(Path(fmu))) is not None:
                raise ConfigError(f"'{fmu}' is {why}", name)
            files[instance] = Path(fmu)
        elif (chosen := _fmu_file(instance, tables[instance], source)) is not None:
            files[instance] = chosen
    for instance, setting in ((PLANT, plant_parameters), *((t, c.parameters)
                                                          for t, c in controllers.items())):
        if setting and instance in instances and instance not in files:
            raise ConfigError(f"{source}: [{instance}.parameters] sets a foreign FMU's own "
                              f"parameters, but [{instance}] names no fmu: give one ([{instance}] "
                              f"fmu or --{'plant' if instance == PLANT else 'controller'}-fmu)")
    return SceneConfig(sc, controllers, cosim, files, over, plant_parameters, origin)
