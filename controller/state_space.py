"""A generic discrete-time linear controller with output saturation.

The law, at its own sample period ``Ts``, sample ``k``::

    u[k]   = clip(C x[k] + D y[k], lower, upper)
    x[k+1] = A x[k] + B y[k]

``y`` are the inputs (e.g. strains [1]), ``u`` the outputs (e.g. actuator forces [N]), ``x`` the
controller state (``n`` entries, ``n = 0`` allowed: a static gain ``u = D y``). The state update
does not see the saturation (no anti-windup): a design that relies on the limits being inactive
says so.

Time discretisation
-------------------
``step(t, h, y)`` runs ``h / Ts`` samples (``h`` an integer multiple of ``Ts`` up to a relative
1e-9; ``h = 0`` runs none) with the inputs ``y`` held, and returns ``u`` of the last one: the
output after a communication step ``[t, t + h]`` is computed from the inputs set before it
(the strain controller's timing: with ``A, B, C`` empty and ``D = K I`` this is its P law).

The workspace
-------------
The numbers of a controller live in one float64 array (:class:`Workspace`): a header, the state
and the inputs side by side, the outputs, a scratch vector, the matrix ``[[C, D], [A, B]]``
(row-major), the lower and the upper limits. One sample is one matrix-vector product
``v = M [x; y]``. :meth:`StateSpaceController.step` is the numpy reference;
:meth:`StateSpaceController.compiled_step` hands views of the workspace to the compiled step
(:func:`controller.compiled.state_space_step`, a numba ``cfunc`` called without the GIL), which
does the same (to rounding: both products are BLAS calls, from numpy's and from numba's BLAS).

Only numpy and the standard library are imported (the package is vendored into FMUs; the
compiled step is made only where numba is loaded, :mod:`controller.acceleration`).
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from .acceleration import OK, REFUSED, compiled_law
from .law import Law
from .ports import Port, limit, parameter, real_input, real_output

__all__ = ["FORMAT", "MULTIPLE_RTOL", "NO_LIMIT", "Signal", "StateSpaceController",
           "StateSpaceParams", "Workspace", "load_state_space", "state_space_core",
           "state_space_from_mapping"]

#: ``format`` key of a state-space file (:meth:`StateSpaceParams.to_mapping`).
FORMAT = "drillcosim.state_space/1"

#: Relative tolerance of "h is an integer multiple of the sample period".
MULTIPLE_RTOL = 1e-9
# header of the workspace: [size, n states, n inputs, n outputs, then the timing the compiled
# step reads: sample period, samples run, MULTIPLE_RTOL]
_SIZE, _NX, _NY, _NU, _TS, _COUNT, _RTOL = range(7)
_HEADER = 7


@dataclass(frozen=True)
class Signal:
    """One input or output of the controller: name, unit and (outputs) saturation limits.

    Attributes
    ----------
    name : str
        An identifier (it becomes an FMU variable name).
    unit : str
        Unit of the signal (free text here; the FMU build checks it is one it can declare).
    lower, upper : float
        Saturation limits of an output [its unit], ``lower <= upper``; ``-inf`` / ``inf`` for
        none (inputs: always none).
    """

    name: str
    unit: str = "1"
    lower: float = -math.inf
    upper: float = math.inf


_ROLES = {"A": "states x states", "B": "states x inputs", "C": "outputs x states",
          "D": "outputs x inputs"}


def _matrix(name: str, value: Any, shape: tuple[int, int]) -> np.ndarray:
    """``value`` as a read-only float array of ``shape``, or ValueError naming ``name``."""
    try:
        arr = np.array(value, dtype=float)
    except (TypeError, ValueError):
        raise ValueError(f"{name}: not a matrix of real numbers (expected shape "
                         f"{shape[0]} x {shape[1]})") from None
    if arr.size == 0 and 0 in shape:
        arr = arr.reshape(shape)
    if arr.shape != shape:
        got = " x ".join(str(s) for s in arr.shape) or "a scalar"
        raise ValueError(f"{name} is {got}; allowed: {shape[0]} x {shape[1]} ({_ROLES[name]})")
    bad = np.argwhere(~np.isfinite(arr))
    if bad.size:
        i, j = (int(v) + 1 for v in bad[0])
        raise ValueError(f"{name}[{i}, {j}] = {float(arr[tuple(bad[0])])!r}: every entry must be finite "
                         f"({len(bad)} non-finite)")
    arr.setflags(write=False)
    return arr


@dataclass(frozen=True, eq=False)
class StateSpaceParams:
    """Validated matrices, signals and sample period of a :class:`StateSpaceController`.

    Parameters
    ----------
    A : array_like, shape (n, n)
    B : array_like, shape (n, m)
    C : array_like, shape (p, n)
    D : array_like, shape (p, m)
        Finite matrices; ``n = 0`` is a static gain. Converted to read-only float arrays.
    inputs : sequence of Signal, length m
    outputs : sequence of Signal, length p
    sample_period : float
        Ts [s], finite and > 0.
    description : str
        Free text (where the matrices come from).

    Raises
    ------
    ValueError
        One line naming the bad item: shapes, non-finite entries, duplicate or non-identifier
        names, limits with ``lower > upper`` or NaN, a bad sample period.
    """

    A: np.ndarray
    B: np.ndarray
    C: np.ndarray
    D: np.ndarray
    inputs: tuple[Signal, ...]
    outputs: tuple[Signal, ...]
    sample_period: float
    description: str = ""

    def __post_init__(self) -> None:
        put = object.__setattr__
        put(self, "inputs", tuple(self.inputs))
        put(self, "outputs", tuple(self.outputs))
        m, p = len(self.inputs), len(self.outputs)
        if m == 0 or p == 0:
            raise ValueError(f"a controller needs >= 1 input and >= 1 output; got {m} inputs "
                             f"and {p} outputs")
        names = [s.name for s in (*self.inputs, *self.outputs)]
        for s in (*self.inputs, *self.outputs):
            if not isinstance(s, Signal):
                raise ValueError(f"inputs/outputs must be Signals, got {s!r}")
            if not isinstance(s.name, str) or not s.name.isidentifier():
                raise ValueError(f"signal name {s.name!r} is not allowed; allowed: an identifier "
                                 "(letters, digits, _; not starting with a digit)")
            if not isinstance(s.unit, str):
                raise ValueError(f"unit of {s.name} must be a string, got {s.unit!r}")
        dup = sorted({n for n in names if names.count(n) > 1})
        if dup:
            raise ValueError(f"signal names must be unique; repeated: {', '.join(dup)}")
        for s in self.inputs:
            if not (s.lower == -math.inf and s.upper == math.inf):
                raise ValueError(f"input {s.name}: inputs have no limits (lower = -inf, "
                                 f"upper = inf), got [{s.lower!r}, {s.upper!r}]")
        for s in self.outputs:
            lo, hi = float(s.lower), float(s.upper)
            if math.isnan(lo) or math.isnan(hi) or lo > hi:
                raise ValueError(f"output {s.name}: limits [{lo!r}, {hi!r}]; allowed: "
                                 "lower <= upper (-inf / inf for none)")
        ts = self.sample_period
        if isinstance(ts, bool) or not isinstance(ts, (int, float)) or not (
                math.isfinite(ts) and ts > 0):
            raise ValueError(f"sample_period = {ts!r}; allowed: a finite number > 0 [s]")
        put(self, "sample_period", float(ts))
        try:
            a = np.array(self.A, dtype=float)
        except (TypeError, ValueError):
            raise ValueError("A: not a matrix of real numbers") from None
        if a.size == 0:
            n = 0
        elif a.ndim == 2 and a.shape[0] == a.shape[1]:
            n = a.shape[0]
        else:
            raise ValueError(f"A is {' x '.join(str(s) for s in a.shape)}; allowed: a square "
                             "matrix (states x states)")
        put(self, "A", _matrix("A", self.A, (n, n)))
        put(self, "B", _matrix("B", self.B, (n, m)))
        put(self, "C", _matrix("C", self.C, (p, n)))
        put(self, "D", _matrix("D", self.D, (p, m)))

    # ------------------------------------------------------------------ shape
    @property
    def n_states(self) -> int:
        """int: n, the length of the controller state."""
        return self.A.shape[0]

    @property
    def input_names(self) -> tuple[str, ...]:
        return tuple(s.name for s in self.inputs)

    @property
    def output_names(self) -> tuple[str, ...]:
        return tuple(s.name for s in self.outputs)

    @property
    def lower(self) -> np.ndarray:
        """numpy.ndarray, shape (p,): lower limits of the outputs."""
        return np.array([s.lower for s in self.outputs], dtype=float)

    @property
    def upper(self) -> np.ndarray:
        """numpy.ndarray, shape (p,): upper limits of the outputs."""
        return np.array([s.upper for s in self.outputs], dtype=float)

    def with_limits(self, lower: Sequence[float], upper: Sequence[float]) -> StateSpaceParams:
        """The same controller with other output limits (validated)."""
        outs = tuple(Signal(s.name, s.unit, float(lo), float(hi))
                     for s, lo, hi in zip(self.outputs, lower, upper, strict=True))
        return StateSpaceParams(self.A, self.B, self.C, self.D, self.inputs, outs,
                                self.sample_period, self.description)

    # ------------------------------------------------------------ (de)serialize
    def to_mapping(self) -> dict[str, Any]:
        """A JSON-ready mapping (the file format :func:`load_state_space` reads; floats are
        written exactly by :mod:`json`, infinite limits as ``null``)."""
        def lim(x: float) -> float | None:
            return None if math.isinf(x) else x

        return {
            "format": FORMAT, "description": self.description,
            "sample_period": self.sample_period, "n_states": self.n_states,
            "inputs": [{"name": s.name, "unit": s.unit} for s in self.inputs],
            "outputs": [{"name": s.name, "unit": s.unit, "lower": lim(s.lower),
                         "upper": lim(s.upper)} for s in self.outputs],
            "A": self.A.tolist(), "B": self.B.tolist(), "C": self.C.tolist(),
            "D": self.D.tolist(),
        }

    def save(self, path: str | Path) -> Path:
        """Write :meth:`to_mapping` as JSON to ``path``; returns it."""
        path = Path(path)
        path.write_text(json.dumps(self.to_mapping(), separators=(",", ":")) + "\n")
        return path


def state_space_from_mapping(data: Mapping[str, Any], where: str = "state space"
                             ) -> StateSpaceParams:
    """Validated :class:`StateSpaceParams` from a mapping of :meth:`StateSpaceParams.to_mapping`'s
    form (a JSON file, or a scene table).

    Raises
    ------
    ValueError
        One line, prefixed by ``where`` (e.g. the file), naming the bad key or entry.
    """
    def fail(msg: str) -> ValueError:
        return ValueError(f"{where}: {msg}")

    if not isinstance(data, Mapping):
        raise fail("not a table/object")
    fmt = data.get("format", FORMAT)
    if fmt != FORMAT:
        raise fail(f"format = {fmt!r}; allowed: {FORMAT!r}")
    allowed = {"format", "description", "sample_period", "n_states", "inputs", "outputs",
               "A", "B", "C", "D"}
    unknown = sorted(set(data) - allowed)
    if unknown:
        raise fail(f"unknown key(s) {', '.join(unknown)}; allowed: {', '.join(sorted(allowed))}")
    missing = [k for k in ("sample_period", "inputs", "outputs", "A", "B", "C", "D")
               if k not in data]
    if missing:
        raise fail(f"missing key(s) {', '.join(missing)}")

    def signals(key: str, limits: bool) -> tuple[Signal, ...]:
        rows = data[key]
        if not isinstance(rows, Sequence) or isinstance(rows, str):
            raise fail(f"{key}: a list of {{name, unit{', lower, upper' if limits else ''}}}")
        out = []
        for i, row in enumerate(rows):
            keys = {"name", "unit", "lower", "upper"} if limits else {"name", "unit"}
            if not isinstance(row, Mapping) or "name" not in row or set(row) - keys:
                raise fail(f"{key}[{i}] = {row!r}; allowed keys: {', '.join(sorted(keys))} "
                           "(name required)")
            lo, hi = row.get("lower"), row.get("upper")
            for side, v in (("lower", lo), ("upper", hi)):
                if v is not None and (isinstance(v, bool) or not isinstance(v, (int, float))):
                    raise fail(f"{key}[{i}].{side} = {v!r}; allowed: a number (or none)")
            out.append(Signal(row["name"], row.get("unit", "1"),
                              -math.inf if lo is None else float(lo),
                              math.inf if hi is None else float(hi)))
        return tuple(out)

    ins, outs = signals("inputs", False), signals("outputs", True)
    n = data.get("n_states")
    if n is not None and (isinstance(n, bool) or not isinstance(n, int) or n < 0
                          or len(data["A"]) != n):
        raise fail(f"n_states = {n!r} does not match A ({len(data['A'])} rows); allowed: the "
                   "number of rows of A")
    A, B, C = data["A"], data["B"], data["C"]
    try:
        return StateSpaceParams(A, B, C, data["D"], ins, outs, data["sample_period"],
                                str(data.get("description", "")))
    except ValueError as exc:
        raise fail(str(exc)) from None


def load_state_space(path: str | Path) -> StateSpaceParams:
    """Read a state-space JSON file (:meth:`StateSpaceParams.save`); ValueError (one line
    naming the file) if it is not one."""
    path = Path(path)
    try:
        data = json.loads(path.read_text())
    except OSError as exc:
        raise ValueError(f"{path}: cannot read ({exc.strerror})") from None
    except json.JSONDecodeError as exc:
        raise ValueError(f"{path}: not JSON ({exc.msg} at line {exc.lineno})") from None
    return state_space_from_mapping(data, str(path))


# ---------------------------------------------------------------------- workspace
class Workspace:
    """The numbers of a controller in one float64 array (see the module docstring).

    Layout after the header: the state ``x`` (n) and the inputs ``y`` (m) side by side (the
    vector ``w = [x; y]``), the outputs (p), a scratch vector (p + n), the matrix
    ``M = [[C, D], [A, B]]`` (row-major, (p + n) x (n + m)), the lower and upper limits (p):
    one sample is ``v = M w``, ``u = clip(v[:p])``, ``x = v[p:]``.

    Attributes
    ----------
    array : numpy.ndarray, shape (size,)
        The whole workspace; everything below is a view of it.
    timing : numpy.ndarray, shape (3,)
        The sample period [s], the samples run so far, :data:`MULTIPLE_RTOL`.
    vector : numpy.ndarray, shape (n + m,)
        ``w = [x; y]``.
    scratch : numpy.ndarray, shape (p + n,)
        ``v = M w`` of the last sample.
    state : numpy.ndarray, shape (n,)
    inputs : numpy.ndarray, shape (m,)
    outputs : numpy.ndarray, shape (p,)
    matrix : numpy.ndarray, shape (p + n, n + m)
    A, B, C, D : numpy.ndarray
        Views of ``matrix``, shapes (n, n), (n, m), (p, n), (p, m).
    lower, upper : numpy.ndarray, shape (p,)
    """

    def __init__(self, params: StateSpaceParams) -> None:
        n, m, p = params.n_states, len(params.inputs), len(params.outputs)
        sizes = {"state": n, "inputs": m, "outputs": p, "scratch": p + n,
                 "matrix": (p + n) * (n + m), "lower": p, "upper": p}
        total = _HEADER + sum(sizes.values())
        self.array = np.zeros(total)
        self.array[[_SIZE, _NX, _NY, _NU, _TS, _RTOL]] = (total, n, m, p, params.sample_period,
                                                          MULTIPLE_RTOL)
        self.timing = self.array[_TS:_RTOL + 1]
        at = _HEADER
        for name, size in sizes.items():
            view = self.array[at:at + size]
            setattr(self, name, view.reshape(p + n, n + m) if name == "matrix" else view)
            at += size
        mat = self.matrix
        self.C, self.D, self.A, self.B = mat[:p, :n], mat[:p, n:], mat[p:, :n], mat[p:, n:]
        for name in ("A", "B", "C", "D", "lower", "upper"):
            getattr(self, name)[...] = getattr(params, name)
        self.vector = self.array[_HEADER:_HEADER + n + m]   # w = [x; y]

    @property
    def samples(self) -> int:
        """int: samples run so far (a float in the array)."""
        return int(self.array[_COUNT])


#: The FMU's "no limit" of an output (a start value every XML reader parses; no force comes
#: near it).
NO_LIMIT = 1e300


# ---------------------------------------------------------------------- the law
class StateSpaceController(Law):
    """The discrete linear law of the module docstring, with its state in a :class:`Workspace`.

    Parameters
    ----------
    params : StateSpaceParams

    Notes
    -----
    :meth:`step` is the numpy reference; :meth:`compiled_step` the same law compiled (they
    agree to rounding). A call that fails validation raises ValueError and leaves the state
    unchanged.
    """

    KIND = "state_space"
    TABLE = "controller"
    FMU = "StateSpaceController"
    DESCRIPTION = ("Generic discrete state-space controller u = clip(C x + D y), x+ = A x + B y "
                   "(matrices in resources/state_space.json)")
    PARAMS = StateSpaceParams
    COMPILED = ("state_space_core", (1, 2, 1, 1, 1, 1, 1, 1, 1))
    #: The FMU's matrices: ``resources/<RESOURCE>`` (this module's JSON format), read at
    #: instantiation and checked against the FMU's layout (:meth:`load_resource`).
    RESOURCE = "state_space.json"
    #: The default FMU's matrices, beside this module: the paper's P law for two sites (no
    #: state, ``D = 1e9 I``, Ts = 0.25 ms).
    DEFAULT_RESOURCE = "state_space_default.json"

    # ------------------------------------------------------------------ interface
    @classmethod
    def layout_for(cls, params: StateSpaceParams, n_sites: int) -> dict[str, Any]:
        """The interface of ``params``: its signals (name, unit, description), output limits
        (None: none), number of states and sample period."""
        def lim(x: float) -> float | None:
            return None if math.isinf(x) else x

        return {
            "inputs": [[s.name, s.unit, f"Input {i} of the state-space law (plant output "
                        f"{s.name})"] for i, s in enumerate(params.inputs, start=1)],
            "outputs": [[s.name, s.unit, f"Output {i} of the state-space law (plant input "
                         f"{s.name})"] for i, s in enumerate(params.outputs, start=1)],
            "lower": [lim(s.lower) for s in params.outputs],
            "upper": [lim(s.upper) for s in params.outputs],
            "n_states": params.n_states, "sample_period": params.sample_period}

    @classmethod
    def default_layout(cls) -> dict[str, Any]:
        """The layout of the default FMU's matrices (:data:`DEFAULT_RESOURCE`)."""
        params = load_state_space(Path(__file__).resolve().parent / cls.DEFAULT_RESOURCE)
        return {**cls.layout_for(params, 2), "description": (
            f"{cls.DESCRIPTION}; this build: the paper's P law, 2 sites x gauges C/E, D = 1e9 "
            f"N/strain, no state, Ts = 0.25 ms")}

    @classmethod
    def load_resource(cls, path: Path, layout: Mapping[str, Any]) -> StateSpaceParams:
        """The matrices file ``path``, checked against ``layout`` (ValueError: one line)."""
        if not path.is_file():
            raise ValueError(f"resources/{path.name} is missing: the FMU has no matrices")
        params = load_state_space(path)
        want = {"inputs": [tuple(r[:2]) for r in layout["inputs"]],
                "outputs": [tuple(r[:2]) for r in layout["outputs"]],
                "n_states": layout["n_states"], "sample_period": float(layout["sample_period"])}
        have = {"inputs": [(s.name, s.unit) for s in params.inputs],
                "outputs": [(s.name, s.unit) for s in params.outputs],
                "n_states": params.n_states, "sample_period": params.sample_period}
        for key, value in want.items():
            if have[key] != value:
                raise ValueError(f"resources/{path.name} does not fit this FMU: {key} "
                                 f"{have[key]!r}; the FMU declares {value!r}")
        return params

    @classmethod
    def io_ports(cls, layout: Mapping[str, Any]) -> tuple[Port, ...]:
        return (*(real_input(n, u, d) for n, u, d in layout["inputs"]),
                *(real_output(n, u, f"{d} (after the step: from the inputs set before it)")
                  for n, u, d in layout["outputs"]))

    @classmethod
    def parameter_ports(cls, layout: Mapping[str, Any]) -> tuple[Port, ...]:
        """The tunable saturation limits ``lower_limit_<output>``, ``upper_limit_<output>``
        (start: the layout's, else -+ :data:`NO_LIMIT`)."""
        out = []
        for (name, unit, _doc), lo, hi in zip(layout["outputs"], layout["lower"],
                                              layout["upper"]):
            for side, start, none in (("lower", lo, -NO_LIMIT), ("upper", hi, NO_LIMIT)):
                out.append(parameter(limit(side, name), unit,
                                     f"Saturation: {side} limit of {name} (+-{NO_LIMIT!r} = none)",
                                     none if start is None else float(start)))
        return tuple(out)

    @classmethod
    def encode(cls, params: StateSpaceParams, layout: Mapping[str, Any]) -> dict[str, Any]:
        """Nothing: the limits are the layout's starts."""
        return {}

    @classmethod
    def decode(cls, values: Mapping[str, Any], layout: Mapping[str, Any],
               base: StateSpaceParams | None = None) -> StateSpaceParams:
        """``base`` (the matrices of :meth:`load_resource`) with the limits of ``values``."""
        if base is None:
            raise ValueError("a state-space law's matrices come from its resource file")
        outs = [n for n, _u, _d in layout["outputs"]]
        lower = [values[limit("lower", o)] for o in outs]
        upper = [values[limit("upper", o)] for o in outs]
        bad = [o for o, lo, hi in zip(outs, lower, upper) if not lo <= hi]
        if bad:
            raise ValueError(f"lower_limit > upper_limit (or NaN) for {', '.join(bad)}; "
                             "allowed: lower <= upper")
        return base.with_limits(lower, upper)

    def __init__(self, params: StateSpaceParams) -> None:
        self._params = params
        self.workspace = Workspace(params)

    @property
    def params(self) -> StateSpaceParams:
        """StateSpaceParams: assigning one with the same matrices and signals (other limits)
        keeps the state; anything else is a ValueError."""
        return self._params

    @params.setter
    def params(self, params: StateSpaceParams) -> None:
        old = self._params
        same = (params.input_names == old.input_names and params.output_names ==
                old.output_names and params.sample_period == old.sample_period
                and all(np.array_equal(getattr(params, k), getattr(old, k)) for k in "ABCD"))
        if not same:
            raise ValueError("only the output limits of a state-space controller can change "
                             "after it is made (the matrices, signals and sample period are "
                             "fixed)")
        self._params = params
        self.workspace.lower[:] = params.lower
        self.workspace.upper[:] = params.upper

    def reset(self) -> None:
        """State and outputs to zero."""
        self.workspace.state[:] = 0.0
        self.workspace.outputs[:] = 0.0

    def get_state(self) -> np.ndarray:
        """numpy.ndarray, shape (n + p,): a copy of the state and the last outputs."""
        ws = self.workspace
        return np.concatenate([ws.state, ws.outputs])

    def set_state(self, state: np.ndarray) -> None:
        """Restore :meth:`get_state`; ValueError for a wrong shape or non-finite entries."""
        ws = self.workspace
        arr = np.asarray(state, dtype=float)
        size = ws.state.size + ws.outputs.size
        if arr.shape != (size,):
            raise ValueError(f"state must have shape ({size},), got {arr.shape}")
        if not np.all(np.isfinite(arr)):
            raise ValueError("state must be finite")
        ws.state[:] = arr[:ws.state.size]
        ws.outputs[:] = arr[ws.state.size:]

    def samples_in(self, h: float) -> int:
        """Number of samples in a step ``h`` [s]; ValueError if it is not a multiple of Ts."""
        ts = self._params.sample_period
        ok = math.isfinite(h) and h >= 0
        k = int(h / ts + 0.5) if ok else 0
        if not ok or abs(h / ts - k) > MULTIPLE_RTOL * max(1.0, h / ts):
            raise ValueError(f"step {h!r} s is not an integer multiple of the controller's "
                             f"sample period {ts!r} s")
        return k

    def step(self, t: float, h: float, y: np.ndarray | None = None) -> np.ndarray:
        """Advance over ``[t, t + h]`` with the inputs held (numpy reference).

        Parameters
        ----------
        t : float
            Start of the step [s] (finite; the law is time-invariant).
        h : float
            Step [s], an integer multiple of the sample period.
        y : array_like, shape (m,), optional
            Inputs; default: the workspace's inputs (as a compiled caller has set them).

        Returns
        -------
        numpy.ndarray, shape (p,)
            The outputs after the step (a copy; also in the workspace).
        """
        ws = self.workspace
        if not math.isfinite(t):
            raise ValueError(f"time t = {t!r} is not finite")
        k = self.samples_in(h)
        if y is not None:
            yy = np.asarray(y, dtype=float)
            if yy.shape != ws.inputs.shape:
                raise ValueError(f"inputs must have shape {ws.inputs.shape}, got {yy.shape}")
        else:
            yy = ws.inputs
        bad = np.flatnonzero(~np.isfinite(yy))
        if bad.size:
            names = ", ".join(self._params.input_names[i] for i in bad)
            raise ValueError(f"non-finite input(s) {names}: {yy[bad].tolist()}")
        ws.inputs[:] = yy
        p = ws.outputs.size
        for _ in range(k):
            v = ws.matrix @ ws.vector           # one matrix-vector product per sample
            ws.outputs[:] = np.clip(v[:p], ws.lower, ws.upper)
            ws.state[:] = v[p:]
            ws.array[_COUNT] += 1.0
        return ws.outputs.copy()

    def initial_outputs(self) -> np.ndarray:
        """The outputs of the last sample (zero after :meth:`reset`)."""
        return self.workspace.outputs.copy()

    def advance(self, t: float, h: float, inputs: np.ndarray, outputs: np.ndarray) -> None:
        """:meth:`step` with ``inputs``, the outputs written into ``outputs``."""
        outputs[:] = self.step(t, h, inputs)

    def compiled_step(self, inputs: np.ndarray, outputs: np.ndarray) -> Any:
        """This law's compiled step (:class:`controller.compiled.CompiledLaw`, core
        :func:`state_space_core`) reading the inputs
        from ``inputs`` (shape (m,)) and writing the outputs into ``outputs`` (shape (p,)),
        float64 buffers; None without numba or with compiled steps switched off. A step it
        refuses (bad time, step or input; nothing changed) is left to :meth:`step`, which
        names the problem."""
        ws = self.workspace

        def pack() -> tuple[object, list[np.ndarray]]:
            return ws, [ws.timing, ws.matrix, ws.vector, ws.scratch, ws.lower, ws.upper,
                        ws.outputs, inputs, outputs]

        return compiled_law(self.KIND, pack)


