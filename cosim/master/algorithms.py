"""Co-simulation algorithms: fixed-step Jacobi and Gauss-Seidel, multirate.

Both share one interface (as in libcosim): :meth:`setup` builds the exchange
plan once, :meth:`initialize` reads the initial outputs and sets the initial
inputs, :meth:`do_step` advances the system from tick ``k`` to ``k + 1``.

Multirate: FMU ``i`` has a period of ``p_i`` base steps; it steps only at ticks
``k`` with ``k % p_i == 0``, with step size ``p_i * H``. Its outputs are held
between its communication points.

* **Jacobi** (parallel): at tick k every due FMU steps with the inputs set at
  tick k; then, at tick k + 1, the FMUs that reached their communication point
  publish their outputs and those due next get their new inputs. The inputs
  used over ``[t_k, t_k+1]`` are outputs sampled at ``t_k``.
* **Gauss-Seidel** (sequential): due FMUs step one after another in
  ``order``; each first takes its inputs from the newest outputs (already at
  ``t_k+1`` for the FMUs before it), steps, and publishes at once. Relative to
  Jacobi, a connection from an earlier to a later FMU has one step less delay.

Initialisation: all outputs are read at the start time, then as many sweeps as
there are FMUs, in stepping order, set each FMU's inputs and re-read its
outputs (propagating direct feedthrough along any chain of FMUs).

The hot loop works on ctypes buffers with precomputed index pairs: per step and
FMU one ``fmi2SetReal``, one ``fmi2DoStep`` and one ``fmi2GetReal`` on the raw
library functions, no dict lookups and no per-step allocation besides floats.
"""

from __future__ import annotations

import ctypes
import math
from collections.abc import Callable, Mapping, Sequence

from .delays import DelayLine
from .errors import DivergenceError
from .slave import Slave, c_double_ptr, vr_pointer
from .system import SystemSpec, split_variable

_FMI_FALSE = 0


class _FmuPlan:
    """Precomputed exchange data of one FMU (built once in ``setup``)."""

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
        self.lines: list[tuple[int, DelayLine, int, float, float]] = []
        self.pushes: list[tuple[int, DelayLine]] = []     # (y index, line)

    def tuple(self, y) -> tuple:
        """The flat tuple unpacked by the hot loop."""
        s = self.slave
        out_vrs, out_vr_p = vr_pointer(s.real_vrs(self.out_names))
        in_vrs, in_vr_p = vr_pointer(s.real_vrs(self.in_names))
        self._keep = (out_vrs, in_vrs)
        self.u = (ctypes.c_double * max(1, len(self.in_names)))()
        y_p = c_double_ptr(y, self.out_offset)
        return (self.index, self.period, self.h, s.component, s.c_do_step, s.c_get_real,
                out_vr_p, len(self.out_names), y_p, s.c_set_real, in_vr_p,
                len(self.in_names), self.u, tuple(self.plain), tuple(self.lines),
                tuple(self.pushes))


