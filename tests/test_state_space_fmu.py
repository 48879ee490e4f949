"""StateSpaceController.fmu through fmpy: equals a numpy simulation of the same matrices
(scipy.signal.dlsim, 1e-14), compiled and Python steps, the default build = the P law, limits,
and one-line errors for a resource that does not fit (at instantiation)."""

from __future__ import annotations

import json
import sys

import numpy as np
import pytest
import scipy.signal
from fmpy import extract, read_model_description

from drillcosim.controller.state_space import Signal, StateSpaceController, StateSpaceParams
from drillcosim.fmu_src.build import REGISTRY, build_one, law_recipe
from support.fmi_logging import RecordingCallbacks, RecordingInstance, fmu_fixtures

SPEC = next(r for r in REGISTRY if r.name == "StateSpaceController")
TS = 2.5e-4
ERROR = 3

fmu_path, md, vr, unzipdir = fmu_fixtures(SPEC)


def controller(n=7, m=3, p=2, seed=0, lower=-np.inf) -> StateSpaceParams:
    rng = np.random.default_rng(seed)
    A = rng.normal(size=(n, n))
    A *= 0.9 / max(abs(np.linalg.eigvals(A)))
    return StateSpaceParams(A, rng.normal(size=(n, m)), rng.normal(size=(p, n)),
                            rng.normal(size=(p, m)), [Signal(f"y{i}") for i in range(m)],
                            [Signal(f"u{i}", "N", lower) for i in range(p)], TS, "test")


def variant(name: str, prm: StateSpaceParams, folder, resource: StateSpaceParams | None = None):
    """Build a variant for ``prm``'s interface carrying ``resource``'s matrices (default prm)."""
    src = folder / f"{name}.json"
    (resource or prm).save(src)
    layout = {"inputs": [[s.name, s.unit, f"input {s.name}"] for s in prm.inputs],
              "outputs": [[s.name, s.unit, f"output {s.name}"] for s in prm.outputs],
              "lower": [None if np.isinf(s.lower) else s.lower for s in prm.outputs],
              "upper": [None if np.isinf(s.upper) else s.upper for s in prm.outputs],
              "n_states": prm.n_states, "sample_period": prm.sample_period,
              "description": f"test variant {name}"}
    recipe = law_recipe(StateSpaceController, layout, name=name, resource=src)
    path = build_one(recipe, folder)
    return path, recipe


class Run:
    """An initialized instance of an FMU file with name -> value reference."""

    def __init__(self, path, folder, prefix="ss"):
        self.md = read_model_description(str(path))
        self.vr = {v.name: v.valueReference for v in self.md.modelVariables}
        self.inst = RecordingInstance(self.md, extract(str(path), unzipdir=str(folder)), prefix)
        self.fmu = self.inst.fmu

    def init(self, booleans=None, reals=None):
        self.fmu.setupExperiment(startTime=0.0)
        self.fmu.enterInitializationMode()
        for k, v in (booleans or {}).items():
            self.fmu.setBoolean([self.vr[k]], [v])
        for k, v in (reals or {}).items():
            self.fmu.setReal([self.vr[k]], [v])
        self.fmu.exitInitializationMode()
        return self

    def run(self, prm: StateSpaceParams, y: np.ndarray, h: float = TS) -> np.ndarray:
        ins = [self.vr[n] for n in prm.input_names]
        outs = [self.vr[n] for n in prm.output_names]
        out = []
        for k, yk in enumerate(y):
            self.fmu.setReal(ins, list(yk))
            self.fmu.doStep(k * h, h)
            out.append(self.fmu.getReal(outs))
        return np.array(out)


@pytest.fixture(scope="module")
def built(tmp_path_factory):
    folder = tmp_path_factory.mktemp("state_space_fmus")
    prm = controller()
    path, recipe = variant("StateSpaceController_test", prm, folder)
    return prm, path, recipe, folder


@pytest.mark.parametrize("compiled", [True, False])
def test_fmu_equals_numpy_simulation(built, tmp_path, compiled, monkeypatch):
    """Compiled (``DRILLCOSIM_COMPILED_STEP=1``, numba loaded in this process) and the numpy
    reference (``=0``) both equal scipy's dlsim of the same matrices."""
    monkeypatch.setenv("DRILLCOSIM_COMPILED_STEP", "1" if compiled else "0")
    prm, path, recipe, _ = built
    y = np.random.default_rng(1).normal(size=(300, 3))
    _t, ref, _x = scipy.signal.dlsim((prm.A, prm.B, prm.C, prm.D, TS), y)
    run = Run(path, tmp_path).init()
    out = run.run(prm, y)
    assert np.max(np.abs(out - ref)) <= 1e-14 * np.max(np.abs(ref))
    run.fmu.terminate()
    run.fmu.freeInstance()


