"""The typed configuration of a run: a scene parsed and validated once.

:func:`load_config` reads a scene file (and the files it ``extends``), applies the overrides
and validates everything, once, into a :class:`SceneConfig`:

* ``scene`` - the plant's data (:class:`plant.scene.Scene`: parameters, model kind, outputs);
* ``controller`` / ``top_drive`` - the controllers' typed parameters
  (:class:`controller.ControllerParams`, :class:`controller.TopDriveControllerParams`;
  ``enabled`` false when the scene has none);
* ``state_space`` - with ``[controller] kind = "state_space"``, the strain controller is a
  discrete state-space law (:class:`StateSpaceSetting`: the matrices file, validated into
  :class:`controller.StateSpaceParams`) instead of the P law;
* ``cosim`` - the co-simulation settings (:class:`CosimSettings`): the base step [s], and the
  stop time, the controllers' period and the recording interval as integer numbers of base
  steps (decided here, by one rule: :func:`cosim.master.system.integer_multiple`);
* ``fmu_files`` - FMU files a user chose for an instance (``[plant] fmu``, ...).

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
(:data:`COSIM_KEYS`). An unknown key path, or a bad value, is a :class:`ConfigError`: one line
naming the key and what is allowed.
"""

from __future__ import annotations

import difflib
import math
import re
import sys
import zipfile
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, fields
from fractions import Fraction
from pathlib import Path
from typing import Any

from drillcosim.controller import ControllerParams, TopDriveControllerParams
from drillcosim.controller.state_space import (
    MULTIPLE_RTOL,
    StateSpaceParams,
    load_state_space,
)
from drillcosim.cosim.master.errors import UserError
from drillcosim.cosim.master.system import ALGORITHMS, COUPLINGS, integer_multiple
from drillcosim.plant.scene import (
    PLANT_KEYS,
    SECTIONS,
    Scene,
    SceneError,
    read_scene_tables,
    scene_from_dict,
)
from drillcosim.plant.signals import CONTROLLER, PLANT, TOP_DRIVE

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

__all__ = ["CONTROLLER_KINDS", "COSIM_KEYS", "ConfigError", "CosimSettings", "SceneConfig",
           "StateSpaceSetting", "key_paths", "load_config", "parse_set",
           "plant_parameter_paths"]

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

#: The controller tables: scene table -> (instance, typed parameters).
CONTROLLER_TABLES: dict[str, tuple[str, type]] = {
    "controller": (CONTROLLER, ControllerParams),
    "top_drive_controller": (TOP_DRIVE, TopDriveControllerParams),
}
#: ``[controller] kind``: the P law (:class:`controller.ControllerParams`), or a discrete
#: state-space law from a matrices file (``matrices``; :class:`StateSpaceSetting`).
CONTROLLER_KINDS = ("proportional", "state_space")
#: ``[controller]`` keys besides the P law's parameters.
_CONTROLLER_EXTRA = ("kind", "matrices", "fmu")
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
    if table in CONTROLLER_TABLES:
        extra = _CONTROLLER_EXTRA if table == "controller" else ("fmu",)
        return [f.name for f in fields(CONTROLLER_TABLES[table][1])] + list(extra)
    if table == "cosim":
        return list(COSIM_KEYS)
    if table == "plant":
        return ["fmu"]
    return None


def _tables() -> list[str]:
    return [*SECTIONS, "plant", *CONTROLLER_TABLES, "cosim"]


def check_key_path(path: str, where: str = "override") -> tuple[str, ...]:
    """``path`` split at its dot, if it names a scene key (module docstring), else
    :class:`ConfigError` naming it and what is allowed."""
    parts = tuple(path.split(".")) if isinstance(path, str) else ()
    if len(parts) == 1 and parts[0] in TOP_VALUES:
        return parts
    if len(parts) != 2 or not all(parts):
        allowed = [*TOP_VALUES, *(f"{t}.KEY" for t in _tables())]
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
            if isinstance(value, Mapping):
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
        key, sep, text = item.partition("=")
        key = key.strip()
        if not sep or not key:
            raise ConfigError(f"--set {item!r}: expected KEY=VALUE, e.g. "
                              "cosim.actuator_delay=0.002 (value in TOML syntax)")
        check_key_path(key, "--set")
        out[key] = _toml_value(text.strip())
    return out


def plant_parameter_paths(overrides: Mapping[str, Any]) -> dict[str, Any]:
    """The overrides that set plant parameters (``gravity``, ``model`` and the plant sections'
    keys), e.g. to pass to a plant FMU as its parameters."""
    return {p: v for p, v in overrides.items()
            if p in ("gravity", "model") or p.split(".", 1)[0] in SECTIONS}


