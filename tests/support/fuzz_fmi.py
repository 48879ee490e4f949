"""FMI 2.0 API misuse fuzzer for our FMUs (pythonfmu slaves on our C wrapper), in a child process.

Usage (normally started by ``tests/test_reliability_fuzz.py``)::

    python tests/support/fuzz_fmi.py FMU --examples N [--seed S] [--report FILE]

Hypothesis draws sequences of FMI calls (instantiate, setupExperiment,
enter/exitInitializationMode, set/get of every type with valid, unknown and
wrongly typed value references, NaN/inf/huge values, doStep with negative,
zero, huge, NaN step sizes or out-of-order times, terminate, reset, doStep after
terminate, get/set/free/serialize FMU states) and runs them through fmpy's
``FMU2Slave`` in *this* process. Properties checked per call:

* it returns a status (fmpy returns, or raises ``FMICallException`` for a status
  worse than fmi2Warning, which is caught and counted);
* the status is never fmi2Fatal: the wrapper reports a Python exception as fmi2Error and
  the adapters report every anticipated problem through the status protocol (an instance
  that went fatal anyway is leaked, never freed, so the report shows it);
* no other exception escapes (fmpy raises nothing else for valid arguments).

A crash (segfault, abort) kills this process: the parent sees a negative exit
code. A hang is caught by the parent's timeout. After all examples, a healthy
instance must reproduce, bit for bit, the reference run computed before them.

The JSON report (``--report``) holds the counts: examples, calls per FMI
function, statuses per function, fatal count, healthy check.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from collections import Counter
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import hypothesis
import numpy as np
from fmpy import extract, read_model_description
from fmpy.fmi1 import FMICallException
from fmpy.fmi2 import (
    FMU2Slave,
)
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from support.fmi_logging import RecordingCallbacks

OK, WARNING, DISCARD, ERROR, FATAL = 0, 1, 2, 3, 4
STATUS_NAMES = ("ok", "warning", "discard", "error", "fatal", "pending")

#: Stable internal step [s] set on the plant in "fast" initializations: skips the
#: eigenvalue estimate of the stable step (~1 s per build) and stays below it (0.4 ms).
FAST_PLANT_STEP = 2.5e-4

REALS: tuple[float, ...] = (0.0, -0.0, 1.0, -1.0, 0.5, 1e-3, -1e-3, 1e3, 1e9, -1e9, 1e300,
                            -1e300, 5e-324, math.nan, math.inf, -math.inf)
INTEGERS: tuple[int, ...] = (-2**31, -1, 0, 1, 2, 3, 11, 26, 30, 2**31 - 1)
STEP_SIZES: tuple[float, ...] = (1e-3, 2.5e-4, 0.02, 0.0, -0.0, -1e-3, -math.inf, math.nan,
                                 math.inf, 1e300, 1e20, 5e-324)
START_TIMES: tuple[float, ...] = (0.0, -1.0, 1e9, math.nan, math.inf)
STRINGS: tuple[str, ...] = ("", "paper_open_loop", "table1_axial_pulse", "paper_closed_loop",
                            "no_such_scene", "../x.toml", "/", ".", "full3d", "auto",
                            "axial_torsional", "ünïcødé ✓", "x" * 300)


@dataclass
class Stats:
    """Counts of one fuzz campaign."""

    examples: int = 0
    calls: Counter = field(default_factory=Counter)
    statuses: Counter = field(default_factory=Counter)
    prefixes: Counter = field(default_factory=Counter)
    seconds: float = 0.0

    def record(self, call: str, status: int) -> None:
        self.calls[call] += 1
        self.statuses[f"{call}:{STATUS_NAMES[status] if 0 <= status < 6 else status}"] += 1


class Harness:
    """One FMU: model description, extracted folder and value-reference tables."""

    def __init__(self, fmu: str) -> None:
        self.fmu = fmu
        self.md = read_model_description(fmu)
        self.unzipdir = extract(fmu)
        self.ident = self.md.coSimulation.modelIdentifier
        self.by_name = {v.name: v for v in self.md.modelVariables}
        self.by_type: dict[str, list[int]] = {"Real": [], "Integer": [], "Boolean": [],
                                               "String": []}
        for v in self.md.modelVariables:
            self.by_type[v.type].append(v.valueReference)
        n = len(self.md.modelVariables)
        self.all_vrs = sorted(v.valueReference for v in self.md.modelVariables)
        self.bad_vrs = [n, n + 1, 10**6, 2**31 - 1, 2**32 - 1]
        self.inputs = [v.valueReference for v in self.md.modelVariables
                       if v.causality == "input"]
        self.outputs = [v.valueReference for v in self.md.modelVariables
                        if v.causality == "output"]
        self.is_plant = self.ident == "DrillstringPlant"
        self._count = 0
        self._recording = RecordingCallbacks(keep_last=50)
        self.messages = self._recording.messages
        self._callbacks = self._recording.callbacks
        self.leaked: list[FMU2Slave] = []

    def new(self, logging_on: bool = True) -> FMU2Slave:
        """A fresh, instantiated slave."""
        self._count += 1
        s = FMU2Slave(guid=self.md.guid, unzipDirectory=self.unzipdir,
                      modelIdentifier=self.ident, instanceName=f"fuzz{self._count}")
        s.instantiate(callbacks=self._callbacks, loggingOn=logging_on)
        return s

    def fast_parameters(self, s: FMU2Slave) -> None:
        """Parameters that keep an initialization cheap (plant: a fixed internal step)."""
        if self.is_plant:
            s.setReal([self.by_name["max_internal_step"].valueReference], [FAST_PLANT_STEP])

    def reference_run(self, steps: int = 20) -> np.ndarray:
        """Outputs of a healthy instance: fast parameters, sine inputs, 1 ms steps."""
        s = self.new(logging_on=False)
        try:
            s.setupExperiment(startTime=0.0)
            s.enterInitializationMode()
            self.fast_parameters(s)
            if {"lag_time_constant", "gain"} <= self.by_name.keys():  # strain controller:
                s.setReal([self.by_name["lag_time_constant"].valueReference,   # a visible lag
                           self.by_name["gain"].valueReference], [0.01, 2e9])  # and gain
            s.exitInitializationMode()
            rows = [s.getReal(self.outputs)]
            # input scale: forces [N] (plant), strains (strain controller), rad/s and N m
            scale = 1e3 if self.is_plant else 1e-6 if "gain" in self.by_name else 1.0
            for k in range(steps):
                u = [scale * math.sin(0.3 * k + i) for i in range(len(self.inputs))]
                s.setReal(self.inputs, u)
                s.doStep(k * 1e-3, 1e-3)
                rows.append(s.getReal(self.outputs))
            s.terminate()
        finally:
            s.freeInstance()
        return np.array(rows)


# ------------------------------------------------------------------ strategies
def operations(h: Harness) -> st.SearchStrategy:
    """Strategy of (prefix, [op, ...]) for one example."""
    any_vr = st.sampled_from(h.all_vrs + h.bad_vrs)
    reals = st.one_of(st.sampled_from(REALS), st.floats(allow_nan=True, allow_infinity=True))
    texts = st.one_of(st.sampled_from(STRINGS), st.text(
        alphabet=st.characters(blacklist_categories=("Cs",), blacklist_characters="\x00"),
        max_size=40))

    def pairs(values: st.SearchStrategy) -> st.SearchStrategy:
        return st.lists(st.tuples(any_vr, values), max_size=4)

    getters = st.tuples(st.sampled_from(["getReal", "getInteger", "getBoolean", "getString"]),
                        st.lists(any_vr, max_size=4))
    op = st.one_of(
        st.tuples(st.just("setupExperiment"), st.sampled_from(START_TIMES)),
        st.sampled_from([("enterInitializationMode",), ("exitInitializationMode",),
                         ("terminate",), ("reset",), ("getFMUstate",)]),
        st.tuples(st.just("setReal"), pairs(reals)),
        st.tuples(st.just("setInteger"), pairs(st.one_of(st.sampled_from(INTEGERS),
                                                         st.integers(-2**31, 2**31 - 1)))),
        st.tuples(st.just("setBoolean"), pairs(st.booleans())),
        st.tuples(st.just("setString"), pairs(texts)),
        getters,
        st.tuples(st.just("setInputs"), reals),
        st.tuples(st.just("setInputs"), st.floats(-1e4, 1e4)),  # valid: reach deeper states
        st.tuples(st.just("doStep"), st.one_of(st.just("now"), st.sampled_from(START_TIMES)),
                  st.sampled_from(STEP_SIZES)),
        st.tuples(st.just("doStep"), st.just("now"), st.just(1e-3)),
        st.tuples(st.just("doStep"), st.just("now"), st.just(1e-3)),
        st.tuples(st.sampled_from(["setFMUstate", "freeFMUstate", "serialize"]),
                  st.integers(0, 3)),
        st.tuples(st.just("setDebugLogging"), st.booleans()),
    )
    prefix = st.sampled_from(["instantiated", "setup", "initialized"])
    return st.tuples(prefix, st.lists(op, max_size=25))


# -------------------------------------------------------------------- execution
class FatalStatusError(AssertionError):
    """An FMI call returned fmi2Fatal (an exception escaped the adapter)."""


_FAILED = object()


def _call(stats: Stats, name: str, fn: Callable[..., Any], *args: Any) -> Any:
    """Call ``fn``; count its status; return its value or ``_FAILED`` (non-OK status)."""
    try:
        out = fn(*args)
    except FMICallException as exc:
        stats.record(name, exc.status)
        if exc.status >= FATAL:
            raise FatalStatusError(f"{name}{args!r} returned status {exc.status}") from None
        return _FAILED
    stats.record(name, OK)
    return out


def run_case(h: Harness, stats: Stats, prefix: str, ops: Sequence[tuple]) -> None:
    """Execute one example on a fresh instance; free it unless it went fatal."""
    s = h.new()
    states: list[Any] = []
    t = 0.0
    fatal = False
    try:
        if prefix in ("setup", "initialized"):
            s.setupExperiment(startTime=0.0)
        if prefix == "initialized":
            s.enterInitializationMode()
            h.fast_parameters(s)
            s.exitInitializationMode()
        for op in ops:
            name = op[0]
            if name == "setupExperiment":
                _call(stats, name, lambda x: s.setupExperiment(startTime=x), op[1])
            elif name in ("enterInitializationMode", "exitInitializationMode", "terminate",
                          "reset"):
                _call(stats, name, getattr(s, name))
            elif name == "getFMUstate":
                state = _call(stats, name, s.getFMUstate)
                if state is not _FAILED:
                    states.append(state)
            elif name in ("setReal", "setInteger", "setBoolean", "setString"):
                vrs = [p[0] for p in op[1]]
                values = [p[1] for p in op[1]]
                _call(stats, name, getattr(s, name), vrs, values)
            elif name in ("getReal", "getInteger", "getBoolean", "getString"):
                _call(stats, name, getattr(s, name), list(op[1]))
            elif name == "setInputs":
                _call(stats, "setReal", s.setReal, h.inputs, [op[1]] * len(h.inputs))
            elif name == "doStep":
                t_call = t if op[1] == "now" else op[1]
                if _call(stats, name, s.doStep, t_call, op[2]) is not _FAILED:
                    t = t_call + op[2]  # the next "now" continues from here
            elif name in ("setFMUstate", "freeFMUstate", "serialize"):
                if not states:
                    continue
                state = states[op[1] % len(states)]
                if name == "setFMUstate":
                    _call(stats, name, s.setFMUstate, state)
                elif name == "freeFMUstate":
                    states.remove(state)
                    _call(stats, name, s.freeFMUstate, state)
                else:
                    blob = _call(stats, "serializeFMUstate", s.serializeFMUstate, state)
                    if blob is not _FAILED:
                        new = _call(stats, "deSerializeFMUstate", s.deSerializeFMUstate, blob)
                        if new is not _FAILED:
                            states.append(new)
                            _call(stats, "setFMUstate", s.setFMUstate, new)
            elif name == "setDebugLogging":
                _call(stats, name, lambda on: s.setDebugLogging(on, []), op[1])
            else:  # pragma: no cover - strategy and executor out of sync
                raise AssertionError(f"unknown op {op!r}")
    except FatalStatusError:
        fatal = True
        raise
    finally:
        if fatal:
            h.leaked.append(s)  # a fatal instance is kept for the report, never freed
        else:
            for state in states:
                try:
                    s.freeFMUstate(state)
                except FMICallException:
                    pass
            s.freeInstance()


def campaign(fmu: str, examples: int, seed: int) -> dict[str, Any]:
    """Run ``examples`` hypothesis examples on ``fmu``; return the report."""
    h = Harness(fmu)
    t0 = time.perf_counter()
    reference = h.reference_run()
    stats = Stats()

    @hypothesis.seed(seed)
    @settings(max_examples=examples, deadline=None, database=None,
              suppress_health_check=list(HealthCheck), print_blob=True)
    @given(operations(h))
    def fuzz(case: tuple) -> None:
        stats.examples += 1
        prefix, ops = case
        stats.prefixes[prefix] += 1
        run_case(h, stats, prefix, ops)

    fuzz()
    healthy = h.reference_run()
    stats.seconds = time.perf_counter() - t0
    return {
        "fmu": Path(fmu).name,
        "seed": seed,
        "examples": stats.examples,
        "examples_by_start": dict(sorted(stats.prefixes.items())),
        "calls_total": sum(stats.calls.values()),
        "calls": dict(sorted(stats.calls.items())),
        "statuses": dict(sorted(stats.statuses.items())),
        "fatal": len(h.leaked),
        "healthy_equal": bool(np.array_equal(reference, healthy)),
        "reference_finite": bool(np.all(np.isfinite(reference))),
        "seconds": round(stats.seconds, 1),
    }


def main(argv: Sequence[str] | None = None) -> int:
    """Command line: run a campaign and print/write the JSON report."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("fmu")
    ap.add_argument("--examples", type=int, default=50)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--report", type=Path)
    args = ap.parse_args(argv)
    report = campaign(args.fmu, args.examples, args.seed)
    text = json.dumps(report, indent=1)
    if args.report:
        args.report.write_text(text)
    print(text)
    return 0 if report["healthy_equal"] and report["fatal"] == 0 else 1


if __name__ == "__main__":
    sys.exit(main())