# ------------------------------------------------------------------------ compiled core
# the timing slots of the workspace's header as the core reads them: the sample period, the
# samples run, the tolerance of "h is a multiple of the sample period"
S_PERIOD, S_COUNT, S_RTOL = range(3)


def state_space_core(t, h, timing, matrix, w, scratch, lower, upper, law_outputs, inputs,
                     outputs):
    """:meth:`controller.StateSpaceController.step` on the views of its workspace: ``w = [x;
    y]`` (the state, then the inputs the law holds), ``matrix = [[C, D], [A, B]]``, one
    product per sample (``scratch = matrix w``)."""
    if not (math.isfinite(t) and math.isfinite(h) and h >= 0.0):
        return REFUSED
    ts = timing[S_PERIOD]
    k_float = h / ts
    k = int(k_float + 0.5)
    if abs(k_float - k) > timing[S_RTOL] * max(1.0, k_float):
        return REFUSED
    m = inputs.size
    p = law_outputs.size
    n = w.size - m
    for j in range(m):
        if not math.isfinite(inputs[j]):
            return REFUSED
    for j in range(m):
        w[n + j] = inputs[j]
    for _ in range(k):
        np.dot(matrix, w, scratch)                  # BLAS, no allocation
        for i in range(p):
            v = scratch[i]
            lo = lower[i]
            hi = upper[i]
            law_outputs[i] = lo if v < lo else (hi if v > hi else v)  # numpy's clip
        for i in range(n):
            w[i] = scratch[p + i]
        timing[S_COUNT] += 1.0
    for i in range(p):
        outputs[i] = law_outputs[i]
    return OK
