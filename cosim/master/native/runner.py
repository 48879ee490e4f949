"""Chunks of base steps in C (``steps.c``) for an :class:`~cosim.master.execution.Execution`.

:meth:`NativeLoop.for_execution` says whether the native loop applies to an execution with
its observers and manipulators, and builds the C plan from the algorithm's own (the same
exchange plan, delay lines and buffers: the C loop writes the master's output and input
buffers in place). It applies when

* every slave gives C entry points (:meth:`~cosim.master.slave.Slave.native_calls`);
* every observer is the :class:`~cosim.master.recorder.Recorder` (at most one, all of its
  variables exchanged), an :class:`~cosim.master.limits.OutputLimit`, or one that acts only
  at multiples of its ``stride_ticks`` (the progress bar: called at chunk ends, which fall on
  those multiples);
* every manipulator says when it acts next (``next_action_tick(execution, tick)``): a chunk
  starts at each such tick, and Python runs the manipulators there;
* the times ``start + k * H`` of the run are exact in C (``k * num < 2**53``).

Anything else (a general observer or manipulator) runs in the Python loop, with the same
results. Between chunks Python syncs the delay lines and the newest-sample ticks both ways,
hands the recorded rows to the recorder and runs the strided observers; an event in a chunk
(an FMI failure, a failed compiled step, a non-finite output, a limit) stops it at that point,
and Python reports it exactly as the Python loop does (same exception, time, FMU, call and
message, same partial result).
"""

from __future__ import annotations

import ctypes
import os
from collections.abc import Callable, Sequence

import numpy as np

from ..limits import OutputLimit
from ..recorder import Recorder
from ..slave import CompiledCalls, FmiCalls
from . import library

__all__ = ["LOOP_ENV", "MAX_CHUNK", "NativeLoop"]

#: Environment variable: ``python`` forces the Python loop, ``auto`` (default) lets the
#: execution choose.
LOOP_ENV = "DRILLCOSIM_MASTER_LOOP"
#: Most base steps in one C call (Python handles signals and flushes rows between chunks).
MAX_CHUNK = 4096

_DONE, _FAILED, _STEP_FAILED, _NON_FINITE, _LIMIT, _FULL = range(6)
_CALLS = ("fmi2SetReal", "fmi2DoStep", "fmi2GetReal")
_I32P = ctypes.POINTER(ctypes.c_int32)
_F64P = ctypes.POINTER(ctypes.c_double)
_VP = ctypes.c_void_p


class _Line(ctypes.Structure):
    _fields_ = [("n", ctypes.c_int32), ("depth", ctypes.c_int32), ("pos", ctypes.c_int32),
                ("linear", ctypes.c_int32), ("f", ctypes.c_double), ("buf", _F64P)]


class _Slave(ctypes.Structure):
    _fields_ = [("kind", ctypes.c_int32), ("period", ctypes.c_int32), ("h", ctypes.c_double),
                ("component", _VP), ("set_real", _VP), ("do_step", _VP), ("get_real", _VP),
                ("in_vr", _VP), ("out_vr", _VP), ("step", _VP), ("context", _VP),
                ("step_in", _VP), ("step_out", _VP), ("in_slot", _I32P), ("out_slot", _I32P),
                ("n_in", ctypes.c_int32), ("n_out", ctypes.c_int32), ("u", _VP), ("y", _VP),
                ("n_plain", ctypes.c_int32), ("n_delayed", ctypes.c_int32),
                ("n_push", ctypes.c_int32), ("plain", _I32P), ("delayed", _I32P),
                ("push", _I32P), ("timing", _F64P)]


