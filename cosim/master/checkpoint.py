"""Checkpoints: the whole state of a co-simulation at one tick, as bytes a later run resumes.

A :class:`Checkpoint` holds each component's serialized state (an FMU's
``fmi2SerializeFMUstate`` bytes, or what an in-process slave writes), the master's own state
(:class:`ExchangeState`: the held outputs and inputs, the tick of each component's newest
outputs, each delay line's past samples) and the tick, with what identifies them: per component
its build (:meth:`~.slave.Slave.state_identity`, for an FMU its model identifier, GUID and the
SHA-256 of its file) and the start values it was given, and the caller's own identity (the
scenario layer adds the scene and its settings). Time stays an integer: a run resumed at tick
``k`` counts on from ``k`` with the same base step, so its times, its sample phases (``k mod``
each period) and its recording grid are those of the run that was never interrupted.

The file (:meth:`Checkpoint.to_bytes`, :meth:`Checkpoint.from_bytes`) is a container of bytes
and JSON; nothing in it is code, and reading it runs none (no pickle). Format version 1, all
integers little-endian:

======  ======  ===============================================================================
offset  bytes   field
======  ======  ===============================================================================
0       8       magic ``b"DCSCHECK"``
8       4       format version (uint32) = 1
12      4       reserved (uint32) = 0
16      8       length m of the manifest (uint64)
24      m       manifest: UTF-8 JSON object (below)
24+m    n       the components' states, one after another (offsets and lengths in the manifest)
end-32  32      SHA-256 of every byte before it
======  ======  ===============================================================================

Manifest keys: ``tick`` (int), ``time`` [s], ``base_step`` ([numerator, denominator] of the step
as the master counts it), ``start_time`` [s], ``algorithm``, ``order`` (instance names in
stepping order), ``identity`` (the caller's JSON object), ``slaves`` (per instance in stepping
order: ``name``, ``identity``, ``parameters`` (start values it ran with), ``period`` [base steps],
``offset`` and ``length`` of its state in the data part, ``sha256`` of it) and ``exchange``
(``outputs``: names of the exchanged outputs, ``values``: their held values, ``newest``: the tick
of each component's newest outputs, ``inputs``: per instance its input names and held values,
``lines``: per delayed or extrapolated connection its ``source``, ``target``, ``delay`` [s],
``coupling`` and ``samples``, the past source samples, oldest first; ``connections``: every
connection's ``[source, target]``). Floats are JSON numbers
written by Python's ``repr``: they read back bit for bit.

A damaged file (length, checksum, JSON, a key of the wrong type) is refused with one line
(:class:`CheckpointError`); so is a checkpoint that does not fit the system it is restored into
(:func:`restore_problems`: instances, FMU builds, periods, step, algorithm, connections).
"""

from __future__ import annotations

import hashlib
import json
import struct
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from .errors import UserError
from .files import atomic_write
from .system import SystemSpec

__all__ = ["FORMAT_VERSION", "MAGIC", "Checkpoint", "CheckpointError", "ExchangeState",
           "LineHistory", "SlaveCheckpoint", "read_checkpoint", "restore_problems",
           "write_checkpoint"]

MAGIC = b"DCSCHECK"
FORMAT_VERSION = 1
_HEADER = struct.Struct("<8sIIQ")
_DIGEST = 32


class CheckpointError(UserError):
    """A checkpoint that is damaged, or that does not fit the run it is given to (one line)."""


@dataclass(frozen=True)
class LineHistory:
    """The past samples of one delay line (a delayed or extrapolated connection).

    Attributes
    ----------
    source, target : str
        ``'instance.variable'`` of the connection.
    delay : float
        Its transport delay [s] when the checkpoint was taken.
    coupling : str
        ``zoh`` or ``linear``.
    samples : tuple of float
        The source samples the line holds, oldest first, newest last.
    """

    source: str
    target: str
    delay: float
    coupling: str
    samples: tuple[float, ...]


@dataclass(frozen=True)
class ExchangeState:
    """The master's own state between two steps.

    Attributes
    ----------
    outputs : tuple of str
        The exchanged outputs ``'instance.variable'``, in the master's buffer order.
    values : tuple of float
        Their held values.
    newest : tuple of int
        Per component (stepping order) the tick of its newest outputs.
    inputs : tuple of (str, tuple of str, tuple of float)
        Per component its name, input names and held input values.
    lines : tuple of LineHistory
    connections : tuple of (str, str)
        Every connection's source and target.
    """

    outputs: tuple[str, ...]
    values: tuple[float, ...]
    newest: tuple[int, ...]
    inputs: tuple[tuple[str, tuple[str, ...], tuple[float, ...]], ...]
    lines: tuple[LineHistory, ...]
    connections: tuple[tuple[str, str], ...]