def _apply(data: dict[str, Any], overrides: Mapping[str, Any]) -> dict[str, Any]:
    out = {k: dict(v) if isinstance(v, dict) else v for k, v in data.items()}
    for path, value in overrides.items():
        parts = path.split(".")
        if len(parts) == 1:
            out[path] = value
        else:
            table = out.setdefault(parts[0], {})
            if not isinstance(table, dict):
                raise ConfigError(f"override '{path}': [{parts[0]}] of the scene is not a table")
            table[parts[1]] = value
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
        frac = Fraction(self.step).limit_denominator(10**12)
        if float(frac) != self.step:
            frac = Fraction(self.step)
        return float(frac * ticks)

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
class StateSpaceSetting:
    """The strain controller as a discrete state-space law (``[controller] kind =
    "state_space"``).

    Attributes
    ----------
    file : Path
        The matrices file (``[controller] matrices``, :mod:`controller.state_space` JSON).
    params : StateSpaceParams
        Its matrices, signals (names and units: checked against the plant when the system is
        built), output limits and sample period (the controllers' period is a whole number of
        them).
    """

    file: Path
    params: StateSpaceParams


@dataclass(frozen=True)
class SceneConfig:
    """A scene validated into typed settings: what :func:`.build.build_system` builds.

    Attributes
    ----------
    scene : plant.scene.Scene
        The plant's data.
    controller : controller.ControllerParams
        The strain controller (``enabled`` false: none).
    top_drive : controller.TopDriveControllerParams
        The top-drive speed controller (``enabled`` false: none).
    cosim : CosimSettings
    fmu_files : dict of str -> Path
        FMU files a user chose, by instance (``[plant] fmu``, ``[controller] fmu``,
        ``[top_drive_controller] fmu`` or the ``plant_fmu`` / ``controller_fmu`` arguments);
        the others run the project's FMUs.
    overrides : dict of str -> value
        The key-path overrides applied on top of the scene file (:func:`key_paths`).
    set_keys : dict of str -> tuple of str
        Per controller instance, the keys its table sets explicitly (file and overrides): a
        foreign FMU must take those.
    state_space : StateSpaceSetting or None
        The strain controller's state-space law (``[controller] kind = "state_space"``); None:
        the P law of ``controller``.
    """

    scene: Scene
    controller: ControllerParams
    top_drive: TopDriveControllerParams
    cosim: CosimSettings
    fmu_files: dict[str, Path] = field(default_factory=dict)
    overrides: dict[str, Any] = field(default_factory=dict)
    set_keys: dict[str, tuple[str, ...]] = field(default_factory=dict)
    state_space: StateSpaceSetting | None = None

    @property
    def name(self) -> str:
        """The scene's name."""
        return self.scene.name

    @property
    def source(self) -> str:
        """The scene's file."""
        return self.scene.source

    @property
    def instances(self) -> tuple[str, ...]:
        """The system's instances: the plant, then each enabled controller."""
        return (PLANT, *((CONTROLLER,) if self.controller.enabled else ()),
                *((TOP_DRIVE,) if self.top_drive.enabled else ()))

    @property
    def n_sites(self) -> int:
        """Actuator sites of the plant."""
        return len(self.scene.plant.actuator_joints)


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
        output_ticks = max(1, math.ceil(1e-3 / step - 1e-9))
    return CosimSettings(step, stop_ticks, partial.algorithm, partial.order, partial.coupling,
                         partial.actuator_delay, partial.sensor_delay, controller_ticks,
                         output_ticks)


def _params(table_name: str, table: Mapping[str, Any], source: str) -> Any:
    cls = CONTROLLER_TABLES[table_name][1]
    names = [f.name for f in fields(cls)]
    for key in table:
        extra = _CONTROLLER_EXTRA if table_name == "controller" else ("fmu",)
        if key not in names and key not in extra:
            raise ConfigError(f"{source}: [{table_name}] unknown key '{key}'"
                              f"{_suggest(key, [*names, *extra])}")
    raw = {"enabled": False, **{k: v for k, v in table.items() if k not in _CONTROLLER_EXTRA}}
    try:
        return cls(**raw)
    except (TypeError, ValueError) as exc:
        raise ConfigError(f"{source}: [{table_name}] {exc}") from None


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


def _state_space(table: Mapping[str, Any], cosim: CosimSettings, source: str,
                 overrides: Mapping[str, Any]) -> StateSpaceSetting | None:
    """The ``[controller]`` table's state-space law (None: ``kind = "proportional"``).

    With ``kind = "state_space"`` the P law's keys are not read: a scene may extend a P-law
    scene (its inherited ``gain``, ``mode`` ... do not apply); set as overrides they are an
    error (a sweep of ``controller.gain`` over a state-space scene changes nothing)."""
    where = f"{source}: [controller]"
    kind = table.get("kind", CONTROLLER_KINDS[0])
    if kind not in CONTROLLER_KINDS:
        raise ConfigError(f"{where} kind = {kind!r} is not allowed"
                          f"{_suggest(str(kind), CONTROLLER_KINDS)}")
    if kind == "proportional":
        if "matrices" in table:
            raise ConfigError(f"{where} matrices applies to kind = \"state_space\" only")
        return None
    p_law = sorted(p for p in overrides if p.startswith("controller.")
                   and p.split(".", 1)[1] not in ("enabled", *_CONTROLLER_EXTRA))
    if p_law:
        raise ConfigError(f"override {', '.join(p_law)}: not a key of a controller of kind = "
                          "\"state_space\"; allowed: controller.enabled, controller.kind, "
                          "controller.matrices (limits and sample period are in the matrices "
                          "file)")
    value = table.get("matrices")
    if not isinstance(value, str) or not value:
        raise ConfigError(f"{where} kind = \"state_space\" needs matrices = \"FILE.json\" (a "
                          f"controller.state_space JSON file, relative to the scene file), "
                          f"got {value!r}")
    path = Path(value).expanduser()
    if not path.is_absolute() and Path(source).is_file():
        path = Path(source).resolve().parent / path
    try:
        params = load_state_space(path)
    except ValueError as exc:
        raise ConfigError(f"{where} matrices: {exc}") from None
    period, ts = cosim.controller_sample_period, params.sample_period
    k = period / ts
    if abs(k - round(k)) > MULTIPLE_RTOL * max(1.0, k) or round(k) < 1:
        raise ConfigError(f"{where} matrices {path.name}: sample period {ts!r} s does not "
                          f"divide the controllers' period {period!r} s (cosim.step or "
                          "cosim.controller_sample_period): allowed a whole number of samples")
    return StateSpaceSetting(path, params)


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
    source = str(scene)
    try:
        data, path = read_scene_tables(scene, folder)
        source = str(path)
        data = _apply(data, over)
        return _validate(data, scene_from_dict(data, name=path.stem, source=source), over,
                         plant_fmu, controller_fmu, given)
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


