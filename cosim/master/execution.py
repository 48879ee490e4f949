"""The execution: owns simulated time, the slaves (FMU instances or in-process components)
and the observers.

Time is an integer number of ticks of the base step H. A float time exists
only at the FMI boundary and is computed from the integer,
``t_k = start + k * H``, with ``k * H`` evaluated as an exact rational
(H is stored as the fraction nearest to it) and rounded once, so 30000 steps
of 1 ms end at exactly 30.0 s and a run split in two equals the continuous
run bit for bit.

Observers only read (``on_step(execution)``, called after every step, and
``on_start`` / ``on_stop`` if they define them); manipulators only write
(``before_step(execution)``, called before every step).

Two loops step the same plan with the same results, bit for bit: the native loop
(:mod:`.native`: chunks of steps in C calling the FMUs' entry points, Python between the
chunks), chosen wherever it applies, and the Python loop (:meth:`Execution.simulate_until`)
for everything else.
"""

from __future__ import annotations

import shutil
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Protocol

from . import fmi_log
from .algorithms import GaussSeidelAlgorithm, JacobiAlgorithm, _Algorithm, make_algorithm
from .errors import CosimError
from .slave import FmuSlave, Slave
from .system import SystemSpec, split_variable
from .timegrid import grid_ticks, seconds, step_fraction
from .unpack import unpack


class Observer(Protocol):
    """Read-only hook called after every step."""

    def on_step(self, execution: Execution) -> None: ...


class Manipulator(Protocol):
    """Write-only hook called before every step."""

    def before_step(self, execution: Execution) -> None: ...


@dataclass(frozen=True)
class ExecutionState:
    """A saved execution state (FMU state handles, exchange buffers, tick)."""

    tick: int
    fmu_states: tuple
    exchange: dict


