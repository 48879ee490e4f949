"""Checks run inside a Python host by fmpy: the Windows CPython under wine, and the Linux one for
the reference (the same code on both sides; only numpy and fmpy are needed).

Usage::

    python windows_checks.py JOBS.json

``JOBS.json`` is a list of ``[name, kind, arguments]``; every job runs in this one process (a
Python start under wine costs seconds), each in its own ``try``: the output is one JSON line,
``{name: {"ok": true, "result": ..., "seconds": s} | {"ok": false, "error": traceback, ...}}``.
Kinds:

* ``loop`` - a co-simulation of FMUs through fmpy's ``FMU2Slave``: Jacobi stepping with a
  zero-order hold (at t_k every connection's source is read, every target set, the outputs
  recorded, then every FMU steps to t_k+1; our master's ``jacobi``). Arguments: ``fmus`` (instance
  -> {"path", "parameters"}), ``connections`` ([source instance, variable, target instance,
  variable]), ``outputs`` ([instance, variable]), ``step``, ``stop``. Result: the rows (time,
  outputs...), the seconds of the first ``fmi2Instantiate`` of each instance and of the run, and
  where each vendored package's compiled steps came from (``native.sources()``: ``"image"`` or
  ``"numba"``).
* ``validate`` - ``fmpy.validation.validate_fmu`` of each path: its problems.
* ``two_builds`` - FMUs of different builds of one model in this host at once (``fmus``: label ->
  path, loaded in that order), every instance stepped with the same inputs (``inputs``: name ->
  value), interleaved: the outputs of each and the ``_dcs_`` modules loaded with their files.
* ``drive`` - one FMU alone, its Real ``inputs`` set to a fixed sequence every step, every
  output recorded (``parameters`` set in initialization): the controllers, whose laws use no
  function of the C math library, give the same bits on every platform.
* ``libm`` - numba's sin, cos, exp, atan2 and sqrt of fixed arguments (the plant's kernels call
  the C runtime's functions: glibc's on Linux, the Windows CRT's there).
* ``fuzz`` - the misuse fuzzer's campaign (:func:`support.fuzz_fmi.campaign`) on ``fmu`` with
  ``examples`` examples and ``seed``.
"""

from __future__ import annotations

import json
import sys
import time
import traceback
from pathlib import Path

HERE = Path(__file__).resolve().parent
_UNZIPPED: list[str] = []  # fmpy's unzip folders, removed at the end
if str(HERE.parent) not in sys.path:  # the tests' folder: `support.*` (a ._pth Python adds none)
    sys.path.insert(0, str(HERE.parent))


def _open(path: str, name: str, logs: list[tuple[int, str]] | None):
    from fmpy import extract, read_model_description
    from fmpy.fmi2 import FMU2Slave

    md = read_model_description(path)
    unzipped = extract(path)
    _UNZIPPED.append(unzipped)
    slave = FMU2Slave(guid=md.guid, unzipDirectory=unzipped, instanceName=name,
                      modelIdentifier=md.coSimulation.modelIdentifier)
    variables = {v.name: v for v in md.modelVariables}
    start = time.perf_counter()
    slave.instantiate(loggingOn=False,
                      callbacks=None if logs is None else _callbacks(slave, logs))
    return slave, variables, time.perf_counter() - start


def _callbacks(slave, logs: list[tuple[int, str]]):
    from fmpy.fmi2 import fmi2CallbackFunctions, fmi2CallbackLoggerTYPE

    def logger(_env, name, status, category, message):
        logs.append((status, f"{name.decode()} {category.decode()}: {message.decode()}"))

    cb = fmi2CallbackFunctions()
    cb.logger = fmi2CallbackLoggerTYPE(logger)
    slave._dcs_keep = cb  # alive as long as the instance
    return cb


def _set(slave, var, value) -> None:
    vr = [var.valueReference]
    kind = var.type
    if kind == "Real":
        slave.setReal(vr, [float(value)])
    elif kind in ("Integer", "Enumeration"):
        slave.setInteger(vr, [int(value)])
    elif kind == "Boolean":
        slave.setBoolean(vr, [bool(value)])
    else:
        slave.setString(vr, [str(value)])


def _compiled_sources() -> dict[str, str]:
    found = {}
    for name, module in list(sys.modules.items()):
        if name.startswith("_dcs_slave_support_") and name.endswith(".native"):
            found.update(module.sources())
    return found