@pytest.mark.parametrize("compiled", [True, False])
def test_compiled_step_never_enters_python(built, tmp_path, monkeypatch, compiled):
    """With the compiled step fmi2DoStep runs the cfunc: the adapter's Python step is not
    called but for a refused step (it names the problem); switched off, once per step. The
    outputs agree to rounding (numba's BLAS product vs numpy's)."""
    monkeypatch.setenv("DRILLCOSIM_COMPILED_STEP", "1" if compiled else "0")
    prm, path, recipe, _ = built
    run = Run(path, tmp_path).init()
    res = tmp_path / "resources"
    cls = getattr(sys.modules[(res / "slavemodule.txt").read_text().strip()],
                  (res / "slaveclass.txt").read_text().strip()).__mro__[1]   # the adapter
    calls = []
    original = cls._step_law
    monkeypatch.setattr(cls, "_step_law", lambda self, t, h: (calls.append(t),
                                                              original(self, t, h))[1])
    y = np.random.default_rng(2).normal(size=(20, 3))
    out = run.run(prm, y)
    assert len(calls) == (0 if compiled else 20)
    from drillcosim.controller.state_space import StateSpaceController

    law = StateSpaceController(prm)
    ref = np.array([law.step(k * TS, TS, yk) for k, yk in enumerate(y)])
    np.testing.assert_allclose(out, ref, rtol=0, atol=1e-13 * np.max(np.abs(ref)))
    run.fmu.setReal([run.vr["y1"]], [float("nan")])
    with pytest.raises(Exception, match="status 3"):
        run.fmu.doStep(20 * TS, TS)
    assert len(calls) == (1 if compiled else 21)
    assert "non-finite input(s) y1" in run.inst.text()
    assert np.array_equal(run.fmu.getReal([run.vr["u0"], run.vr["u1"]]), out[-1])
    run.fmu.freeInstance()


def test_default_build_is_the_p_law(fmu_path, project_fmus, tmp_path):
    """The default StateSpaceController.fmu (D = 1e9 I) equals StrainController.fmu at its
    default gain 1e9, bit for bit."""
    ss = Run(fmu_path, tmp_path / "a").init()
    p = Run(project_fmus["StrainController"], tmp_path / "b", "p").init(reals={"gain": 1e9})
    names = [f"strain{s}_{a}" for s in (1, 2) for a in "CE"]
    forces = [f"actuator{s}_force_{a}" for s in (1, 2) for a in "CE"]
    rng = np.random.default_rng(3)
    for k in range(10):
        y = list(rng.normal(scale=1e-5, size=4))
        for r in (ss, p):
            r.fmu.setReal([r.vr[n] for n in names], y)
            r.fmu.doStep(k * TS, TS)
        assert (ss.fmu.getReal([ss.vr[n] for n in forces])
                == p.fmu.getReal([p.vr[n] for n in forces]))


def test_limits_and_bad_steps(built, tmp_path):
    prm, path, _recipe, _ = built
    run = Run(path, tmp_path).init(reals={"upper_limit_u0": 0.25, "lower_limit_u1": -0.1})
    y = np.random.default_rng(4).normal(size=(50, 3))
    lim = prm.with_limits([-np.inf, -0.1], [0.25, np.inf])
    from drillcosim.controller.state_space import StateSpaceController

    law = StateSpaceController(lim)
    ref = np.array([law.step(k * TS, TS, yk) for k, yk in enumerate(y)])
    out = run.run(prm, y)
    assert np.max(np.abs(out - ref)) <= 1e-14 * np.max(np.abs(ref))
    assert out[:, 0].max() <= 0.25 and out[:, 1].min() >= -0.1
    before = run.fmu.getReal([run.vr["u0"], run.vr["u1"]])
    for h in (0.5 * TS, 3.3 * TS):
        with pytest.raises(Exception, match="status 3"):
            run.fmu.doStep(1.0, h)
    assert "not an integer multiple of the controller's sample period" in run.inst.text()
    assert run.fmu.getReal([run.vr["u0"], run.vr["u1"]]) == before
    run.fmu.setReal([run.vr["lower_limit_u0"]], [1.0])     # above its upper limit 0.25
    with pytest.raises(Exception, match="status 3"):
        run.fmu.doStep(1.0, TS)
    assert "lower_limit > upper_limit (or NaN) for u0" in run.inst.text()
    run.fmu.freeInstance()


@pytest.mark.parametrize("case, message", [  # fmi2Instantiate fails (NULL), one line
    ("nan", "D[1, 2] = nan: every entry must be finite"),
    ("names", "does not fit this FMU: inputs"),
    ("states", "does not fit this FMU: n_states 6"),
])
def test_bad_resource_is_one_line_at_instantiation(built, tmp_path, case, message):
    prm, _path, _recipe, folder = built
    data = prm.to_mapping()
    if case == "nan":
        data["D"][0][1] = float("nan")
    elif case == "names":
        data["inputs"][0]["name"] = "other"
    else:
        small = controller(n=6)
        data = small.to_mapping()
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps(data))
    unzipped = tmp_path / "unzipped"
    extract(str(_path), unzipdir=str(unzipped))
    (unzipped / "resources" / "state_space.json").write_text(bad.read_text())
    md_ = read_model_description(str(_path))
    from fmpy.fmi2 import FMU2Slave

    rec = RecordingCallbacks()
    fmu = FMU2Slave(guid=md_.guid, unzipDirectory=str(unzipped),
                    modelIdentifier=md_.coSimulation.modelIdentifier, instanceName="bad")
    with pytest.raises(Exception, match="[Ff]ailed to instantiate"):
        fmu.instantiate(callbacks=rec.callbacks, loggingOn=True)
    lines = [m for s, m in rec.messages if s >= ERROR]
    assert len(lines) == 1 and message in lines[0] and "\n" not in lines[0], rec.messages
    assert "fmi2Instantiate" in lines[0]