class _Steps(ctypes.Structure):
    _fields_ = [("algorithm", ctypes.c_int32), ("n_slaves", ctypes.c_int32),
                ("n_lines", ctypes.c_int32), ("n_y", ctypes.c_int32),
                ("slaves", ctypes.POINTER(_Slave)), ("lines", ctypes.POINTER(_Line)),
                ("horizons", _F64P), ("y", _VP), ("newest", ctypes.POINTER(ctypes.c_int64)),
                ("start", ctypes.c_double), ("num", ctypes.c_int64), ("den", ctypes.c_int64),
                ("rec_every", ctypes.c_int64), ("rec_capacity", ctypes.c_int64),
                ("rec_rows", ctypes.c_int64), ("n_rec", ctypes.c_int32),
                ("n_limit", ctypes.c_int32), ("rec_index", _I32P), ("rec", _F64P),
                ("limit_index", _I32P), ("limit", _F64P), ("tick", ctypes.c_int64),
                ("event_tick", ctypes.c_int64), ("event", ctypes.c_int32),
                ("event_slave", ctypes.c_int32), ("event_call", ctypes.c_int32),
                ("event_status", ctypes.c_int32), ("resume", ctypes.c_int32)]


def _i32(values: Sequence[int]):
    return (ctypes.c_int32 * max(1, len(values)))(*values)


def _f64(values: Sequence[float]):
    return (ctypes.c_double * max(1, len(values)))(*values)


def _loop_choice() -> str:
    choice = os.environ.get(LOOP_ENV, "auto").strip().lower() or "auto"
    if choice not in ("auto", "python"):
        raise ValueError(f"${LOOP_ENV}: 'auto' or 'python', got {choice!r}")
    return choice


