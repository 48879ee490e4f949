"""Every registered controller law (``controller/registry.py``) is a whole plug-in: its port
table is consistent with its parameters, its FMU declares exactly the table and computes what
the law computes, and it reaches the scene tables, the schema and the in-process slaves.

The FMUs are the project's default builds (session fixture ``project_fmus``: one per law, made
by ``fmu_src/build.py`` from the registry); the reference is the law object itself.
"""

from __future__ import annotations

import dataclasses
import math
import shutil

import numpy as np
import pytest
from fmpy import extract, read_model_description
from fmpy.fmi2 import FMU2Slave

from drillcosim.controller import LAWS, TABLES, kinds, law_named
from drillcosim.controller.ports import CAUSALITIES, TYPES, VARIABILITIES
from drillcosim.cosim.scenario.config import load_config
from drillcosim.cosim.scenario.inprocess import inprocess_slaves
from drillcosim.cosim.scenario.schema import cosim_schema_markdown
from drillcosim.fmu_src.build import REGISTRY

SETTINGS_LAWS = [law for law in LAWS if not law.RESOURCE]
IDS = [law.KIND for law in LAWS]


def _layout(law):
    return law.default_layout()


@pytest.mark.parametrize("law", LAWS, ids=IDS)
def test_port_table_is_consistent(law) -> None:
    ports = law.ports(_layout(law))
    names = [p.name for p in ports]
    assert len(set(names)) == len(names)
    for p in ports:
        assert p.causality in CAUSALITIES and p.variability in VARIABILITIES
        assert p.type in TYPES and p.description
        if p.causality in ("input", "output"):
            assert (p.type, p.variability, p.start) == ("Real", "continuous", 0.0)
        if p.range is not None and p.type in ("Real", "Integer"):
            assert p.range[0] <= p.start <= p.range[1], p.name
    # inputs, then outputs, then parameters
    order = [CAUSALITIES.index(p.causality) for p in ports]
    assert order == sorted(order)
    assert law.KIND in kinds(law.TABLE) and law.TABLE in TABLES
    assert law_named(law.KIND) is law


@pytest.mark.parametrize("law", SETTINGS_LAWS, ids=[law.KIND for law in SETTINGS_LAWS])
def test_parameters_round_trip_through_the_fmu_encoding(law) -> None:
    layout = _layout(law)
    params = law.PARAMS()
    values = law.encode(params, layout)
    declared = {p.name for p in law.ports(layout) if p.causality == "parameter"}
    assert set(values) == declared
    assert law.decode(values, layout) == params  # 1e30 stands for inf both ways
    for f in dataclasses.fields(law.PARAMS):
        if "doc" in f.metadata:  # every field is a scene key with its unit and words
            assert f.name in cosim_schema_markdown()


def _run_fmu(fmu, law, inputs: np.ndarray, h: float) -> np.ndarray:
    """The FMU's outputs after each step with these inputs (default parameters)."""
    md = read_model_description(str(fmu))
    vr = {v.name: v.valueReference for v in md.modelVariables}
    ports = law.ports(_layout(law))
    ins = [vr[p.name] for p in ports if p.causality == "input"]
    outs = [vr[p.name] for p in ports if p.causality == "output"]
    unzip = extract(str(fmu))
    s = FMU2Slave(guid=md.guid, unzipDirectory=unzip,
                  modelIdentifier=md.coSimulation.modelIdentifier, instanceName=law.KIND)
    try:
        s.instantiate()
        s.setupExperiment(startTime=0.0)
        s.enterInitializationMode()
        s.exitInitializationMode()
        rows = []
        for k, u in enumerate(inputs):
            s.setReal(ins, u.tolist())
            s.doStep(k * h, h)
            rows.append(s.getReal(outs))
        s.terminate()
        s.freeInstance()
    finally:
        shutil.rmtree(unzip, ignore_errors=True)
    return np.array(rows)


@pytest.mark.parametrize("law", SETTINGS_LAWS, ids=[law.KIND for law in SETTINGS_LAWS])
def test_fmu_declares_the_table_and_computes_the_law(law, project_fmus) -> None:
    fmu = project_fmus[law.FMU]
    md = read_model_description(str(fmu))
    layout = _layout(law)
    ports = law.ports(layout)
    got = [(v.name, v.causality, v.variability, v.type, v.unit or "", v.description)
           for v in md.modelVariables]
    want = [(p.name, p.causality, p.variability, p.type, p.unit if p.type == "Real" else "",
             p.description) for p in ports]
    assert got == want
    for v, p in zip(md.modelVariables, ports):
        if p.causality == "parameter":
            start = {"Real": float, "Integer": int, "Boolean": lambda x: x in (True, "true")}
            assert start[p.type](v.start) == p.start, p.name
            if p.range is not None:
                lo, hi = (float(x) if x is not None else None for x in (v.min, v.max))
                assert lo == (p.range[0] if math.isfinite(p.range[0]) else None), p.name
                assert hi == (p.range[1] if math.isfinite(p.range[1]) else None), p.name
    n_in = sum(p.causality == "input" for p in ports)
    rng = np.random.default_rng(7)
    scale = 1e-5 if law.TABLE == "controller" else np.array([2.0, 3e3])
    inputs = rng.normal(size=(60, n_in)) * scale + (0 if law.TABLE == "controller"
                                                    else np.array([2.0, 3e3]))
    h = 2.5e-4 if law.TABLE == "controller" else 1e-3
    out = _run_fmu(fmu, law, inputs, h)
    ref_law = law.create(law.decode(law.encode(law.PARAMS(), layout), layout), layout)
    ref = np.empty_like(out)
    for k, u in enumerate(inputs):
        ref_law.advance(k * h, h, u, ref[k])
    assert out.tobytes() == ref.tobytes()
    assert np.ptp(ref) > 0


def test_every_law_has_a_default_fmu_and_a_scene_table() -> None:
    assert {r.name for r in REGISTRY} >= {law.FMU for law in LAWS}
    for law in SETTINGS_LAWS:
        over = {f"{law.TABLE}.kind": law.KIND, f"{law.TABLE}.enabled": True}
        scene = "paper_closed_loop" if law.TABLE == "controller" else "stick_slip_soft_torque"
        config = load_config(scene, {**over, "cosim.stop_time": 0.01})
        setting = config.controllers[law.TABLE]
        assert setting.kind == law.KIND and isinstance(setting.params, law.PARAMS)
        slave = inprocess_slaves(config)[law.TABLE]
        assert type(slave.law) is law
