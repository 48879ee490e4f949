"""The wrapper's compiled-step protocol (``fmu_src/wrapper/dcs_slave.c``), on a tiny FMU.

``mt_compiled`` integrates x' = u either with a numba ``@cfunc`` handed to the wrapper
(``_fmi2_compiled_step``) or with its Python ``do_step``; it counts which path ran. Checked
against the exact integral of a held input (sum of u h) and against the Python path: the
compiled step runs without entering Python, gives the same numbers, turns a failure code
into the slave's status and message, and follows the slave when a Python call switches it
off or restores an FMU state.
"""

from __future__ import annotations

import shutil

import pytest
from fmpy import extract, read_model_description
from fmpy.fmi1 import FMICallException
from fmpy.fmi2 import FMU2Slave

pytestmark = [pytest.mark.needs_cc]


def _open(fmu, name="c"):
    md = read_model_description(str(fmu))
    unzip = extract(str(fmu))
    s = FMU2Slave(guid=md.guid, unzipDirectory=unzip,
                  modelIdentifier=md.coSimulation.modelIdentifier, instanceName=name)
    s.instantiate()
    vr = {v.name: v.valueReference for v in md.modelVariables}
    return s, vr, unzip


def _run(fmu, use_compiled, inputs, h=0.01):
    s, vr, unzip = _open(fmu)
    try:
        s.setBoolean([vr["use_compiled"]], [use_compiled])
        s.setupExperiment(startTime=0.0)
        s.enterInitializationMode()
        s.exitInitializationMode()
        xs = []
        for k, u in enumerate(inputs):
            s.setReal([vr["u"]], [u])
            s.doStep(k * h, h)
            xs.append(s.getReal([vr["x"]])[0])
        counts = s.getReal([vr["n_compiled"], vr["n_python"]])
        s.terminate()
        return xs, counts
    finally:
        s.freeInstance()
        shutil.rmtree(unzip, ignore_errors=True)


def test_compiled_step_equals_the_python_step_and_never_enters_python(fmus):
    inputs = [0.5 * k - 3.0 for k in range(200)]
    exact, x = [], 0.0
    for u in inputs:
        x = x + u * 0.01
        exact.append(x)
    xs_c, (n_c, n_py_c) = _run(fmus["mt_compiled"], True, inputs)
    xs_p, (n_c_p, n_py) = _run(fmus["mt_compiled"], False, inputs)
    assert (n_c, n_py_c) == (200, 0)   # every step compiled, none through Python
    assert (n_c_p, n_py) == (0, 200)   # the reference path
    assert xs_c == xs_p == exact       # bit for bit


def test_a_failure_code_becomes_the_status_the_slave_gives_it(fmus):
    s, vr, unzip = _open(fmus["mt_compiled"])
    try:
        s.setReal([vr["fail_at_time"]], [0.05])
        s.setupExperiment(startTime=0.0)
        s.enterInitializationMode()
        s.exitInitializationMode()
        for k in range(5):
            s.setReal([vr["u"]], [1.0])
            s.doStep(k * 0.01, 0.01)
        with pytest.raises(FMICallException) as info:
            s.doStep(0.05, 0.01)
        assert info.value.status == 2  # fmi2Discard, from _fmi2_compiled_step_failed
        assert s.getReal([vr["n_compiled"], vr["n_python"]]) == [5.0, 0.0]
    finally:
        s.freeInstance()
        shutil.rmtree(unzip, ignore_errors=True)


def test_a_python_call_or_a_restored_state_changes_the_path(fmus):
    s, vr, unzip = _open(fmus["mt_compiled"])
    try:
        s.setupExperiment(startTime=0.0)
        s.enterInitializationMode()
        s.exitInitializationMode()
        s.setReal([vr["u"]], [2.0])
        s.doStep(0.0, 0.5)
        saved = s.getFMUstate()
        s.setBoolean([vr["use_compiled"]], [False])   # a Python call: the step is asked anew
        s.doStep(0.5, 0.5)
        assert s.getReal([vr["x"], vr["n_compiled"], vr["n_python"]]) == [2.0, 1.0, 1.0]
        s.setFMUstate(saved)                          # back to compiled, x = 1
        s.doStep(0.5, 0.5)
        assert s.getReal([vr["x"], vr["n_compiled"], vr["n_python"]]) == [2.0, 2.0, 0.0]
        s.freeFMUstate(saved)
    finally:
        s.freeInstance()
        shutil.rmtree(unzip, ignore_errors=True)
