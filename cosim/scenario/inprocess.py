"""In-process slaves: the plant simulator and the controller laws behind the master's slave
protocol (:class:`cosim.master.slave.Slave`), without FMI.

The FMUs wrap the same objects (``fmu_src/``): :class:`PlantSlave` steps a
:class:`plant.simulator.PlantSimulator`, :class:`LawSlave` any registered controller law
(:mod:`controller.registry`; its inputs and outputs from the law's port table) exactly as the
FMU adapters do
(same times, same step sizes, outputs taken after each step, a failed plant step discarded with
the plant's own message; the plant is the model the plant FMU builds: the scene's, or the 3D
model for a scene the default plant FMU runs) and through the same compiled steps
(:mod:`plant.compiled_step`, :mod:`controller.compiled`, called here through ctypes), so the master
(:class:`cosim.master.execution.Execution`, its algorithms, delay lines and observers) gives
the same numbers with either, bit for bit (``tests/test_sweep.py``), while the in-process
slaves save the FMI boundary. Parameters stay typed (:class:`plant.model.DrillstringModel`,
the laws' parameters).

:func:`inprocess_slaves` makes the slaves that stand in for the FMUs of a configuration
(:func:`.build.build_system` with ``engine="inprocess"`` wires them as it wires the FMUs).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from drillcosim.controller import Law
from drillcosim.controller.ports import inputs, names, outputs
from drillcosim.cosim.master import state_codec
from drillcosim.cosim.master.errors import FMI2_DISCARD, FMI2_ERROR, CosimError
from drillcosim.cosim.master.slave import CompiledCalls, Slave
from drillcosim.cosim.master.system import ParameterValue, _did_you_mean
from drillcosim.plant.model import DrillstringModel
from drillcosim.plant.signals import PLANT
from drillcosim.plant.simulator import PlantSimulator

from .config import SceneConfig
from .scene_fmus import plant_layout

__all__ = ["LawSlave", "PlantSlave", "inprocess_slaves"]


class _ArraySlave(Slave):
    """Shared parts: named inputs/outputs held in arrays, binding to the master's buffers."""

    def __init__(self, name: str, inputs: Sequence[str], outputs: Sequence[str]):
        self.name = name
        self.inputs = list(inputs)
        self.outputs = list(outputs)
        self._causality = {**dict.fromkeys(self.outputs, "output"),
                           **dict.fromkeys(self.inputs, "input")}
        self.u = np.zeros(len(self.inputs))        # inputs held over the next step
        self.y = np.zeros(len(self.outputs))       # outputs of the last step
        self._problem: str | None = None
        self._in_idx = self._out_idx = np.zeros(0, dtype=np.intp)
        self._uv = self._yv = np.zeros(0)

    def check_variable(self, name: str, causalities: Sequence[str]) -> None:
        """``ValueError`` unless ``name`` is an input/output of one of ``causalities``."""
        c = self._causality.get(name)
        if c is None:
            raise ValueError(f"in-process '{self.name}' has no variable '{name}'"
                             f"{_did_you_mean(name, list(self._causality))}")
        if c not in causalities:
            raise ValueError(f"'{self.name}.{name}' has causality '{c}', expected one of "
                             f"{tuple(causalities)}")

    def bind(self, outputs: Sequence[str], y, offset: int, inputs: Sequence[str], u) -> None:
        """Views on the master's buffers (no copies) and the index maps."""
        self._yv = np.ctypeslib.as_array(y)[offset:offset + len(outputs)]
        self._out_idx = np.array([self.outputs.index(n) for n in outputs], dtype=np.intp)
        self._uv = np.ctypeslib.as_array(u)[:len(inputs)]
        self._in_idx = np.array([self.inputs.index(n) for n in inputs], dtype=np.intp)

    def write_inputs(self) -> int:
        """Take the bound inputs from the master's buffer."""
        self.u[self._in_idx] = self._uv
        return 0

    def read_outputs(self) -> int:
        """Put the outputs of the last step into the master's buffer."""
        np.take(self.y, self._out_idx, out=self._yv)
        return 0

    def get_real(self, name: str, time: float) -> float:
        """An input or output by name."""
        if name in self.outputs:
            return float(self.y[self.outputs.index(name)])
        if name in self.inputs:
            return float(self.u[self.inputs.index(name)])
        raise ValueError(f"in-process '{self.name}' has no variable '{name}'")

    def set_value(self, name: str, value: ParameterValue, time: float) -> None:
        """Set an input (parameters are fixed at construction)."""
        if name not in self.inputs:
            raise CosimError(self.name, f"set {name}", time, "an in-process slave takes its "
                             "parameters at construction; only inputs can be set")
        self.u[self.inputs.index(name)] = float(value)

    def take_problem(self) -> str | None:
        """The message of the last failed step, once."""
        problem, self._problem = self._problem, None
        return problem

    def close(self) -> None:
        """Nothing to release."""

    can_get_set_state = True

    def get_state(self, time: float):
        """The model's state (:meth:`_save`), inputs and outputs."""
        return self._save(), self.u.copy(), self.y.copy()

    def set_state(self, state, time: float) -> None:
        """Restore a state from :meth:`get_state`."""
        model, u, y = state
        self._restore(model)
        self.u[:], self.y[:] = u, y
        self.errored = False

    def serialize_state(self, time: float) -> bytes:
        """:meth:`get_state` as bytes (:mod:`cosim.master.state_codec`: JSON, no code)."""
        return state_codec.encode(self.get_state(time))

    def deserialize_state(self, data: bytes, time: float) -> None:
        """Restore :meth:`serialize_state`'s bytes, all or (CosimError) nothing."""
        try:
            model, u, y = state_codec.decode(data)
            if np.shape(u) != self.u.shape or np.shape(y) != self.y.shape:
                raise ValueError(f"{np.size(u)} inputs and {np.size(y)} outputs; this "
                                 f"component has {self.u.size} and {self.y.size}")
            saved = self._save()
            try:
                self._restore(model)
            except BaseException:
                self._restore(saved)
                raise
        except (ValueError, TypeError) as exc:
            raise CosimError(self.name, "restore state", time, str(exc)) from None
        self.u[:], self.y[:] = u, y
        self.errored = False

    def _compiled_calls(self, step: Any) -> CompiledCalls:
        """The master's native loop view of ``step`` (a compiled step reading ``self.u`` and
        writing ``self.y``, both kept in place): the bound inputs and outputs by slot."""
        return CompiledCalls(step.function, step.context, self.u.ctypes.data,
                             tuple(int(i) for i in self._in_idx), self.y.ctypes.data,
                             tuple(int(i) for i in self._out_idx))

    def _save(self):  # pragma: no cover - each subclass has its own
        raise NotImplementedError

    def _restore(self, state) -> None:  # pragma: no cover
        raise NotImplementedError


