"""The FMUs in a Python host of any version: a script that needs only fmpy and numpy.

Usage (run by ``tests/test_python_versions.py`` with the Python of each version's venv)::

    python version_run.py PLANT.fmu CONTROLLER.fmu

Prints one JSON object: the interpreter's version and, per run, the recorded outputs (a list of
rows, one per communication point, ``repr``-exact floats):

* ``plant``: the plant FMU alone, 40 steps of 0.25 ms, a sine force on every actuator input;
* ``controller``: the strain controller alone, 40 steps of 1 ms with a first-order lag, strain
  ramps on every input;
* ``closed_loop``: both, Gauss-Seidel at 0.25 ms for 40 steps, the plant's strains into the
  controller and its forces back into the plant (the paper's loop, gain 1e9), plus a sine
  disturbance force on every actuator input.

Only the FMI functions are used (fmpy's ``FMU2Slave``), as a user's tool on another Python would.
"""

from __future__ import annotations

import json
import math
import sys

from fmpy import extract, read_model_description
from fmpy.fmi2 import FMU2Slave

PLANT_STEP = 2.5e-4
STEPS = 40


class Fmu:
    """One instance: value references by name, the outputs in model order."""

    def __init__(self, path: str, name: str) -> None:
        md = read_model_description(path)
        self.slave = FMU2Slave(guid=md.guid, unzipDirectory=extract(path), instanceName=name,
                               modelIdentifier=md.coSimulation.modelIdentifier)
        self.vr = {v.name: v.valueReference for v in md.modelVariables}
        self.outputs = [v.name for v in md.modelVariables if v.causality == "output"]
        self.inputs = [v.name for v in md.modelVariables if v.causality == "input"]
        self.slave.instantiate()
        self.slave.setupExperiment(startTime=0.0)
        self.slave.enterInitializationMode()

    def start(self, reals: dict[str, float]) -> None:
        """Set parameters in initialization mode and leave it."""
        if reals:
            self.slave.setReal([self.vr[k] for k in reals], list(reals.values()))
        self.slave.exitInitializationMode()

    def set(self, values: dict[str, float]) -> None:
        self.slave.setReal([self.vr[k] for k in values], list(values.values()))

    def get(self, names: list[str]) -> list[float]:
        return list(self.slave.getReal([self.vr[k] for k in names]))

    def close(self) -> None:
        self.slave.terminate()
        self.slave.freeInstance()


def plant_alone(path: str) -> list[list[float]]:
    plant = Fmu(path, "plant")
    plant.start({"max_internal_step": PLANT_STEP})
    rows = [plant.get(plant.outputs)]
    for k in range(STEPS):
        plant.set({name: 1e3 * math.sin(50.0 * k * PLANT_STEP + i)
                   for i, name in enumerate(plant.inputs)})
        plant.slave.doStep(k * PLANT_STEP, PLANT_STEP)
        rows.append(plant.get(plant.outputs))
    plant.close()
    return rows


def controller_alone(path: str) -> list[list[float]]:
    ctrl = Fmu(path, "controller")
    ctrl.start({"lag_time_constant": 0.01})
    rows = [ctrl.get(ctrl.outputs)]
    for k in range(STEPS):
        ctrl.set({name: 1e-6 * (k + 1) * (i + 1) for i, name in enumerate(ctrl.inputs)})
        ctrl.slave.doStep(k * 1e-3, 1e-3)
        rows.append(ctrl.get(ctrl.outputs))
    ctrl.close()
    return rows


def closed_loop(plant_path: str, controller_path: str) -> list[list[float]]:
    plant, ctrl = Fmu(plant_path, "plant"), Fmu(controller_path, "controller")
    plant.start({"max_internal_step": PLANT_STEP})
    ctrl.start({})
    strains = ctrl.inputs  # the plant's outputs of these names
    rows = []
    for k in range(STEPS + 1):
        ctrl.set(dict(zip(strains, plant.get(strains))))
        forces = ctrl.get(ctrl.outputs)
        rows.append(plant.get(plant.outputs) + forces)
        if k == STEPS:
            break
        plant.set({name: f + 1e3 * math.sin(50.0 * k * PLANT_STEP + i)
                   for i, (name, f) in enumerate(zip(ctrl.outputs, forces))})
        plant.slave.doStep(k * PLANT_STEP, PLANT_STEP)
        ctrl.slave.doStep(k * PLANT_STEP, PLANT_STEP)
    plant.close()
    ctrl.close()
    return rows


def main(argv: list[str]) -> int:
    plant_path, controller_path = argv
    result = {"python": sys.version.split()[0],
              "plant": plant_alone(plant_path),
              "controller": controller_alone(controller_path),
              "closed_loop": closed_loop(plant_path, controller_path)}
    print(json.dumps(result))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
