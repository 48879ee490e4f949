"""Sweep grids: value lists from the command line and the points of a sweep.

A LIST is one of

* comma-separated values: ``1e6,1e7,1e9``;
* ``start:stop:count`` (linear, both ends included): ``0:2e-3:5``;
* ``log:start:stop:count`` (log spacing, both ends included): ``log:1e6:1e10:9``.

Items can be mixed with commas: ``0,log:1e-4:1e-2:3``.
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from functools import cached_property
from typing import Any

import numpy as np

from drillcosim.cosim.master.errors import UserError
from drillcosim.cosim.master.timegrid import integer_multiple
from drillcosim.cosim.scenario.build import ENGINES

__all__ = ["DEFAULT_GAIN_KEY", "GAIN_TABLES", "LOOP_KEYS", "Point", "SweepSpec", "check_gain_key",
           "loop_side", "parse_list", "point_key"]

KINDS = ("closed_loop", "open_loop")
#: The scene key a sweep's gain sets by default: the strain controller's gain [N per unit strain].
DEFAULT_GAIN_KEY = "controller.gain"
#: Scene tables whose keys a sweep's gain may set (the controller it enables).
GAIN_TABLES = ("controller", "top_drive_controller")


def check_gain_key(key: str) -> str:
    """``key`` if it names a key of a controller table (``"table.key"``), else ValueError."""
    table, dot, name = key.partition(".")
    if not dot or table not in GAIN_TABLES or not name.isidentifier():
        raise UserError(f"--gain-key {key!r}: must be TABLE.KEY with TABLE one of "
                         f"{', '.join(GAIN_TABLES)} (e.g. {DEFAULT_GAIN_KEY}, "
                         f"top_drive_controller.p_gain)")
    return key


def _number(text: str, what: str) -> float:
    try:
        x = float(text)
    except ValueError:
        raise UserError(f"{what}: {text!r} is not a number") from None
    if not math.isfinite(x):
        raise UserError(f"{what}: {text!r} is not finite")
    return x


def _range(item: str, what: str) -> list[float]:
    log = item.startswith("log:")
    parts = item[4:].split(":") if log else item.split(":")
    if len(parts) != 3:
        raise UserError(f"{what}: {item!r}: use start:stop:count or log:start:stop:count")
    a, b = _number(parts[0], what), _number(parts[1], what)
    try:
        n = int(parts[2])
    except ValueError:
        raise UserError(f"{what}: {item!r}: count {parts[2]!r} is not an integer") from None
    if n < 1:
        raise UserError(f"{what}: {item!r}: count must be >= 1")
    if log:
        if a <= 0 or b <= 0:
            raise UserError(f"{what}: {item!r}: log spacing needs start, stop > 0")
        return [float(x) for x in np.geomspace(a, b, n)]
    return [float(x) for x in np.linspace(a, b, n)]


def parse_list(text: str, what: str = "list", minimum: float | None = None,
               positive: bool = False) -> list[float]:
    """Parse a LIST (see the module docstring) into sorted unique floats.

    Parameters
    ----------
    text : str
    what : str
        Name used in error messages (e.g. ``"--gain"``).
    minimum : float, optional
        Smallest allowed value (inclusive).
    positive : bool
        Values must be > 0.

    Returns
    -------
    list of float

    Raises
    ------
    ValueError
        One line naming ``what`` and the offending item.
    """
    values: list[float] = []
    for item in (s.strip() for s in text.split(",")):
        if not item:
            continue
        values += _range(item, what) if ":" in item else [_number(item, what)]
    if not values:
        raise UserError(f"{what}: no values in {text!r}")
    for v in values:
        if positive and v <= 0:
            raise UserError(f"{what}: {v!r} must be > 0")
        if minimum is not None and v < minimum:
            raise UserError(f"{what}: {v!r} must be >= {minimum}")
    # round to 12 significant digits so 1e-3 from a range equals a typed 0.001
    return sorted({float(f"{v:.12g}") for v in values})


def point_key(scene: str, engine: str, kind: str, gain: float | str, delay: float, step: float,
              stop_time: float, extra: str = "") -> str:
    """Identity of a point in the results table (resuming skips known keys). ``gain`` is the
    gain's value or its slot's text (the gain and a point's other controller-side values: the
    open-loop reference of a point has ``0`` in that slot, :func:`cosim.study.table.reference_key`)."""
    slot = gain if isinstance(gain, str) else f"{gain:.12g}"
    return (f"{scene}|{engine}|{kind}|{slot}|{delay:.12g}|{step:.12g}|{stop_time:.12g}"
            + (f"|{extra}" if extra else ""))


#: Key paths of a sweep's controller side besides the controllers' own tables: what the
#: open-loop reference of a point does not depend on.
LOOP_KEYS = ("cosim.actuator_delay", "cosim.sensor_delay", "cosim.controller_sample_period")


def loop_side(key: str) -> bool:
    """Whether a varied key path belongs to the closed loop's controller side (a controller
    table's key, ``<table>.parameters.NAME`` included, or a delay / the controllers' period):
    the open-loop reference of a point does not depend on it."""
    return key.split(".", 1)[0] in GAIN_TABLES or key in LOOP_KEYS


def _json(pairs: Sequence[tuple[str, Any]]) -> str:
    return json.dumps(dict(pairs), sort_keys=True) if pairs else ""


@dataclass(frozen=True)
class Point:
    """One co-simulation of a sweep (all the arguments of a point measurement).

    Attributes
    ----------
    scene : str
        Scene name or path.
    gain : float
        The value of ``gain_key`` (the strain controller's gain [N per unit strain] by default;
        0 for open loop; NaN where the sweep varies no gain: the scene's).
    delay : float
        Actuator delay [s].
    step : float
        Communication step [s].
    stop_time : float
        [s].
    engine : {"fmu", "inprocess"}
    kind : {"closed_loop", "open_loop"}
    overrides : str
        JSON of the sweep's extra scene keys by key path, "" for none.
    options : tuple of (str, float)
        Metric options for the measurement (see :class:`cosim.study.point.PointOptions`).
    gain_key : str
        The scene key the gain sets (``"table.key"``, default :data:`DEFAULT_GAIN_KEY`).
    vary : tuple of (str, value)
        The point's values of the sweep's other axes (``--vary``), by key path.
    config : SceneConfig or None
        The point's typed configuration, derived from the sweep's base configuration once
        (:func:`cosim.scenario.config.derive_config`); not part of its identity.
    """

    scene: str
    gain: float
    delay: float
    step: float
    stop_time: float
    engine: str = "fmu"
    kind: str = "closed_loop"
    overrides: str = ""
    options: tuple[tuple[str, float], ...] = ()
    gain_key: str = DEFAULT_GAIN_KEY
    vary: tuple[tuple[str, Any], ...] = ()
    config: Any = field(default=None, compare=False, repr=False)

    @property
    def key(self) -> str:
        """See :func:`point_key`: the controller-side values of ``vary`` share the gain's slot,
        the others (and a gain key other than the default) the extra part."""
        loop = tuple((k, v) for k, v in self.vary if loop_side(k))
        plant = tuple((k, v) for k, v in self.vary if not loop_side(k))
        slot = f"{self.gain:.12g}" + (f";{_json(loop)}" if loop else "")
        extra = "|".join(x for x in (self.overrides, _json(plant),
                                     "" if self.gain_key == DEFAULT_GAIN_KEY
                                     else f"gain_key={self.gain_key}") if x)
        return point_key(self.scene, self.engine, self.kind, slot, self.delay, self.step,
                         self.stop_time, extra)

    def identity(self) -> dict[str, Any]:
        """The identity columns of the point's table row (``varied``: its values of the
        sweep's other axes, JSON)."""
        return {"key": self.key, "scene": self.scene, "engine": self.engine,
                "kind": self.kind, "gain": self.gain, "delay": self.delay,
                "step": self.step, "stop_time": self.stop_time, "varied": _json(self.vary)}

    def kwargs(self) -> dict[str, Any]:
        """Keyword arguments of :func:`cosim.study.point.measure_point` (the typed
        configuration too, where the point has one)."""
        out = {"scene": self.scene, "gain": self.gain, "delay": self.delay, "step": self.step,
               "stop_time": self.stop_time, "engine": self.engine,
               "open_loop": self.kind == "open_loop",
               "overrides": json.loads(self.overrides) if self.overrides else None,
               "gain_key": self.gain_key, **dict(self.options)}
        if self.config is not None:
            out["config"] = self.config
        return out


@dataclass(frozen=True)
class SweepSpec:
    """A full-factorial sweep over gain x delay x step x the other axes, plus open-loop
    references.

    Attributes
    ----------
    scene : str
    gains : sequence of float
        Values of ``gain_key`` (the strain gain [N per unit strain] by default); empty: the
        scene's gain (no gain axis).
    delays : sequence of float
        Actuator delays [s].
    steps : sequence of float
        Communication steps [s].
    stop_time : float
        [s].
    engine : {"fmu", "inprocess"}
    overrides : mapping
        Extra scene keys by key path (e.g. ``{"cosim.algorithm": "jacobi"}``).
    open_loop : bool
        Also run open-loop references (needed for the control benefit): one per value of the
        plant-side axes (the step, and the axes that are no controller key nor delay).
    options : mapping of str -> float
        Metric options (:class:`cosim.study.point.PointOptions` fields).
    gain_key : str
        The scene key the gains set (default :data:`DEFAULT_GAIN_KEY`; e.g.
        ``"top_drive_controller.p_gain"`` [N m s/rad] for the top-drive controller).
    vary : tuple of (str, tuple)
        Further axes: ``(key path, values)`` (``drillcosim sweep --vary KEY=LIST``).
    base : SceneConfig or None
        The scene with ``overrides``, validated once (:func:`cosim.study.sweep.sweep_spec`);
        the points' configurations are derived from it (:attr:`planned`). None: the points
        carry no configuration (their measurement loads it).
    """

    scene: str
    gains: Sequence[float]
    delays: Sequence[float]
    steps: Sequence[float]
    stop_time: float
    engine: str = "fmu"
    overrides: Mapping[str, Any] = field(default_factory=dict)
    open_loop: bool = True
    options: Mapping[str, float] = field(default_factory=dict)
    gain_key: str = DEFAULT_GAIN_KEY
    vary: tuple[tuple[str, tuple[Any, ...]], ...] = ()
    base: Any = field(default=None, compare=False, repr=False)

    @property
    def table(self) -> str:
        """The scene table of the controller the closed-loop points enable (and the open-loop
        references disable): the gain key's where the gains vary or no other axis is a
        controller's, else the first controller axis'."""
        if not self.gains:
            for key, _values in self.vary:
                if key.split(".", 1)[0] in GAIN_TABLES:
                    return key.split(".", 1)[0]
        return self.gain_key.partition(".")[0]

    def points(self) -> list[Point]:
        """Open-loop references first, then gain x delay x step x the other axes."""
        return list(self.planned)

    @cached_property
    def planned(self) -> tuple[Point, ...]:
        """The points (made once per spec), each with its configuration where :attr:`base`
        is given (ConfigError: a value some point cannot take, before anything runs)."""
        if self.engine not in ENGINES:
            raise UserError(f"engine = {self.engine!r} is not allowed; allowed: "
                            f"{', '.join(ENGINES)}")
        if not (self.stop_time > 0 and math.isfinite(self.stop_time)):
            raise UserError(f"stop time: a finite number > 0 [s], got {self.stop_time!r}")
        if self.base is None:  # the measurement loads the configuration; checked here
            for h in self.steps:
                if integer_multiple(self.stop_time, h) is None:
                    raise UserError(f"stop time {self.stop_time:g} s: not a whole number of "
                                    f"steps of {h:g} s ({self.stop_time / h:.6g}); choose a "
                                    "stop time every step divides")
        over = json.dumps(dict(self.overrides), sort_keys=True) if self.overrides else ""
        opts = tuple(sorted((k, float(v)) for k, v in self.options.items()))
        check_gain_key(self.gain_key)
        common = {"stop_time": float(self.stop_time), "engine": self.engine,
                  "overrides": over, "options": opts, "gain_key": self.gain_key}
        plant_axes = [(k, v) for k, v in self.vary if not loop_side(k)]
        pts = []
        if self.open_loop:
            for h in self.steps:
                for combo in _combos(plant_axes):
                    pts.append(self._point(0.0, 0.0, float(h), combo, "open_loop", common))
        for h in self.steps:
            for k in (self.gains or [math.nan]):
                for d in self.delays:
                    for combo in _combos(list(self.vary)):
                        pts.append(self._point(float(k), float(d), float(h), combo,
                                               "closed_loop", common))
        return tuple(pts)

    def _point(self, gain: float, delay: float, step: float, vary: tuple,
               kind: str, common: Mapping[str, Any]) -> Point:
        config = None
        if self.base is not None:
            from drillcosim.cosim.scenario.config import derive_config

            values = {"cosim.step": step, "cosim.stop_time": self.stop_time,
                      "cosim.actuator_delay": delay, **dict(vary)}
            values[f"{self.table}.enabled"] = kind == "closed_loop"
            if kind == "closed_loop" and not math.isnan(gain):
                values[self.gain_key] = gain
            config = derive_config(self.base, values, controller_fmu=not (
                kind == "open_loop" and self.table == "controller"))
        return Point(self.scene, gain, delay, step, kind=kind, vary=vary, config=config,
                     **common)


def _combos(axes: Sequence[tuple[str, Sequence[Any]]]) -> list[tuple[tuple[str, Any], ...]]:
    """Every combination of the axes' values, as ``((key, value), ...)`` (one empty one for
    no axes)."""
    out: list[tuple[tuple[str, Any], ...]] = [()]
    for key, values in axes:
        out = [(*combo, (key, v)) for combo in out for v in values]
    return out
