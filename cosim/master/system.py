"""Typed, validated description of a co-simulation system.

All times are in seconds. A system is a set of FMU instances
(:class:`FmuSpec`), a set of :class:`Connection` s between their variables and
the master settings (:class:`SystemSpec`). Invalid values raise ``ValueError``
with a one-line message naming the field and the allowed range.
"""

from __future__ import annotations

import difflib
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path

from .timegrid import integer_multiple

ALGORITHMS = ("jacobi", "gauss_seidel")
COUPLINGS = ("zoh", "linear")
ParameterValue = float | int | bool | str


def _did_you_mean(word: str, choices: Sequence[str]) -> str:
    close = difflib.get_close_matches(word, list(choices), n=1)
    return f" (did you mean '{close[0]}'?)" if close else ""


def split_variable(ref: str, field_name: str) -> tuple[str, str]:
    """Split ``'fmu.var'`` into ``('fmu', 'var')`` (the variable may contain dots)."""
    if not isinstance(ref, str) or "." not in ref:
        raise ValueError(f"{field_name}: expected 'fmu.variable', got {ref!r}")
    fmu, var = ref.split(".", 1)
    if not fmu or not var:
        raise ValueError(f"{field_name}: expected 'fmu.variable', got {ref!r}")
    return fmu, var


@dataclass(frozen=True)
class FmuSpec:
    """One FMU instance.

    Parameters
    ----------
    name : str
        Instance name, unique in the system, without '.'.
    path : str or Path
        Path of the ``.fmu`` file (it also describes a component the caller hands to the
        execution ready-made, e.g. an in-process slave, see
        :class:`~cosim.master.execution.Execution`).
    parameters : dict[str, float | int | bool | str]
        Start values set before initialisation, by variable name.
    sample_period_ticks : int
        The FMU steps every ``sample_period_ticks`` base steps (>= 1), with step
        size ``sample_period_ticks * base_step``; its outputs are held between.
    """

    name: str
    path: str | Path
    parameters: dict[str, ParameterValue] = field(default_factory=dict)
    sample_period_ticks: int = 1

    def __post_init__(self):
        if not isinstance(self.name, str) or not self.name or "." in self.name:
            raise ValueError(f"FmuSpec.name: non-empty string without '.', got {self.name!r}")
        if isinstance(self.sample_period_ticks, bool) or not isinstance(
                self.sample_period_ticks, int) or self.sample_period_ticks < 1:
            raise ValueError(f"FmuSpec.sample_period_ticks of '{self.name}': integer >= 1, "
                             f"got {self.sample_period_ticks!r}")
        for key, value in self.parameters.items():
            if not isinstance(value, (float, int, bool, str)):
                raise ValueError(f"FmuSpec.parameters['{key}'] of '{self.name}': "
                                 f"float, int, bool or str, got {type(value).__name__}")


@dataclass(frozen=True)
class Connection:
    """A connection from an output to an input.

    Parameters
    ----------
    source, target : str
        ``'fmu.variable'``; the source is an output, the target an input.
    delay : float
        Transport delay [s], >= 0 (see :mod:`cosim.master.delays`).
    coupling : {'zoh', 'linear'}
        Zero-order hold of the latest sample, or linear extrapolation from the
        last two samples (see :mod:`cosim.master.delays`).
    """

    source: str
    target: str
    delay: float = 0.0
    coupling: str = "zoh"

    def __post_init__(self):
        split_variable(self.source, "Connection.source")
        split_variable(self.target, "Connection.target")
        if isinstance(self.delay, bool) or not isinstance(self.delay, (int, float)) \
                or not math.isfinite(self.delay) or self.delay < 0:
            raise ValueError(f"Connection.delay of {self.source} -> {self.target}: "
                             f"finite number >= 0 [s], got {self.delay!r}")
        if self.coupling not in COUPLINGS:
            raise ValueError(f"Connection.coupling of {self.source} -> {self.target}: "
                             f"one of {COUPLINGS}, got {self.coupling!r}"
                             f"{_did_you_mean(str(self.coupling), COUPLINGS)}")