class Execution:
    """A running co-simulation of a :class:`SystemSpec`.

    Parameters
    ----------
    system : SystemSpec
    read_outputs : sequence of str, optional
        Extra outputs ``'fmu.var'`` read at every communication point (e.g.
        recorded ones); all values read are checked for finiteness.
    algorithm : JacobiAlgorithm or GaussSeidelAlgorithm, optional
        Defaults to ``system.algorithm``.
    slaves : mapping of str to Slave, optional
        Ready-made components by instance name (not instantiated yet; e.g. in-process models,
        :mod:`cosim.scenario.inprocess`); every other instance of the system is loaded from
        its FMU file as an :class:`~cosim.master.slave.FmuSlave`. The execution closes them.

    Notes
    -----
    Use as a context manager, or call :meth:`close` to free the slaves.
    """

    def __init__(self, system: SystemSpec, read_outputs=(), algorithm: _Algorithm | None = None,
                 slaves: Mapping[str, Slave] | None = None):
        self.system = system
        self.base_step = system.base_step
        self.start_time = system.start_time
        #: the base step as an exact fraction [s] (:func:`.timegrid.step_fraction`)
        self.base_fraction = step_fraction(system.base_step)
        self.tick = 0
        self.observers: list = []
        self.manipulators: list = []
        self.slaves: dict[str, Slave] = {}
        self._states: list[ExecutionState] = []
        self.algorithm = algorithm or make_algorithm(system.algorithm)
        self._read_outputs = tuple(read_outputs)
        self._native = None          # the native loop's plan, built at the first use
        self._resume = None          # a checkpoint initialize() restores
        self.initialized = False
        self.closed = False
        given = dict(slaves or {})
        unknown = sorted(set(given) - {f.name for f in system.fmus})
        if unknown:
            raise ValueError(f"slaves: no instance {unknown} in the system")
        dirs: dict[Path, str] = {}
        self._dirs: list[str] = []
        try:
            for spec in system.fmus:
                if spec.name in given:
                    self.slaves[spec.name] = given.pop(spec.name)
                    continue
                path = Path(spec.path).resolve()
                if path not in dirs and path.is_file():
                    dirs[path], owned = unpack(path)
                    if owned:
                        self._dirs.append(dirs[path])
                self.slaves[spec.name] = FmuSlave(spec, dirs.get(path))
        except BaseException:
            for slave in given.values():  # ready-made ones not taken over yet
                slave.close()
            self.close()
            raise

    # -- time -----------------------------------------------------------------
    def time_of(self, tick: int) -> float:
        """Time of tick ``tick`` [s]: ``start + tick * H`` rounded once."""
        return seconds(tick, self.base_fraction, self.start_time)

    @property
    def time(self) -> float:
        """Current simulated time [s]."""
        return seconds(self.tick, self.base_fraction, self.start_time)

    def ticks_until(self, stop_time: float) -> int:
        """Tick of ``stop_time``; ``ValueError`` unless it is on the base-step grid."""
        k = grid_ticks(stop_time - self.start_time, self.base_step)
        if k is None:
            raise ValueError(f"stop_time: a multiple of base_step = {self.base_step} s after "
                             f"start_time, got {stop_time} s")
        return k

    def resume_from(self, checkpoint) -> None:
        """Start from ``checkpoint`` (a :class:`~.checkpoint.Checkpoint`) instead of the start
        time: :meth:`initialize` restores it (:func:`.resume.restore`)."""
        if self.initialized:
            raise RuntimeError("resume_from: call it before the execution is initialized")
        self._resume = checkpoint

    # -- hooks ----------------------------------------------------------------
    def add_observer(self, observer: Observer) -> None:
        """Register a read-only observer (``on_step(execution)``).

        Its ``on_start`` (if any) runs at initialisation, or at once if the
        execution is already initialised.
        """
        self.observers.append(observer)
        if self.initialized and hasattr(observer, "on_start"):
            observer.on_start(self)

    def add_manipulator(self, manipulator: Manipulator) -> None:
        """Register a write-only manipulator (``before_step(execution)``)."""
        self.manipulators.append(manipulator)

    # -- running ----------------------------------------------------------------
    def initialize(self) -> None:
        """Instantiate and initialise the slaves, read initial outputs, set inputs."""
        if self.initialized:
            return
        system = self.system
        stop = system.stop_time
        fmi_log.claim()
        for slave in self.slaves.values():
            slave.instantiate(system.start_time, stop)
        read = list(self._read_outputs)
        for ref in read:
            fmu, _ = split_variable(ref, "read_outputs")
            if fmu not in self.slaves:
                raise ValueError(f"read_outputs: unknown FMU in {ref!r}")
        self.algorithm.setup(system, self.slaves, self.time_of, read)
        self.algorithm.initialize()
        if self._resume is not None:
            from .resume import restore

            restore(self, self._resume)
        self.initialized = True
        for obs in self.observers:
            if hasattr(obs, "on_start"):
                obs.on_start(self)

    def simulate_until(self, stop_time: float) -> None:
        """Advance to ``stop_time`` [s] (a multiple of the base step).

        Can be called repeatedly; splitting a run gives the same result as
        one call, bit for bit.

        Raises
        ------
        CosimError
            An FMU call failed (status Discard, Error or Fatal).
        DivergenceError
            A non-finite output was read.
        """
        if self.closed:
            raise CosimError("", "simulate_until", self.time, "the execution is closed")
        self.initialize()
        k_stop = self.ticks_until(stop_time)
        if k_stop < self.tick:
            raise ValueError(f"stop_time: >= current time {self.time} s, got {stop_time} s")
        fmi_log.claim()
        observers = tuple(o.on_step for o in self.observers)
        native = self._native_loop(k_stop)
        if native is not None and native.run(k_stop, observers, self.manipulators):
            return
        do_step = self.algorithm.do_step
        manipulators = tuple(m.before_step for m in self.manipulators)
        tick = self.tick
        if not observers and not manipulators:
            while tick < k_stop:
                do_step(tick)
                tick += 1
                self.tick = tick
            return
        while tick < k_stop:
            for m in manipulators:
                m(self)
            do_step(tick)
            tick += 1
            self.tick = tick
            for o in observers:
                o(self)

    def _native_loop(self, k_stop: int):
        """The native loop if it applies to this run (see :mod:`.native.runner`), else None."""
        from .native.runner import NativeLoop

        native = self._native
        if native is None or native.observed != (self.observers, self.manipulators):
            native = NativeLoop.for_execution(self, self.observers, self.manipulators)
            self._native = native
        if native is None or not native.exact_until(k_stop):
            return None
        return native

    # -- access ----------------------------------------------------------------
    def get_real(self, ref: str) -> float:
        """Current value of Real variable ``'fmu.var'`` [its unit]."""
        fmu, var = split_variable(ref, "ref")
        y_index = getattr(self.algorithm, "y_index", {})
        if ref in y_index:
            return self.algorithm.y[y_index[ref]]
        return self.slaves[fmu].get_real(var, self.time)

    def set_value(self, ref: str, value) -> None:
        """Set variable ``'fmu.var'`` now (for manipulators; typed by the FMU).

        A connected input is overwritten at the FMU's next exchange.
        """
        fmu, var = split_variable(ref, "ref")
        self.slaves[fmu].set_value(var, value, self.time)

    def get_state(self) -> ExecutionState:
        """Save the full state: FMU states, exchange buffers, delay lines, tick."""
        self.initialize()
        t = self.time
        fmu_states = tuple(s.get_state(t) for s in self.slaves.values())
        state = ExecutionState(self.tick, fmu_states, self.algorithm.get_state())
        self._states.append(state)
        return state

    def set_state(self, state: ExecutionState) -> None:
        """Restore a state saved by :meth:`get_state` of this execution."""
        for slave, fs in zip(self.slaves.values(), state.fmu_states):
            slave.set_state(fs, self.time_of(state.tick))
        self.algorithm.set_state(state.exchange)
        self.tick = state.tick

    def close(self) -> None:
        """Free saved states, close all slaves (FMUs: terminate, free), delete temporary
        unpacked files (the shared cache of :mod:`.unpack` stays). An observer's ``on_stop``
        that raises (e.g. the recorder's last write) is raised after all that."""
        if self.closed:
            return
        self.closed = True
        failure = None
        for obs in self.observers:
            if hasattr(obs, "on_stop"):
                try:
                    obs.on_stop(self)
                except Exception as exc:  # noqa: BLE001 - raised once everything is freed
                    failure = failure or exc
        for state in self._states:
            for slave, fs in zip(self.slaves.values(), state.fmu_states):
                slave.free_state(fs)
        self._states.clear()
        for slave in self.slaves.values():
            slave.close()
        for d in self._dirs:
            shutil.rmtree(d, ignore_errors=True)
        if failure is not None:
            raise failure

    def __enter__(self) -> Execution:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


__all__ = ["Execution", "ExecutionState", "JacobiAlgorithm", "GaussSeidelAlgorithm",
           "Observer", "Manipulator"]
