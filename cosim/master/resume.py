"""Take a :class:`~.checkpoint.Checkpoint` of a running execution, and resume one from it.

:func:`capture` reads each component's serialized state and the master's own (held outputs and
inputs, newest-sample ticks, each delay line's past source samples) at the current tick.
:func:`restore` puts them into a freshly initialized execution of a system that fits
(:func:`~.checkpoint.restore_problems`), so that stepping on from the checkpoint's tick gives
what the run that saved it would have given, bit for bit: time stays the integer tick, the
delay lines hold the past samples of their source (whatever delay the saved run had), a start
value that differs from the saved run's is set again after the component's state (a tunable
one: a fixed one is refused by the component), and under Jacobi the inputs due at the tick are
taken again from the lines (a different delay reads a different past sample).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from .checkpoint import (
    Checkpoint,
    CheckpointError,
    ExchangeState,
    LineHistory,
    SlaveCheckpoint,
    changed_parameters,
    check_history,
    parameters_record,
    restore_problems,
)
from .errors import CosimError

__all__ = ["capture", "restore"]


def _line_connections(execution: Any) -> list:
    """The connections that have a delay line, in the order of ``algorithm.lines``."""
    return [c for c in execution.system.connections
            if not (c.delay == 0.0 and c.coupling == "zoh")]


def capture(execution: Any, identity: Mapping[str, Any]) -> Checkpoint:
    """The checkpoint of ``execution`` (initialized) at its current tick.

    Parameters
    ----------
    execution : cosim.master.execution.Execution
    identity : mapping
        The caller's identity of the run (JSON-ready), kept in the checkpoint.
    """
    execution.initialize()
    alg, system, t = execution.algorithm, execution.system, execution.time
    slaves = tuple(SlaveCheckpoint(name, dict(execution.slaves[name].state_identity()),
                                   parameters_record(system.fmu(name).parameters),
                                   system.fmu(name).sample_period_ticks,
                                   execution.slaves[name].serialize_state(t))
                   for name in system.stepping_order)
    lines = tuple(LineHistory(c.source, c.target, c.delay, c.coupling, line.history())
                  for c, line in zip(_line_connections(execution), alg.lines))
    exchange = ExchangeState(
        tuple(alg.y_names), tuple(alg.y[:len(alg.y_names)]), tuple(alg.newest),
        tuple((p.name, tuple(p.in_names), tuple(p.u[:len(p.in_names)])) for p in alg.plans),
        lines, tuple((c.source, c.target) for c in system.connections))
    base = execution.base_fraction
    return Checkpoint(execution.tick, t, (base.numerator, base.denominator), system.start_time,
                      alg.name, tuple(system.stepping_order), slaves, exchange, dict(identity))


def restore(execution: Any, checkpoint: Checkpoint) -> None:
    """Put ``checkpoint`` into ``execution`` (a :class:`~.execution.Execution` just initialized at
    its start time; not imported here: the execution imports this module).

    Raises
    ------
    CheckpointError
        One line: the checkpoint does not fit this system (instances, builds, step, algorithm,
        connections, a delay line needing more history than saved), or a component refused its
        state or a changed start value.
    """
    alg, system = execution.algorithm, execution.system
    identities = {n: execution.slaves[n].state_identity() for n in system.stepping_order}
    problems = restore_problems(checkpoint, system, execution.base_fraction.numerator,
                                execution.base_fraction.denominator, identities)
    if problems:
        raise CheckpointError(f"does not fit this run: {problems[0]}"
                              + (f" (and {len(problems) - 1} more)" if len(problems) > 1
                                 else ""))
    t = checkpoint.time
    saved_by_name = {s.name: s for s in checkpoint.slaves}
    for name in system.stepping_order:
        saved = saved_by_name[name]
        changed, unset = changed_parameters(saved.parameters, system.fmu(name).parameters)
        if unset:
            raise CheckpointError(f"instance '{name}': the checkpoint's run set {unset}, this "
                                  "run does not (a start value cannot be unset)")
        slave = execution.slaves[name]
        try:
            slave.deserialize_state(saved.state, t)
            slave.restore_parameters(changed, t)
        except CosimError as exc:
            raise CheckpointError(f"instance '{name}' refused it: {exc}") from None
    ex = checkpoint.exchange
    values = dict(zip(ex.outputs, ex.values))
    for i, ref in enumerate(alg.y_names):
        if ref in values:
            alg.y[i] = values[ref]
        else:   # an output the saved run did not exchange: the restored component's own value
            fmu, var = ref.split(".", 1)
            alg.y[i] = execution.slaves[fmu].get_real(var, t)
    alg.newest[:] = ex.newest
    held = {name: dict(zip(names, vals)) for name, names, vals in ex.inputs}
    for plan in alg.plans:
        mine = held.get(plan.name, {})
        for j, var in enumerate(plan.in_names):
            plan.u[j] = mine.get(var, plan.u[j])
    saved_lines = {(ln.source, ln.target): ln for ln in ex.lines}
    for c, line in zip(_line_connections(execution), alg.lines):
        line.restore_history(check_history(c.delay, line.depth,
                                           saved_lines.get((c.source, c.target)),
                                           f"{c.source} -> {c.target}"))
    k = checkpoint.tick
    saved_delay = {(ln.source, ln.target): ln.delay for ln in ex.lines}
    for c in _line_connections(execution):
        target = system.fmu(c.target.split(".", 1)[0])
        if (alg.name == "jacobi" and k % target.sample_period_ticks
                and saved_delay.get((c.source, c.target)) != c.delay):
            raise CheckpointError(f"connection {c.source} -> {c.target}: its delay differs "
                                  f"from the checkpoint's and its target holds an input taken "
                                  f"before the checkpoint's time {t!r} s")
    execution.tick = k
    if alg.name == "jacobi":    # the inputs of this tick's steps, from the lines as delayed here
        for f in alg.flat:
            if not k % f[1]:
                alg._apply_inputs(f, k, t)