@dataclass(frozen=True)
class SystemSpec:
    """A co-simulation system.

    Parameters
    ----------
    fmus : sequence of FmuSpec
        FMU instances, unique names.
    connections : sequence of Connection
        Each input is the target of at most one connection.
    base_step : float
        Base communication step H [s], > 0; every sample period is a multiple.
    algorithm : {'jacobi', 'gauss_seidel'}
        Jacobi: all FMUs step in parallel on the outputs of the previous
        communication point. Gauss-Seidel: FMUs step one after another in
        ``order``, each using the newest outputs of those before it.
    order : sequence of str
        Stepping order for Gauss-Seidel (a permutation of the FMU names);
        empty means declaration order.
    start_time : float
        Start time [s].
    stop_time : float or None
        Default stop time [s], > start_time.
    """

    fmus: Sequence[FmuSpec]
    connections: Sequence[Connection] = ()
    base_step: float = 1e-3
    algorithm: str = "jacobi"
    order: Sequence[str] = ()
    start_time: float = 0.0
    stop_time: float | None = None

    def __post_init__(self):
        object.__setattr__(self, "fmus", tuple(self.fmus))
        object.__setattr__(self, "connections", tuple(self.connections))
        object.__setattr__(self, "order", tuple(self.order))
        names = [f.name for f in self.fmus]
        if not names:
            raise ValueError("SystemSpec.fmus: at least one FmuSpec, got none")
        dup = sorted({n for n in names if names.count(n) > 1})
        if dup:
            raise ValueError(f"SystemSpec.fmus: names must be unique, repeated: {dup}")
        if not isinstance(self.base_step, (int, float)) or not math.isfinite(self.base_step) \
                or self.base_step <= 0:
            raise ValueError(f"SystemSpec.base_step: finite number > 0 [s], "
                             f"got {self.base_step!r}")
        if self.algorithm not in ALGORITHMS:
            raise ValueError(f"SystemSpec.algorithm: one of {ALGORITHMS}, got "
                             f"{self.algorithm!r}{_did_you_mean(str(self.algorithm), ALGORITHMS)}")
        if self.order and sorted(self.order) != sorted(names):
            raise ValueError(f"SystemSpec.order: a permutation of the FMU names {names}, "
                             f"got {list(self.order)}")
        if not math.isfinite(self.start_time):
            raise ValueError(f"SystemSpec.start_time: finite number [s], got {self.start_time}")
        if self.stop_time is not None and not self.stop_time > self.start_time:
            raise ValueError(f"SystemSpec.stop_time: > start_time = {self.start_time} s, "
                             f"got {self.stop_time!r}")
        targets: set[str] = set()
        for c in self.connections:
            for ref, what in ((c.source, "source"), (c.target, "target")):
                fmu = ref.split(".", 1)[0]
                if fmu not in names:
                    raise ValueError(f"Connection.{what} {ref!r}: unknown FMU '{fmu}'"
                                     f"{_did_you_mean(fmu, names)}; known: {names}")
            if c.target in targets:
                raise ValueError(f"Connection.target {c.target!r}: connected more than once")
            targets.add(c.target)

    def fmu(self, name: str) -> FmuSpec:
        """The :class:`FmuSpec` called ``name``."""
        for f in self.fmus:
            if f.name == name:
                return f
        raise KeyError(name)

    @property
    def stepping_order(self) -> tuple[str, ...]:
        """FMU names in stepping order (``order`` or declaration order)."""
        return self.order or tuple(f.name for f in self.fmus)


_TOP_KEYS = ("step", "stop_time", "start_time", "algorithm", "order", "coupling", "fmus",
             "connections")
_FMU_KEYS = ("path", "sample_period", "parameters")
_CONN_KEYS = ("source", "target", "delay", "coupling")