@dataclass(frozen=True)
class SlaveCheckpoint:
    """One component's part of a checkpoint.

    Attributes
    ----------
    name : str
        Instance name.
    identity : dict
        What the state belongs to (:meth:`~.slave.Slave.state_identity`, JSON-ready).
    parameters : dict
        The start values the instance ran with (:attr:`~.system.FmuSpec.parameters`).
    period : int
        Its sample period [base steps].
    state : bytes
        Its serialized state.
    """

    name: str
    identity: dict[str, Any]
    parameters: dict[str, Any]
    period: int
    state: bytes


@dataclass(frozen=True)
class Checkpoint:
    """The state of a co-simulation at tick :attr:`tick` (module docstring).

    Attributes
    ----------
    tick : int
        Base steps since the start time.
    time : float
        The time of that tick [s].
    base_step : tuple of int
        The base step as the master counts it, numerator and denominator [s].
    start_time : float
        [s]
    algorithm : str
    order : tuple of str
        Instance names in stepping order.
    slaves : tuple of SlaveCheckpoint
        In stepping order.
    exchange : ExchangeState
    identity : dict
        The caller's identity of the run (JSON-ready; the scenario layer's scene and settings).
    """

    tick: int
    time: float
    base_step: tuple[int, int]
    start_time: float
    algorithm: str
    order: tuple[str, ...]
    slaves: tuple[SlaveCheckpoint, ...]
    exchange: ExchangeState
    identity: dict[str, Any]

    def to_bytes(self) -> bytes:
        """The checkpoint file's content (module docstring)."""
        blobs, parts, offset = [], [], 0
        for s in self.slaves:
            blobs.append(s.state)
            parts.append({"name": s.name, "identity": s.identity, "parameters": s.parameters,
                          "period": s.period, "offset": offset, "length": len(s.state),
                          "sha256": hashlib.sha256(s.state).hexdigest()})
            offset += len(s.state)
        ex = self.exchange
        manifest = {
            "tick": self.tick, "time": self.time, "base_step": list(self.base_step),
            "start_time": self.start_time, "algorithm": self.algorithm,
            "order": list(self.order), "identity": self.identity, "slaves": parts,
            "exchange": {
                "outputs": list(ex.outputs), "values": list(ex.values),
                "newest": list(ex.newest),
                "inputs": [{"name": n, "names": list(names), "values": list(values)}
                           for n, names, values in ex.inputs],
                "lines": [{"source": ln.source, "target": ln.target, "delay": ln.delay,
                           "coupling": ln.coupling, "samples": list(ln.samples)}
                          for ln in ex.lines],
                "connections": [list(c) for c in ex.connections]}}
        text = json.dumps(manifest, separators=(",", ":")).encode("utf-8")
        body = _HEADER.pack(MAGIC, FORMAT_VERSION, 0, len(text)) + text + b"".join(blobs)
        return body + hashlib.sha256(body).digest()

    @classmethod
    def from_bytes(cls, data: bytes) -> Checkpoint:
        """Read a checkpoint file's content; :class:`CheckpointError` (one line) if it is not
        one of this format or is damaged."""
        data = bytes(data)
        if len(data) < _HEADER.size + _DIGEST or data[:8] != MAGIC:
            raise CheckpointError("not a drillcosim checkpoint (it does not start with "
                                  f"{MAGIC.decode()})")
        _magic, version, _reserved, m = _HEADER.unpack_from(data)
        if version != FORMAT_VERSION:
            raise CheckpointError(f"checkpoint format version {version}; this drillcosim reads "
                                  f"version {FORMAT_VERSION}")
        if hashlib.sha256(data[:-_DIGEST]).digest() != data[-_DIGEST:]:
            raise CheckpointError("damaged: its SHA-256 checksum does not match its content")
        if _HEADER.size + m > len(data) - _DIGEST:
            raise CheckpointError("damaged: its manifest length exceeds the file")
        try:
            manifest = json.loads(data[_HEADER.size:_HEADER.size + m].decode("utf-8"))
            return _parse(manifest, data[_HEADER.size + m:-_DIGEST])
        except (UnicodeDecodeError, ValueError, KeyError, TypeError) as exc:
            if isinstance(exc, CheckpointError):
                raise
            raise CheckpointError(f"damaged: its manifest is not what this format holds "
                                  f"({type(exc).__name__}: {exc})") from None


