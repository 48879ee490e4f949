"""Co-simulation algorithms: fixed-step Jacobi and Gauss-Seidel, multirate.

Both share one interface (as in libcosim): :meth:`setup` builds the exchange
plan once, :meth:`initialize` reads the initial outputs and sets the initial
inputs, :meth:`do_step` advances the system from tick ``k`` to ``k + 1``. They
drive :class:`~cosim.master.slave.Slave` s (FMUs or in-process components alike).

Multirate: component ``i`` has a period of ``p_i`` base steps; it steps only at ticks
``k`` with ``k % p_i == 0``, with step size ``p_i * H``. Its outputs are held
between its communication points.

* **Jacobi** (parallel): at tick k every due component steps with the inputs set at
  tick k; then, at tick k + 1, the components that reached their communication point
  publish their outputs and those due next get their new inputs. The inputs
  used over ``[t_k, t_k+1]`` are outputs sampled at ``t_k``.
* **Gauss-Seidel** (sequential): due components step one after another in
  ``order``; each first takes its inputs from the newest outputs (already at
  ``t_k+1`` for the components before it), steps, and publishes at once. Relative to
  Jacobi, a connection from an earlier to a later component has one step less delay.

:func:`newest_sample_tick` states this exchange timing (which source sample a
target sees when) once: the algorithms take their coupling horizons from it, and
so does the linear stability prediction (:mod:`cosim.study.stability`).

Initialisation: all outputs are read at the start time, then as many sweeps as
there are components, in stepping order, set each one's inputs and re-read its
outputs (propagating direct feedthrough along any chain of components).

The hot loop works on ctypes buffers with precomputed index pairs: per step and
component one :meth:`~cosim.master.slave.Slave.write_inputs`, one
:meth:`~cosim.master.slave.Slave.do_step` and one
:meth:`~cosim.master.slave.Slave.read_outputs`, no dict lookups and no per-step
allocation besides floats.
"""

from __future__ import annotations

import ctypes
import math
from collections.abc import Callable, Mapping, Sequence
from time import perf_counter

from .delays import DelayLine
from .errors import DivergenceError
from .slave import Slave
from .system import SystemSpec, split_variable

__all__ = ["GaussSeidelAlgorithm", "JacobiAlgorithm", "make_algorithm", "newest_sample_tick"]


def newest_sample_tick(algorithm: str, source_first: bool, source_period: int,
                       tick: int) -> int:
    """Tick of the newest source sample a target sees for its step from ``tick``.

    The exchange timing of the algorithms, stated once (the delay lines count their
    delays back from this sample, :mod:`cosim.master.delays`):

    * Jacobi: the source's last communication point at or before ``tick``;
    * Gauss-Seidel, source earlier in the stepping order (``source_first``): the end of the
      source's step that contains ``tick`` (it has stepped already);
    * Gauss-Seidel, source later in the order: ``tick`` if the source is due at ``tick`` (not
      stepped yet), else the end of its step that contains ``tick``.

    Parameters
    ----------
    algorithm : {"jacobi", "gauss_seidel"}
    source_first : bool
        The source steps before the target (Gauss-Seidel only).
    source_period : int
        Source period [base steps], >= 1.
    tick : int
        Start of the target's step [base steps], a multiple of the target's period.

    Returns
    -------
    int
    """
    last = tick - tick % source_period
    if algorithm == "jacobi":
        return last
    if algorithm != "gauss_seidel":
        raise ValueError(f"algorithm: 'jacobi' or 'gauss_seidel', got {algorithm!r}")
    if not source_first and last == tick:
        return tick
    return last + source_period


class _Plan:
    """Precomputed exchange data of one component (built once in ``setup``)."""

    def __init__(self, index: int, slave: Slave, period: int, base_step: float):
        self.index = index
        self.slave = slave
        self.name = slave.name
        self.period = period
        self.h = period * base_step
        self.out_names: list[str] = []
        self.out_offset = 0
        self.in_names: list[str] = []
        self.plain: list[tuple[int, int]] = []            # (input pos, y index)
        # (input pos, line, coupling horizons by tick % source period)
        self.lines: list[tuple[int, DelayLine, tuple[float, ...], int]] = []
        self.pushes: list[tuple[int, DelayLine]] = []     # (y index, line)

    def tuple(self, y) -> tuple:
        """The flat tuple unpacked by the hot loop (after binding the slave's buffers)."""
        s = self.slave
        self.u = (ctypes.c_double * max(1, len(self.in_names)))()
        s.bind(self.out_names, y, self.out_offset, self.in_names, self.u)
        return (self.index, self.period, self.h, s.do_step, s.read_outputs, s.write_inputs,
                self.u, tuple(self.plain), tuple(self.lines), tuple(self.pushes))