class _Algorithm:
    """Common setup, initialisation, state and divergence check."""

    name = "base"

    def __init__(self):
        self.plans: list[_FmuPlan] = []
        self.y = None
        self.newest: list[int] = []
        self.lines: list[DelayLine] = []
        self.y_names: list[str] = []

    def setup(self, system: SystemSpec, slaves: Mapping[str, Slave],
              time_of: Callable[[int], float],
              read_outputs: Sequence[str] = ()) -> None:
        """Build the exchange plan.

        Parameters
        ----------
        system : SystemSpec
        slaves : mapping of name to Slave
            Instantiated FMUs.
        time_of : callable
            Tick -> time [s] (exact conversion owned by the execution).
        read_outputs : sequence of str
            Extra ``'fmu.var'`` outputs read at every communication point
            (recorded or monitored), besides the connection sources.
        """
        self.time_of = time_of
        order = system.stepping_order
        H = system.base_step
        self.plans = [_FmuPlan(i, slaves[n], system.fmu(n).sample_period_ticks, H)
                      for i, n in enumerate(order)]
        by_name = {p.name: p for p in self.plans}
        for ref in [c.source for c in system.connections] + list(read_outputs):
            fmu, var = split_variable(ref, "output")
            plan = by_name[fmu]
            plan.slave.variable(var, ("output", "local", "parameter", "calculatedParameter",
                                      "input"))
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
        self.n_y = offset
        self.lines = []
        for c in system.connections:
            src_fmu, _ = split_variable(c.source, "source")
            dst_fmu, dst_var = split_variable(c.target, "target")
            dst = by_name[dst_fmu]
            src = by_name[src_fmu]
            dst.slave.variable(dst_var, ("input", "parameter"))
            pos = len(dst.in_names)
            dst.in_names.append(dst_var)
            y_idx = self.y_index[c.source]
            if c.delay == 0.0 and c.coupling == "zoh":
                dst.plain.append((pos, y_idx))
                continue
            line = DelayLine(c.delay, src.h, c.coupling == "linear")
            self.lines.append(line)
            src.pushes.append((y_idx, line))
            # horizon [source periods] = (k + p_dst / 2 - newest_src) / p_src
            dst.lines.append((pos, line, src.index, dst.period / 2.0, 1.0 / src.period))
        self.flat = [p.tuple(self.y) for p in self.plans]
        self.newest = [0] * len(self.plans)

    # -- shared pieces ---------------------------------------------------------
    def _read(self, plan: _FmuPlan, tick: int) -> None:
        n_out = len(plan.out_names)
        if n_out:
            f = self.flat[plan.index]
            st = f[5](f[3], f[6], n_out, f[8])
            if st > 1:
                plan.slave.fail(st, "fmi2GetReal", self.time_of(tick))
        self.newest[plan.index] = tick

    def _gather_set(self, plan: _FmuPlan, tick: int) -> None:
        self._apply_inputs(self.flat[plan.index], tick, self.time_of(tick))

    def initialize(self) -> None:
        """Read initial outputs, then feedthrough sweeps in stepping order.

        One sweep per FMU (each: set inputs, re-read outputs, restart its
        delay lines from the new outputs) propagates direct feedthrough along
        any chain of FMUs; the signals are taken constant before the start.
        """
        for plan in self.plans:
            self._read(plan, 0)
            self._reset_lines(plan)
        for _ in self.plans:
            for plan in self.plans:
                self._gather_set(plan, 0)
                self._read(plan, 0)
                self._reset_lines(plan)
        self.check_finite()

    def _reset_lines(self, plan: _FmuPlan) -> None:
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

    def value(self, ref: str) -> float:
        """Last read value of output ``'fmu.var'`` (must be in the read set)."""
        return self.y[self.y_index[ref]]

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


    def _apply_inputs(self, f: list, tick: int, t: float) -> None:
        """Write FMU plan ``f``'s inputs for ``tick`` (held / extrapolated / delayed values).

        Direct connections copy the newest exchanged output; delayed or extrapolated ones ask
        their line at the age of the newest sample (in source periods).
        """
        u = f[12]
        y = self.y
        newest = self.newest
        for d, s in f[13]:
            u[d] = y[s]
        for d, line, src, half, inv_p in f[14]:
            u[d] = line.value((tick + half - newest[src]) * inv_p)
        if f[11]:
            st = f[9](f[3], f[10], f[11], u)
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
            st = f[4](f[3], t, f[2], _FMI_FALSE)
            if st > 1:
                self.plans[f[0]].slave.fail(st, "fmi2DoStep", t)
        k1 = tick + 1
        newest = self.newest
        y = self.y
        for f in self.flat:
            if k1 % f[1]:
                continue
            if f[7]:
                st = f[5](f[3], f[6], f[7], f[8])
                if st > 1:
                    self.plans[f[0]].slave.fail(st, "fmi2GetReal", time_of(k1))
            newest[f[0]] = k1
            for s, line in f[15]:
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
            st = f[4](f[3], t, f[2], _FMI_FALSE)
            if st > 1:
                self.plans[f[0]].slave.fail(st, "fmi2DoStep", t)
            if f[7]:
                st = f[5](f[3], f[6], f[7], f[8])
                if st > 1:
                    self.plans[f[0]].slave.fail(st, "fmi2GetReal", time_of(tick + p))
            newest[f[0]] = tick + p
            for s, line in f[15]:
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