def _typed(value: Any, kind: type | tuple[type, ...], what: str) -> Any:
    if isinstance(value, bool) and kind is not bool or not isinstance(value, kind):
        raise CheckpointError(f"damaged: {what} is {value!r}")
    return value


def _numbers(values: Any, what: str) -> tuple[float, ...]:
    _typed(values, list, what)
    return tuple(float(_typed(v, (int, float), what)) for v in values)


def _names(values: Any, what: str) -> tuple[str, ...]:
    return tuple(_typed(v, str, what) for v in _typed(values, list, what))


def _parse(m: Mapping[str, Any], data: bytes) -> Checkpoint:
    """The checkpoint of manifest ``m`` and data part ``data`` (types checked)."""
    _typed(m, dict, "the manifest")
    slaves = []
    for s in _typed(m["slaves"], list, "slaves"):
        offset, length = _typed(s["offset"], int, "an offset"), _typed(s["length"], int,
                                                                        "a length")
        if offset < 0 or length < 0 or offset + length > len(data):
            raise CheckpointError(f"damaged: the state of '{s['name']}' lies outside the file")
        blob = data[offset:offset + length]
        if hashlib.sha256(blob).hexdigest() != s["sha256"]:
            raise CheckpointError(f"damaged: the state of '{s['name']}' does not match its "
                                  "SHA-256")
        slaves.append(SlaveCheckpoint(_typed(s["name"], str, "a name"),
                                      _typed(s["identity"], dict, "an identity"),
                                      _typed(s["parameters"], dict, "parameters"),
                                      _typed(s["period"], int, "a period"), blob))
    if tuple(s.name for s in slaves) != _names(m["order"], "order"):
        raise CheckpointError("damaged: its components are not those of its stepping order")
    ex = _typed(m["exchange"], dict, "exchange")
    inputs = tuple((_typed(i["name"], str, "a name"), _names(i["names"], "input names"),
                    _numbers(i["values"], "input values")) for i in _typed(ex["inputs"], list,
                                                                             "inputs"))
    lines = tuple(LineHistory(_typed(ln["source"], str, "a source"),
                              _typed(ln["target"], str, "a target"),
                              float(_typed(ln["delay"], (int, float), "a delay")),
                              _typed(ln["coupling"], str, "a coupling"),
                              _numbers(ln["samples"], "line samples"))
                  for ln in _typed(ex["lines"], list, "lines"))
    connections = tuple(_names(c, "a connection") for c in _typed(ex["connections"], list,
                                                                  "connections"))
    if any(len(c) != 2 for c in connections):
        raise CheckpointError("damaged: a connection is not a (source, target) pair")
    exchange = ExchangeState(_names(ex["outputs"], "outputs"),
                             _numbers(ex["values"], "output values"),
                             tuple(_typed(k, int, "a tick") for k in _typed(ex["newest"], list,
                                                                            "newest")),
                             inputs, lines, connections)
    step = _typed(m["base_step"], list, "base_step")
    if len(step) != 2 or not all(isinstance(v, int) and v > 0 for v in step):
        raise CheckpointError(f"damaged: base_step is {step!r}")
    return Checkpoint(_typed(m["tick"], int, "tick"), float(_typed(m["time"], (int, float),
                                                                   "time")),
                      (step[0], step[1]), float(_typed(m["start_time"], (int, float),
                                                       "start_time")),
                      _typed(m["algorithm"], str, "algorithm"), _names(m["order"], "order"),
                      tuple(slaves), exchange, _typed(m["identity"], dict, "identity"))


def write_checkpoint(checkpoint: Checkpoint, path: str | Path) -> Path:
    """Write ``checkpoint`` to ``path`` atomically (an earlier file stays until it is complete)."""
    path = Path(path)
    atomic_write(path, checkpoint.to_bytes())
    return path


def read_checkpoint(path: str | Path) -> Checkpoint:
    """Read the checkpoint file ``path``.

    Raises
    ------
    CheckpointError
        One line naming the file: no such file, not a checkpoint, damaged.
    """
    path = Path(path)
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise CheckpointError(f"checkpoint '{path}': cannot be read ({exc.strerror or exc})"
                              ) from None
    try:
        return Checkpoint.from_bytes(data)
    except CheckpointError as exc:
        raise CheckpointError(f"checkpoint '{path}': {exc}") from None