class _Algorithm:
    """Common setup, initialisation, state and divergence check."""

    name = "base"

    def __init__(self):
        self.plans: list[_Plan] = []
        self.y = None
        self.newest: list[int] = []
        self.lines: list[DelayLine] = []
        self.y_names: list[str] = []
        #: per component (in stepping order) [step total, step max, exchange total, steps]
        #: [s, s, s, 1]: the wall time of its calls, kept by both loops (:meth:`timings`)
        self.timing = (ctypes.c_double * 4)()

    def setup(self, system: SystemSpec, slaves: Mapping[str, Slave],
              time_of: Callable[[int], float],
              read_outputs: Sequence[str] = ()) -> None:
        """Build the exchange plan.

        Parameters
        ----------
        system : SystemSpec
        slaves : mapping of name to Slave
            Instantiated components.
        time_of : callable
            Tick -> time [s] (exact conversion owned by the execution).
        read_outputs : sequence of str
            Extra ``'fmu.var'`` outputs read at every communication point
            (recorded or monitored), besides the connection sources.
        """
        self.time_of = time_of
        order = system.stepping_order
        H = system.base_step
        self.plans = [_Plan(i, slaves[n], system.fmu(n).sample_period_ticks, H)
                      for i, n in enumerate(order)]
        self.timing = (ctypes.c_double * (4 * max(1, len(self.plans))))()
        by_name = {p.name: p for p in self.plans}
        for ref in [c.source for c in system.connections] + list(read_outputs):
            fmu, var = split_variable(ref, "output")
            plan = by_name[fmu]
            plan.slave.check_variable(var, ("output", "local", "parameter",
                                            "calculatedParameter", "input"))
            if var not in plan.out_names:
                plan.out_names.append(var)
        offset = 0
        self.y_names = []
        for plan in self.plans:
            plan.out_offset = offset
            offset += len(plan.out_names)
            self.y_names += [f"{plan.name}.{v}" for v in plan.out_names]
        self.y_index = {n: i for i, n in enumerate(self.y_names)}
        self.y = (ctypes.c_double * max(1, offset))()
        self.lines = []
        for c in system.connections:
            src_fmu, _ = split_variable(c.source, "source")
            dst_fmu, dst_var = split_variable(c.target, "target")
            dst = by_name[dst_fmu]
            src = by_name[src_fmu]
            dst.slave.check_variable(dst_var, ("input", "parameter"))
            pos = len(dst.in_names)
            dst.in_names.append(dst_var)
            y_idx = self.y_index[c.source]
            if c.delay == 0.0 and c.coupling == "zoh":
                dst.plain.append((pos, y_idx))
                continue
            line = DelayLine(c.delay, src.h, c.coupling == "linear")
            self.lines.append(line)
            src.pushes.append((y_idx, line))
            # horizon [source periods]: newest source sample -> midpoint of the target's step
            p = src.period
            first = src.index < dst.index
            horizons = tuple((k + dst.period / 2.0 - newest_sample_tick(self.name, first, p, k))
                             * (1.0 / p) for k in range(p))
            dst.lines.append((pos, line, horizons, p))
        self.flat = [p.tuple(self.y) for p in self.plans]
        self.newest = [0] * len(self.plans)

    # -- shared pieces ---------------------------------------------------------
    def _read(self, plan: _Plan, tick: int) -> None:
        st = self.flat[plan.index][4]()
        if st > 1:
            plan.slave.fail(st, "fmi2GetReal", self.time_of(tick))
        self.newest[plan.index] = tick

    def initialize(self) -> None:
        """Read initial outputs, then feedthrough sweeps in stepping order.

        One sweep per component (each: set inputs, re-read outputs, restart its
        delay lines from the new outputs) propagates direct feedthrough along
        any chain of components; the signals are taken constant before the start.
        """
        for plan in self.plans:
            self._read(plan, 0)
            self._reset_lines(plan)
        for _ in self.plans:
            for plan in self.plans:
                self._apply_inputs(self.flat[plan.index], 0, self.time_of(0))
                self._read(plan, 0)
                self._reset_lines(plan)
        self.check_finite()

    def _reset_lines(self, plan: _Plan) -> None:
        for y_idx, line in plan.pushes:
            line.reset(self.y[y_idx])

    def check_finite(self) -> None:
        """Raise :class:`DivergenceError` naming the first non-finite output."""
        y = self.y
        s = sum(y)
        if s - s == 0.0:
            return
        for plan in self.plans:
            for j in range(plan.out_offset, plan.out_offset + len(plan.out_names)):
                if not math.isfinite(y[j]):
                    raise DivergenceError(self.y_names[j], self.time_of(self.newest[plan.index]),
                                          y[j])

    def get_state(self) -> dict:
        """Snapshot of the master-side exchange state (buffers, delay lines)."""
        return {"y": bytes(self.y), "u": [bytes(p.u) for p in self.plans],
                "newest": list(self.newest), "lines": [ln.get_state() for ln in self.lines]}

    def set_state(self, state: dict) -> None:
        """Restore a snapshot from :meth:`get_state` (and set the inputs again)."""
        ctypes.memmove(self.y, state["y"], len(state["y"]))
        for plan, u in zip(self.plans, state["u"]):
            ctypes.memmove(plan.u, u, len(u))
        self.newest[:] = state["newest"]
        for line, s in zip(self.lines, state["lines"]):
            line.set_state(s)

    def do_step(self, tick: int) -> None:  # pragma: no cover - abstract
        raise NotImplementedError

    def reset_timing(self) -> None:
        """Zero the components' call times (:attr:`timing`): the stepping loop starts."""
        ctypes.memset(self.timing, 0, ctypes.sizeof(self.timing))

    def timings(self) -> dict[str, dict[str, float]]:
        """Per component (by name): ``steps``, ``step_total_s``, ``step_max_s`` and
        ``exchange_s`` (its set-inputs and get-outputs calls) since :meth:`reset_timing`."""
        w = self.timing
        return {p.name: {"steps": int(w[4 * p.index + 3]), "step_total_s": w[4 * p.index],
                         "step_max_s": w[4 * p.index + 1], "exchange_s": w[4 * p.index + 2]}
                for p in self.plans}

    def _timed_step(self, f: tuple, t: float) -> int:
        """Plan ``f``'s step from ``t``, its wall time added to :attr:`timing`."""
        t0 = perf_counter()
        st = f[3](t, f[2])
        dt = perf_counter() - t0
        w, k = self.timing, 4 * f[0]
        w[k] += dt
        if dt > w[k + 1]:
            w[k + 1] = dt
        w[k + 3] += 1.0
        return st

    def _timed_read(self, f: tuple) -> int:
        """Plan ``f``'s get-outputs call, its wall time added to :attr:`timing`."""
        t0 = perf_counter()
        st = f[4]()
        self.timing[4 * f[0] + 2] += perf_counter() - t0
        return st

    def _apply_inputs(self, f: tuple, tick: int, t: float) -> None:
        """Write plan ``f``'s inputs for its step from ``tick`` (held / extrapolated / delayed).

        Direct connections copy the newest exchanged output; delayed or extrapolated ones ask
        their line at the coupling horizon of this tick (:func:`newest_sample_tick`).
        """
        u = f[6]
        y = self.y
        for d, s in f[7]:
            u[d] = y[s]
        for d, line, horizons, p in f[8]:
            u[d] = line.value(horizons[tick % p])
        t0 = perf_counter()
        st = f[5]()
        self.timing[4 * f[0] + 2] += perf_counter() - t0
        if st > 1:
            self.plans[f[0]].slave.fail(st, "fmi2SetReal", t)