def loop(fmus: dict, connections: list, outputs: list, step: float, stop: float) -> dict:
    """The Jacobi co-simulation described in the module docstring."""
    logs: list[tuple[int, str]] = []
    instances, instantiate = {}, {}
    for inst, spec in fmus.items():
        slave, variables, seconds = _open(spec["path"], inst, logs)
        instances[inst] = (slave, variables)
        instantiate[inst] = seconds
    started = time.perf_counter()
    for inst, (slave, variables) in instances.items():
        slave.setupExperiment(startTime=0.0, stopTime=stop)
        slave.enterInitializationMode()
        for name, value in fmus[inst]["parameters"].items():
            _set(slave, variables[name], value)
        slave.exitInitializationMode()
    links = [(instances[si][0], instances[si][1][sv].valueReference,
              instances[ti][0], instances[ti][1][tv].valueReference)
             for si, sv, ti, tv in connections]
    probes = [(instances[i][0], instances[i][1][v].valueReference) for i, v in outputs]
    n_steps = round(stop / step)
    rows = []
    for k in range(n_steps + 1):
        t = k * step
        values = [src.getReal([svr])[0] for src, svr, _dst, _dvr in links]
        for (_src, _svr, dst, dvr), value in zip(links, values):
            dst.setReal([dvr], [value])
        rows.append([t, *(s.getReal([vr])[0] for s, vr in probes)])
        if k < n_steps:
            for slave, _variables in instances.values():
                slave.doStep(currentCommunicationPoint=t, communicationStepSize=step)
    seconds = time.perf_counter() - started
    sources = _compiled_sources()
    for slave, _variables in instances.values():
        slave.terminate()
        slave.freeInstance()
    return {"rows": rows, "instantiate_s": instantiate, "run_s": seconds,
            "compiled_sources": sources, "errors": [text for status, text in logs if status >= 3]}


def validate(paths: list[str]) -> dict:
    from fmpy.validation import validate_fmu

    return {p: validate_fmu(p) for p in paths}


def two_builds(fmus: dict, inputs: dict, steps: int = 5, step: float = 1e-3) -> dict:
    """Every FMU of ``fmus`` instantiated (all alive), stepped interleaved with ``inputs``."""
    opened = {label: _open(path, label, None)[:2] for label, path in fmus.items()}
    rows = {label: [] for label in opened}
    for slave, _variables in opened.values():
        slave.setupExperiment(startTime=0.0)
        slave.enterInitializationMode()
        slave.exitInitializationMode()
    for k in range(steps):
        for label, (slave, variables) in opened.items():
            for name, value in inputs.items():
                _set(slave, variables[name], value * (k + 1))
            slave.doStep(k * step, step)
            outs = [v.valueReference for v in variables.values() if v.causality == "output"]
            rows[label].append(slave.getReal(outs))
    names = sorted(m for m in sys.modules if m.startswith("_dcs_") and "." not in m)
    files = {m: getattr(sys.modules[m], "__file__", None) for m in names}
    for slave, _variables in opened.values():
        slave.terminate()
        slave.freeInstance()
    return {"rows": rows, "modules": names, "files": files}


def drive(fmu: str, inputs: list, steps: int, step: float, parameters: dict) -> dict:
    """``fmu`` alone: at step k input j is ``1e-6 * ((3 k + j) % 11 - 5)``; the outputs."""
    slave, variables, _seconds = _open(fmu, "driven", None)
    slave.setupExperiment(startTime=0.0)
    slave.enterInitializationMode()
    for name, value in parameters.items():
        _set(slave, variables[name], value)
    slave.exitInitializationMode()
    vrs = [variables[n].valueReference for n in inputs]
    outs = [v.valueReference for v in variables.values() if v.causality == "output"]
    rows = []
    for k in range(steps):
        slave.setReal(vrs, [1e-6 * ((3 * k + j) % 11 - 5) for j in range(len(vrs))])
        slave.doStep(k * step, step)
        rows.append(slave.getReal(outs))
    sources = _compiled_sources()
    slave.terminate()
    slave.freeInstance()
    return {"rows": rows, "compiled_sources": sources}


def libm(n: int) -> dict:
    """numba's math functions of ``n`` fixed arguments in [-4, 4] and [-1e-3, 1e-3]."""
    import math

    import numba
    import numpy as np

    @numba.njit(cache=False)
    def values(x):
        out = np.empty((x.size, 5))
        for i in range(x.size):
            out[i, 0] = math.sin(x[i])
            out[i, 1] = math.cos(x[i])
            out[i, 2] = math.exp(1e-3 * x[i])
            out[i, 3] = math.atan2(x[i], 1.7)
            out[i, 4] = math.sqrt(abs(x[i]))
        return out

    rng = np.random.default_rng(1)
    x = np.concatenate([rng.uniform(-4.0, 4.0, n), rng.uniform(-1e-3, 1e-3, n // 2)])
    return {"values": values(x).tolist()}


def fuzz(fmu: str, examples: int, seed: int) -> dict:
    from support.fuzz_fmi import campaign

    return campaign(fmu, examples, seed)


KINDS = {"loop": loop, "validate": validate, "two_builds": two_builds, "drive": drive,
         "libm": libm, "fuzz": fuzz}


def run_jobs(jobs: list) -> dict:
    """Run ``[name, kind, arguments]`` jobs in order, each caught on its own."""
    results = {}
    for name, kind, arguments in jobs:
        start = time.perf_counter()
        try:
            results[name] = {"ok": True, "result": KINDS[kind](**arguments)}
        except Exception:  # reported to the test, which fails naming the job
            results[name] = {"ok": False, "error": traceback.format_exc()}
        results[name]["seconds"] = time.perf_counter() - start
    return results


def main() -> int:
    import shutil

    jobs = json.loads(Path(sys.argv[1]).read_text())
    results = run_jobs(jobs)
    for folder in _UNZIPPED:  # a library still loaded (Windows) keeps its folder: ignored
        shutil.rmtree(folder, ignore_errors=True)
    print(json.dumps(results))
    return 0


if __name__ == "__main__":
    sys.exit(main())