class PlantSlave(_ArraySlave):
    """:class:`plant.simulator.PlantSimulator` as a slave (inputs: actuator forces [N];
    outputs: :attr:`plant.model.DrillstringModel.output_names`).

    Parameters
    ----------
    name : str
        Instance name.
    simulator : PlantSimulator
    """

    def __init__(self, name: str, simulator: PlantSimulator):
        super().__init__(name, simulator.input_names, simulator.model.output_names)
        self.sim = simulator
        self._halted: str | None = None
        # the plant FMU's compiled step on this slave's arrays (None: Python do_step)
        self._step = simulator.compiled_step(self.u, np.arange(len(self.inputs)), self.y,
                                             np.arange(len(self.outputs)))

    def instantiate(self, start_time: float, stop_time: float | None) -> None:
        """Start at ``start_time`` with the outputs of the initial state."""
        self.sim.time = float(start_time)
        self._halted = None
        self.y[:] = self.sim.outputs()

    def do_step(self, t: float, h: float) -> int:
        """One plant step; a divergence discards it (and every later one), with the plant's
        message; a refused step (bad time, step or input) is an error, state unchanged."""
        if self._halted is not None:
            self._problem = f"the simulation diverged earlier ({self._halted})"
            return FMI2_DISCARD
        if self._step is not None:
            res = self._step.step(t, h)  # inputs from self.u, outputs into self.y
        else:
            sim = self.sim
            sim.u[:] = self.u
            res = sim.do_step(t, h)
            if res.ok:
                self.y[:] = sim.outputs()
        return self._settle(res)

    def _settle(self, res) -> int:
        """The status of a step's :class:`~plant.simulator.StepResult` (its message kept)."""
        if not res.ok:
            self._problem = res.message
            if not res.quantity:
                return FMI2_ERROR
            self._halted = res.message
            return FMI2_DISCARD
        return 0

    def native_calls(self) -> CompiledCalls | None:
        """The compiled step for the master's native loop (None once diverged: every later
        step is discarded in Python, as the FMU does)."""
        if self._step is None or self._halted is not None:
            return None
        self._step.refresh()  # the method or operator may have changed in Python
        return self._compiled_calls(self._step)

    def native_step_failed(self, code: int, t: float, h: float) -> int:
        """A compiled step's failure code settled as :meth:`do_step` would (a fallback runs
        the step in Python)."""
        return self._settle(self._step.finish(code, t, h))

    def _save(self):
        return self.sim.get_state(), self._halted

    def _restore(self, state) -> None:
        sim_state, self._halted = state
        self.sim.set_state(sim_state)