class NativeLoop:
    """The C plan of one execution; :meth:`run` advances it in chunks.

    Build with :meth:`for_execution` (None where the native loop does not apply).
    """

    def __init__(self, execution, lib: ctypes.CDLL, recorder: Recorder | None,
                 limits: Sequence[OutputLimit], strided: Sequence[Callable],
                 strides: Sequence[int]):
        alg = execution.algorithm
        self.execution = execution
        self.algorithm = alg
        self.run_steps = lib.dcs_run_steps
        self.recorder = recorder
        self.strided = tuple(strided)
        self.strides = tuple(strides)
        #: the observers and manipulators the plan was made for
        self.observed = (list(execution.observers), list(execution.manipulators))
        self._keep: list = []                 # every ctypes array the C plan points at
        plans = alg.plans
        self.lines = list(alg.lines)
        line_index = {id(line): i for i, line in enumerate(self.lines)}
        self.c_lines = (_Line * max(1, len(self.lines)))()
        self.line_bufs = []
        for c, line in zip(self.c_lines, self.lines):
            buf = (ctypes.c_double * line.depth)()
            self.line_bufs.append(buf)
            c.n, c.depth, c.linear, c.f = line.n, line.depth, int(line.linear), line.f
            c.buf = ctypes.cast(buf, _F64P)
        horizons: list[float] = []
        self.c_slaves = (_Slave * len(plans))()
        self.compiled: list[tuple[_Slave, object]] = []
        y_address = ctypes.addressof(alg.y)
        for c, plan in zip(self.c_slaves, plans):
            c.period, c.h = plan.period, plan.h
            c.timing = ctypes.cast(ctypes.byref(alg.timing, 8 * 4 * plan.index), _F64P)
            c.n_in, c.n_out = len(plan.in_names), len(plan.out_names)
            c.u = ctypes.addressof(plan.u)
            c.y = y_address + 8 * plan.out_offset
            delayed = []
            for pos, line, hz, p in plan.lines:
                delayed += [pos, line_index[id(line)], len(horizons), p]
                horizons += hz
            plain = [v for pair in plan.plain for v in pair]
            push = [v for y_idx, line in plan.pushes for v in (y_idx, line_index[id(line)])]
            arrays = [_i32(plain), _i32(delayed), _i32(push)]
            self._keep += arrays
            c.plain, c.delayed, c.push = (ctypes.cast(a, _I32P) for a in arrays)
            c.n_plain, c.n_delayed, c.n_push = len(plan.plain), len(plan.lines), len(plan.pushes)
            calls = plan.slave.native_calls()
            if isinstance(calls, FmiCalls):
                c.kind = 0
                c.component, c.set_real, c.do_step, c.get_real = (
                    calls.component, calls.set_real, calls.do_step, calls.get_real)
                c.in_vr, c.out_vr = calls.in_vrs, calls.out_vrs
            else:
                c.kind = 1
                self.compiled.append((c, plan.slave))
        self.c_horizons = _f64(horizons)
        self.newest = (ctypes.c_int64 * len(plans))()
        s = self.steps = _Steps()
        s.resume = -1
        s.algorithm = 0 if alg.name == "jacobi" else 1
        s.n_slaves, s.n_lines = len(plans), len(self.lines)
        s.n_y = len(alg.y)
        s.slaves = ctypes.cast(self.c_slaves, ctypes.POINTER(_Slave))
        s.lines = ctypes.cast(self.c_lines, ctypes.POINTER(_Line))
        s.horizons = ctypes.cast(self.c_horizons, _F64P)
        s.y = y_address
        s.newest = ctypes.cast(self.newest, ctypes.POINTER(ctypes.c_int64))
        frac = execution.base_fraction
        s.start, s.num, s.den = execution.start_time, frac.numerator, frac.denominator
        index = alg.y_index
        limit_index = [index[r] for lim in limits for r in lim.refs]
        limit = [lim.bound for lim in limits for _r in lim.refs]
        self.c_limit_index, self.c_limit = _i32(limit_index), _f64(limit)
        s.n_limit = len(limit_index)
        s.limit_index = ctypes.cast(self.c_limit_index, _I32P)
        s.limit = ctypes.cast(self.c_limit, _F64P)
        columns = recorder.exchanged_columns(index) if recorder is not None else []
        self.c_rec_index = _i32(columns)
        s.n_rec = len(columns)
        s.rec_index = ctypes.cast(self.c_rec_index, _I32P)
        every = recorder.interval_ticks if recorder is not None else 0
        s.rec_every = every
        capacity = MAX_CHUNK // every + 2 if every else 1
        self.rec = np.zeros((capacity, 1 + len(columns)))
        s.rec = self.rec.ctypes.data_as(_F64P)
        s.rec_capacity = capacity

    # -- when it applies -------------------------------------------------------------------
    @classmethod
    def for_execution(cls, execution, observers: Sequence, manipulators: Sequence
                      ) -> NativeLoop | None:
        """The native loop of ``execution`` with these observers and manipulators, or None
        where it does not apply (see the module docstring)."""
        if _loop_choice() == "python":
            return None
        alg = execution.algorithm
        if getattr(alg, "name", None) not in ("jacobi", "gauss_seidel"):
            return None
        if any(not hasattr(m, "next_action_tick") for m in manipulators):
            return None
        recorder, limits, strided, strides = None, [], [], []
        for obs in observers:
            if type(obs) is Recorder and recorder is None \
                    and obs.exchanged_columns(alg.y_index) is not None:
                recorder = obs
            elif type(obs) is OutputLimit and all(r in alg.y_index for r in obs.refs):
                limits.append(obs)
            elif isinstance(getattr(obs, "stride_ticks", None), int) and obs.stride_ticks >= 1:
                strided.append(obs.on_step)
                strides.append(obs.stride_ticks)
            else:
                return None
        for plan in alg.plans:
            calls = plan.slave.native_calls()
            if not isinstance(calls, (FmiCalls, CompiledCalls)):
                return None
        lib = library()
        if lib is None:
            return None
        return cls(execution, lib, recorder, limits, strided, strides)

    def exact_until(self, k_stop: int) -> bool:
        """Whether the C times of ticks up to ``k_stop`` equal Python's (exact products)."""
        s = self.steps
        return k_stop * s.num < 2**53 and s.den < 2**53

    # -- running ----------------------------------------------------------------------------
    def _compiled_ready(self) -> bool:
        """Take each compiled step anew (it may change after a Python call); False if one is
        gone (the Python loop then takes over)."""
        keep = []
        for c, slave in self.compiled:
            calls = slave.native_calls()
            if not isinstance(calls, CompiledCalls):
                return False
            slots = (_i32(calls.input_slots), _i32(calls.output_slots))
            keep.append(slots)
            c.step, c.context = calls.step, calls.context
            c.step_in, c.step_out = calls.inputs, calls.outputs
            c.in_slot, c.out_slot = (ctypes.cast(a, _I32P) for a in slots)
        self._compiled_slots = keep
        return True

    def _sync_in(self) -> None:
        for c, line, buf in zip(self.c_lines, self.lines, self.line_bufs):
            buf[:] = line.buf
            c.pos = line.pos
        self.newest[:] = self.algorithm.newest

    def _sync_out(self) -> None:
        for c, line, buf in zip(self.c_lines, self.lines, self.line_bufs):
            line.buf = buf[:]
            line.pos = c.pos
        self.algorithm.newest[:] = self.newest[:]
        s = self.steps
        if s.rec_rows:
            self.recorder.add_rows(self.rec[:s.rec_rows].copy())
            s.rec_rows = 0

    def _chunk_end(self, tick: int, k_stop: int, manipulators: Sequence) -> int:
        end = min(k_stop, tick + MAX_CHUNK)
        for stride in self.strides:
            end = min(end, (tick // stride + 1) * stride)
        for m in manipulators:
            nxt = m.next_action_tick(self.execution, tick + 1)
            if nxt is not None:
                end = min(end, max(nxt, tick + 1))
        return end

    def run(self, k_stop: int, observers: Sequence[Callable],
            manipulators: Sequence) -> bool:
        """Advance the execution to tick ``k_stop`` in chunks.

        ``observers``: every observer's ``on_step`` in order (run in Python at a limit's tick);
        ``manipulators``: the manipulator objects (run in Python at each chunk's start).
        Returns False if a compiled step went away (the caller continues in Python from
        ``execution.tick``). Raises what the Python loop raises, at the same point.
        """
        ex = self.execution
        s = self.steps
        befores = tuple(m.before_step for m in manipulators)
        settled = False          # a failed compiled step was settled in Python: go on after it
        while ex.tick < k_stop:
            tick = ex.tick
            if not settled:
                for before in befores:
                    before(ex)
            if self.compiled and not self._compiled_ready():
                if settled:
                    raise RuntimeError("internal: a compiled step went away in the middle of "
                                       "a step")
                return False
            end = self._chunk_end(tick, k_stop, manipulators)
            self._sync_in()
            s.tick = tick
            event = self.run_steps(ctypes.byref(s), end)
            self._sync_out()
            ex.tick = s.tick
            settled = False
            if event in (_DONE, _FULL):
                for obs in self.strided:
                    obs(ex)
                continue
            settled = self._report(event, observers)
        return True

    def _report(self, event: int, observers: Sequence[Callable]) -> bool:
        """Do what the Python loop does at the event that stopped the chunk: raise its error,
        or run the observers of a limit's tick, or settle a failed compiled step in Python
        (True: it went well, the chunk goes on after it)."""
        ex, s = self.execution, self.steps
        if event == _LIMIT:            # tick completed: its observers in order, in Python
            for obs in observers:
                obs(ex)
            return False
        if event == _NON_FINITE:
            self.algorithm.check_finite()
            raise RuntimeError("internal: the native loop saw a non-finite output the "
                               "algorithm's check did not")
        plan = self.algorithm.plans[s.event_slave]
        t = ex.time_of(s.event_tick)
        status = s.event_status
        if event == _STEP_FAILED:
            status = plan.slave.native_step_failed(status, t, plan.h)
            if status <= 1:
                s.resume = s.event_slave
                return True
        elif event != _FAILED:
            raise RuntimeError(f"internal: unknown event {event} of the native loop")
        plan.slave.fail(status, _CALLS[s.event_call], t)
        raise RuntimeError("internal: Slave.fail returned")   # pragma: no cover