class JacobiAlgorithm(_Algorithm):
    """Parallel (Jacobi) fixed-step multirate algorithm; see module docstring."""

    name = "jacobi"

    def do_step(self, tick: int) -> None:
        """Advance from tick ``tick`` to ``tick + 1``."""
        time_of = self.time_of
        t = time_of(tick)
        for f in self.flat:
            if tick % f[1]:
                continue
            st = self._timed_step(f, t)
            if st > 1:
                self.plans[f[0]].slave.fail(st, "fmi2DoStep", t)
        k1 = tick + 1
        newest = self.newest
        y = self.y
        for f in self.flat:
            if k1 % f[1]:
                continue
            st = self._timed_read(f)
            if st > 1:
                self.plans[f[0]].slave.fail(st, "fmi2GetReal", time_of(k1))
            newest[f[0]] = k1
            for s, line in f[9]:
                line.push(y[s])
        s = sum(y)
        if s - s != 0.0:
            self.check_finite()
        for f in self.flat:
            if not k1 % f[1]:
                self._apply_inputs(f, k1, time_of(k1))


class GaussSeidelAlgorithm(_Algorithm):
    """Sequential (Gauss-Seidel) fixed-step multirate algorithm; see module docstring."""

    name = "gauss_seidel"

    def do_step(self, tick: int) -> None:
        """Advance from tick ``tick`` to ``tick + 1``."""
        time_of = self.time_of
        t = time_of(tick)
        newest = self.newest
        y = self.y
        for f in self.flat:
            p = f[1]
            if tick % p:
                continue
            self._apply_inputs(f, tick, t)
            st = self._timed_step(f, t)
            if st > 1:
                self.plans[f[0]].slave.fail(st, "fmi2DoStep", t)
            st = self._timed_read(f)
            if st > 1:
                self.plans[f[0]].slave.fail(st, "fmi2GetReal", time_of(tick + p))
            newest[f[0]] = tick + p
            for s, line in f[9]:
                line.push(y[s])
        s = sum(y)
        if s - s != 0.0:
            self.check_finite()


def make_algorithm(name: str) -> _Algorithm:
    """Algorithm instance by name (``'jacobi'`` or ``'gauss_seidel'``)."""
    if name == "jacobi":
        return JacobiAlgorithm()
    if name == "gauss_seidel":
        return GaussSeidelAlgorithm()
    raise ValueError(f"algorithm: 'jacobi' or 'gauss_seidel', got {name!r}")