def _check_keys(d: Mapping, allowed: Sequence[str], where: str) -> None:
    if not isinstance(d, Mapping):
        raise ValueError(f"{where}: expected a table, got {type(d).__name__}")
    for key in d:
        if key not in allowed:
            raise ValueError(f"{where}: unknown key '{key}'{_did_you_mean(key, allowed)}; "
                             f"allowed: {list(allowed)}")


def _ticks(period: float, step: float, where: str) -> int:
    n = integer_multiple(period, step)
    if n is None:
        raise ValueError(f"{where}: a positive integer multiple of step = {step} s, "
                         f"got {period} s")
    return n


def system_from_dict(d: Mapping, base_dir: str | Path | None = None) -> SystemSpec:
    """Build a :class:`SystemSpec` from a dict shaped like a TOML ``[cosim]`` section.

    Schema (all times in seconds)::

        step = 1e-3                 # base communication step H [s], required
        stop_time = 30.0            # default stop time [s], optional
        start_time = 0.0            # [s], optional (0)
        algorithm = "jacobi"        # or "gauss_seidel", optional ("jacobi")
        order = ["plant", "ctrl"]   # Gauss-Seidel stepping order, optional
        coupling = "zoh"            # default coupling of connections: "zoh" | "linear"

        [cosim.fmus.plant]          # one table per FMU instance, key = instance name
        path = "build/plant.fmu"    # relative to base_dir
        sample_period = 1e-3        # [s], integer multiple of step, optional (= step)
        parameters = { k = 2.0 }    # start values by variable name, optional

        [[cosim.connections]]
        source = "plant.x"          # output "fmu.variable"
        target = "ctrl.u"           # input "fmu.variable"
        delay = 0.0                 # transport delay [s], optional (0)
        coupling = "linear"         # overrides the default, optional

    Parameters
    ----------
    d : Mapping
        The ``[cosim]`` table.
    base_dir : str or Path, optional
        Directory against which relative FMU paths are resolved.

    Returns
    -------
    SystemSpec

    Raises
    ------
    ValueError
        On unknown keys (with a "did you mean" suggestion), missing required
        keys or out-of-range values.
    """
    _check_keys(d, _TOP_KEYS, "[cosim]")
    for key in ("step", "fmus"):
        if key not in d:
            raise ValueError(f"[cosim]: missing required key '{key}'")
    step = float(d["step"])
    if not math.isfinite(step) or step <= 0:
        raise ValueError(f"[cosim].step: finite number > 0 [s], got {d['step']!r}")
    base = Path(base_dir) if base_dir is not None else None
    fmus = []
    if not isinstance(d["fmus"], Mapping):
        raise ValueError("[cosim].fmus: expected a table of FMU tables")
    for name, f in d["fmus"].items():
        where = f"[cosim.fmus.{name}]"
        _check_keys(f, _FMU_KEYS, where)
        if "path" not in f:
            raise ValueError(f"{where}: missing required key 'path'")
        path = Path(f["path"])
        if base is not None and not path.is_absolute():
            path = base / path
        ticks = _ticks(float(f.get("sample_period", step)), step, f"{where}.sample_period")
        fmus.append(FmuSpec(name, path, dict(f.get("parameters", {})), ticks))
    default_coupling = d.get("coupling", "zoh")
    connections = []
    for i, c in enumerate(d.get("connections", [])):
        where = f"[[cosim.connections]] #{i + 1}"
        _check_keys(c, _CONN_KEYS, where)
        for key in ("source", "target"):
            if key not in c:
                raise ValueError(f"{where}: missing required key '{key}'")
        connections.append(Connection(c["source"], c["target"], float(c.get("delay", 0.0)),
                                      c.get("coupling", default_coupling)))
    stop = d.get("stop_time")
    return SystemSpec(fmus, connections, step, d.get("algorithm", "jacobi"),
                      tuple(d.get("order", ())), float(d.get("start_time", 0.0)),
                      None if stop is None else float(stop))
