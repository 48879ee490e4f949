"""In-process slaves in the one master: state save/restore, failures with the model's own
message, interface checks (cosim.scenario.inprocess; equality with the FMUs: test_sweep.py)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from drillcosim.cosim.master.errors import CosimError
from drillcosim.cosim.master.execution import Execution
from drillcosim.cosim.master.master import Master
from drillcosim.cosim.master.recorder import Recorder
from drillcosim.cosim.scenario.build import build_system
from drillcosim.cosim.scenario.config import load_config


def closed_loop(**cosim):
    """The closed loop's system with in-process slaves (no FMU file is read)."""
    config = load_config("paper_closed_loop", {"cosim": {"step": 1e-3, **cosim}})
    return build_system(config, "inprocess")


def test_state_restore_with_in_process_slaves_reproduces_the_run():
    """Save at 0.1 s, run to 0.2 s, restore, run again: the same values bit for bit (plant
    state, controller lag state and the master's delay lines)."""
    ss = closed_loop(actuator_delay=2.5e-3, coupling="linear")
    with Execution(ss.system, read_outputs=ss.outputs, slaves=ss.slaves) as ex:
        ex.simulate_until(0.1)
        state = ex.get_state()
        runs = []
        for _ in range(2):
            rec = Recorder(ss.outputs)
            ex.add_observer(rec)
            ex.simulate_until(0.2)
            runs.append(rec.data)
            ex.observers.remove(rec)
            ex.set_state(state)
    assert len(runs[0]) == 101 and np.any(runs[0]["controller.actuator1_force_C"] != 0)
    assert runs[0].tobytes() == runs[1].tobytes()


def test_a_diverging_in_process_plant_stops_the_master_with_its_own_message():
    config = load_config("paper_closed_loop", {
        "cosim.step": 1e-3, "cosim.actuator_delay": 5e-3, "cosim.stop_time": 1.0,
        "controller.gain": 1e14})
    ss = build_system(config, "inprocess")
    with pytest.raises(CosimError) as info:
        Master(ss.system, slaves=ss.slaves).simulate(outputs=ss.outputs)
    err = info.value
    assert (err.fmu_name, err.call, err.status) == ("plant", "fmi2DoStep", 2)
    # the plant's report names the end of the step it discarded and the quantity
    assert err.fmu_message.startswith(f"diverged at t = {err.time + 1e-3:.6g} s: ")
    assert "exceeds" in err.fmu_message
    assert str(err).endswith(err.fmu_message) and 0 < err.time < 1.0
    assert err.result.data["time"][-1] == pytest.approx(err.time)


def test_in_process_slaves_check_the_wiring_like_fmus():
    ss = closed_loop()
    system = ss.system
    bad = dataclasses.replace(system.connections[0], target="controller.strain1_X")
    system = dataclasses.replace(system, connections=[bad, *system.connections[1:]])
    with pytest.raises(ValueError, match="no variable 'strain1_X' \\(did you mean 'strain1_"):
        Master(system, slaves=ss.slaves).simulate(0.01)
    with pytest.raises(ValueError, match="slaves: no instance \\['ctrl'\\]"):
        Execution(ss.system, slaves={"ctrl": closed_loop().slaves["controller"]})