def restore_problems(checkpoint: Checkpoint, system: SystemSpec, num: int, den: int,
                     identities: Mapping[str, Mapping[str, Any]]) -> list[str]:
    """Why ``checkpoint`` cannot be restored into ``system`` (empty: it can).

    The instances (names, stepping order, periods), the base step (``num / den`` as the master
    counts it), the start time, the algorithm and the connections (source and target) must be
    those of the run that saved it, and each instance's identity (``identities``, by name) the
    saved one. Delays, couplings and start values may differ: the caller decides whether they
    act before the checkpoint's time (the master refuses what it cannot restore when it
    restores: a delay line needing more samples than it holds, a start value the component
    cannot take after its initialization).
    """
    problems = []
    order = system.stepping_order
    if tuple(order) != checkpoint.order:
        return [f"its instances are {list(checkpoint.order)} (in stepping order), this "
                f"system's {list(order)}"]
    if (num, den) != checkpoint.base_step:
        step = checkpoint.base_step[0] / checkpoint.base_step[1]
        problems.append(f"its base step is {step!r} s, this system's {num / den!r} s")
    if system.start_time != checkpoint.start_time:
        problems.append(f"its start time is {checkpoint.start_time!r} s, this system's "
                        f"{system.start_time!r} s")
    if system.algorithm != checkpoint.algorithm:
        problems.append(f"its algorithm is {checkpoint.algorithm}, this system's "
                        f"{system.algorithm}")
    for saved in checkpoint.slaves:
        spec = system.fmu(saved.name)
        if spec.sample_period_ticks != saved.period:
            problems.append(f"instance '{saved.name}' stepped every {saved.period} base steps, "
                            f"here every {spec.sample_period_ticks}")
        problems += [f"instance '{saved.name}': {p}"
                     for p in _identity_problems(saved.identity, identities[saved.name])]
    pairs = sorted((c.source, c.target) for c in system.connections)
    saved_pairs = sorted(checkpoint.exchange.connections)
    if pairs != saved_pairs:
        extra = [f"{s} -> {t}" for s, t in pairs if (s, t) not in saved_pairs]
        gone = [f"{s} -> {t}" for s, t in saved_pairs if (s, t) not in pairs]
        problems.append("its connections differ from this system's ("
                        + "; ".join([*(f"{c} only here" for c in extra[:2]),
                                     *(f"{c} only there" for c in gone[:2])]) + ")")
    return problems


def _identity_problems(saved: Mapping[str, Any], now: Mapping[str, Any]) -> list[str]:
    """The keys of two identities that differ, each as ``key: saved -> now``."""
    keys = sorted(set(saved) | set(now))
    return [f"{k} was {saved.get(k)!r} in the checkpoint, here {now.get(k)!r} (another "
            f"build or component)" for k in keys if saved.get(k) != now.get(k)]


def _json_ready(value: Any) -> Any:
    """``value`` if JSON writes it and reads it back equal (parameters, identities)."""
    return value if isinstance(value, (bool, int, float, str)) else str(value)


def parameters_record(parameters: Mapping[str, Any]) -> dict[str, Any]:
    """Start values as the checkpoint records them (JSON scalars)."""
    return {k: _json_ready(v) for k, v in parameters.items()}


def changed_parameters(saved: Mapping[str, Any], now: Mapping[str, Any]
                       ) -> tuple[dict[str, Any], list[str]]:
    """The start values of ``now`` that differ from ``saved`` (to set after the state is
    restored), and the names ``saved`` set that ``now`` does not (they cannot be unset)."""
    record = parameters_record(now)
    changed = {k: now[k] for k in now if k not in saved or saved[k] != record[k]
               or type(saved[k]) is not type(record[k])}
    return changed, sorted(set(saved) - set(now))


def check_history(line_delay: float, depth: int, saved: LineHistory | None,
                  where: str) -> Sequence[float]:
    """The samples a line of ``depth`` samples takes from ``saved`` (newest ``depth``);
    :class:`CheckpointError` if it holds fewer."""
    if saved is None or len(saved.samples) < depth:
        held = 0 if saved is None else len(saved.samples)
        raise CheckpointError(f"connection {where}: a delay of {line_delay!r} s needs {depth} "
                              f"past samples; the checkpoint holds {held}")
    return saved.samples[len(saved.samples) - depth:]