def _validate(data: dict[str, Any], sc: Scene, over: Mapping[str, Any],
              plant_fmu: str | Path | None, controller_fmu: str | Path | None,
              given: Mapping[str, str]) -> SceneConfig:
    """The typed configuration of the scene ``sc`` (its tables ``data``, overrides applied)."""
    source = sc.source
    tables = {}
    for key in ("plant", *CONTROLLER_TABLES, "cosim"):
        tables[key] = data.get(key, {})
    for key in tables["plant"]:
        if key != "fmu":
            raise ConfigError(f"{source}: [plant] unknown key '{key}'; allowed: fmu (the "
                              "plant's own parameters are top-level tables)")
    ctrl_table = tables["controller"]
    if ctrl_table.get("kind") == "state_space":  # the P law's keys are not read (_state_space)
        ctrl_table = {k: v for k, v in ctrl_table.items() if k in ("enabled", "fmu")}
    controller = _params("controller", ctrl_table, source)
    top_drive = _params("top_drive_controller", tables["top_drive_controller"], source)
    n_sites = len(sc.plant.actuator_joints)
    if controller.gain_matrix and len(controller.gain_matrix) != n_sites:
        size = len(controller.gain_matrix)
        raise ConfigError(f"{source}: [controller] gain_matrix is {size} x {size}; the scene "
                          f"has {n_sites} actuator sites: allowed an {n_sites} x {n_sites} matrix")
    if controller.enabled and sc.model != "full3d":
        raise ConfigError(f"{source}: the controller needs model = 'full3d', got '{sc.model}'")
    mode = sc.plant.top_drive.mode
    if top_drive.enabled and mode != "torque":
        raise ConfigError(f"{source}: [top_drive_controller] drives the motor torque of a top "
                          f"drive in mode 'torque', but top_drive.mode = {mode!r}: set "
                          "[top_drive] mode = \"torque\" and inertia")
    instances = (PLANT, *((CONTROLLER,) if controller.enabled else ()),
                 *((TOP_DRIVE,) if top_drive.enabled else ()))
    cosim = _cosim(tables["cosim"], instances, source)
    state_space = _state_space(tables["controller"], cosim, source, over)
    if state_space is not None and (controller_fmu or "fmu" in tables["controller"]):
        raise ConfigError(f"{source}: [controller] kind = \"state_space\" runs the matrices in "
                          "a StateSpaceController FMU built for the scene: a controller FMU "
                          "file cannot be given too")
    if controller_fmu and not controller.enabled:
        raise ConfigError(f"{source}: a controller FMU was given ({controller_fmu}) but the "
                          "scene's controller is off: set controller.enabled=true")
    files: dict[str, Path] = {}
    for instance, table_name, fmu in ((PLANT, "plant", plant_fmu),
                                      (CONTROLLER, "controller", controller_fmu),
                                      (TOP_DRIVE, "top_drive_controller", None)):
        if instance not in instances:
            continue
        if fmu:
            name = given[f"{table_name}.fmu"]
            if not Path(fmu).is_file():
                raise ConfigError(f"no file '{fmu}'", name)
            if (why := _not_an_fmu(Path(fmu))) is not None:
                raise ConfigError(f"'{fmu}' is {why}", name)
            files[instance] = Path(fmu)
        elif (chosen := _fmu_file(table_name, tables[table_name], source)) is not None:
            files[instance] = chosen
    set_keys = {CONTROLLER_TABLES[t][0]: tuple(k for k in tables[t]
                                               if k not in ("enabled", *_CONTROLLER_EXTRA))
                for t in CONTROLLER_TABLES}
    if state_space is not None:
        set_keys[CONTROLLER] = ()
        state_space = state_space if controller.enabled else None
    return SceneConfig(sc, controller, top_drive, cosim, files, over, set_keys, state_space)