class LawSlave(_ArraySlave):
    """A controller law as a slave (``controller/law.py``): stepped by its compiled step on
    this slave's arrays, as in the controller FMUs, else (or for a step the compiled law leaves
    to Python) by :meth:`Law.advance <controller.law.Law.advance>`; a ``ValueError`` of the law
    is the step's error, state unchanged.

    Parameters
    ----------
    name : str
        Instance name.
    law : controller.law.Law
        The law (made for its layout: ``Law.create``).
    ports : sequence of controller.ports.Port
        Its port table for that layout (the inputs and outputs, in the law's array order).
    """

    def __init__(self, name: str, law: Law, ports: Sequence[Any]):
        super().__init__(name, names(inputs(ports)), names(outputs(ports)))
        self.law = law
        self._step = law.compiled_step(self.u, self.y)

    def instantiate(self, start_time: float, stop_time: float | None) -> None:
        """The law's state back to its start (zero force, integral, state), its outputs."""
        self.law.reset()
        self.y[:] = self.law.initial_outputs()

    def do_step(self, t: float, h: float) -> int:
        """The outputs at ``t + h`` from the inputs held over the step."""
        if self._step is not None:
            code = self._step.step(t, h)
            if code == 0:
                return 0
            return self.native_step_failed(code, t, h)
        return self._python_step(t, h)

    def _python_step(self, t: float, h: float) -> int:
        try:
            self.law.advance(t, h, self.u, self.y)
        except ValueError as exc:
            self._problem = f"at t = {t!r}: {exc}"
            return FMI2_ERROR
        return 0

    def native_calls(self) -> CompiledCalls | None:
        """The law's compiled step for the master's native loop (None: stepped in Python)."""
        return None if self._step is None else self._compiled_calls(self._step)

    def native_step_failed(self, code: int, t: float, h: float) -> int:
        """A step the compiled law left to Python (nothing changed): the Python step; an
        internal failure raises."""
        self._step.check(code, t, h)
        return self._python_step(t, h)

    def _save(self):
        return self.law.get_state()

    def _restore(self, state) -> None:
        self.law.set_state(state)


def inprocess_slaves(config: SceneConfig) -> dict[str, Slave]:
    """In-process slaves standing in for the FMUs of a configuration's system.

    The plant is the model the plant FMU builds: the scene's own (any number of actuator
    sites), or the 3D model for a scene the default plant FMU runs (:func:`.scene_fmus.
    plant_layout`); the strain controller serves every site of the plant.

    Returns
    -------
    dict
        ``{"plant": PlantSlave, "controller": LawSlave, "top_drive_controller": LawSlave}``
        (the enabled controllers), for ``Master(system, slaves)``.
    """
    scene = config.scene
    kind = "full3d" if plant_layout(scene) is None else scene.model
    slaves: dict[str, Slave] = {
        PLANT: PlantSlave(PLANT, PlantSimulator(DrillstringModel(scene.plant, kind)))}
    for instance in config.instances[1:]:
        setting = config.controllers[instance]
        layout = setting.layout(config.n_sites)
        law = setting.law
        slaves[instance] = LawSlave(instance, law.create(setting.params, layout),
                                    law.ports(layout))
    return slaves
