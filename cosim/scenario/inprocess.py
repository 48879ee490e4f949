"""In-process slaves: the plant simulator and the controller law behind the master's slave
protocol (:class:`cosim.master.slave.Slave`), without FMI.

The FMUs wrap the same objects (``fmu_src/``): :class:`PlantSlave` steps a
:class:`plant.simulator.PlantSimulator` and :class:`ControllerSlave` a
:class:`controller.StrainController` exactly as the FMU adapters do (same times, same step
sizes, outputs taken after each step, a failed plant step discarded with the plant's own
message), so the master (:class:`cosim.master.execution.Execution`, its algorithms, delay
lines and observers) gives the same numbers with either, bit for bit
(``tests/test_sweep.py``), while the in-process pair saves the FMI boundary. Parameters stay
typed (:class:`plant.model.DrillstringModel`, :class:`controller.ControllerParams`).

:func:`inprocess_slaves` makes the slaves that stand in for the FMUs of a
:class:`~.scene_system.SceneSystem` (the FMU files still describe the system: instance names,
variables, wiring; they are not loaded).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from drillcosim.controller import N_CHANNELS, ControllerParams, StrainController
from drillcosim.cosim.master.errors import FMI2_DISCARD, FMI2_ERROR, CosimError
from drillcosim.cosim.master.slave import Slave
from drillcosim.cosim.master.system import ParameterValue, _did_you_mean
from drillcosim.plant.model import DrillstringModel
from drillcosim.plant.simulator import PlantSimulator

from .scene_system import AXES, CONTROLLER, CONTROLLER_SITES, PLANT, SceneSystem, scene_controller

__all__ = ["ControllerSlave", "PlantSlave", "inprocess_slaves", "inprocess_system"]


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
        sim = self.sim
        sim.u[:] = self.u
        res = sim.do_step(t, h)
        if not res.ok:
            self._problem = res.message
            if not res.quantity:
                return FMI2_ERROR
            self._halted = res.message
            return FMI2_DISCARD
        self.y[:] = sim.outputs()
        return 0

    def _save(self):
        return self.sim.get_state(), self._halted

    def _restore(self, state) -> None:
        sim_state, self._halted = state
        self.sim.set_state(sim_state)


class ControllerSlave(_ArraySlave):
    """:class:`controller.StrainController` as a slave (inputs: the strains, outputs: the
    actuator forces [N] of ``sites``, gauges C and E).

    Parameters
    ----------
    name : str
        Instance name.
    params : ControllerParams
    sites : sequence of int
        Actuator sites served (default :data:`~.scene_system.CONTROLLER_SITES`, the two of
        the controller FMU). The law acts channel by channel, so more sites are served by
        one :class:`StrainController` (four channels) per pair of sites, the last one padded
        with a zero strain.
    """

    def __init__(self, name: str, params: ControllerParams,
                 sites: Sequence[int] = CONTROLLER_SITES):
        pairs = [(s, a) for s in sites for a in AXES]
        super().__init__(name, [f"strain{s}_{a}" for s, a in pairs],
                         [f"actuator{s}_force_{a}" for s, a in pairs])
        n = len(pairs)
        self.laws = [StrainController(params) for _ in range(0, n, N_CHANNELS)]
        self._pad = np.zeros(len(self.laws) * N_CHANNELS)

    def _forces(self, parts: Sequence[np.ndarray]) -> np.ndarray:
        return np.concatenate(parts)[:len(self.outputs)]

    def instantiate(self, start_time: float, stop_time: float | None) -> None:
        """Zero force (the lag state) at the start."""
        for law in self.laws:
            law.reset()
        self.y[:] = self._forces([law.forces for law in self.laws])

    def do_step(self, t: float, h: float) -> int:
        """The force at ``t + h`` from the strains held over the step."""
        self._pad[:len(self.u)] = self.u
        try:
            parts = [law.step(t, h, self._pad[i * N_CHANNELS:(i + 1) * N_CHANNELS])
                     for i, law in enumerate(self.laws)]
        except ValueError as exc:
            self._problem = f"at t = {t!r}: {exc}"
            return FMI2_ERROR
        self.y[:] = self._forces(parts)
        return 0

    def _save(self):
        return [law.get_state() for law in self.laws]

    def _restore(self, state) -> None:
        for law, st in zip(self.laws, state):
            law.set_state(st)


def inprocess_slaves(ss: SceneSystem) -> dict[str, Slave]:
    """In-process slaves standing in for the FMUs of a scene's system (built from the scene).

    Returns
    -------
    dict
        ``{"plant": PlantSlave, "controller": ControllerSlave}`` (no controller when the
        scene's controller is disabled), for ``Execution(..., slaves=...)``.
    """
    scene = ss.scene
    slaves: dict[str, Slave] = {
        PLANT: PlantSlave(PLANT, PlantSimulator(DrillstringModel(scene.plant, scene.model)))}
    if CONTROLLER in {f.name for f in ss.system.fmus}:
        slaves[CONTROLLER] = ControllerSlave(CONTROLLER, scene_controller(scene))
    return slaves


def inprocess_system(scene) -> tuple[SceneSystem, dict[str, Slave]]:
    """A scene's system and its in-process slaves, for any number of actuator sites.

    The FMU pair serves the two sites of :data:`~.scene_system.CONTROLLER_SITES`
    (:func:`~.scene_system.scene_system` refuses other plants); in process the plant takes the
    scene's sites (``[actuators] joints``) and :class:`ControllerSlave` serves all of them, so
    the same master, with the same algorithm, order, delays and sampling as
    :func:`~.scene_system.scene_system` builds from the scene's ``[cosim]``, runs e.g. 1, 2 or
    3 sites per span. No FMU file is read; the instances' paths are placeholders.

    Parameters
    ----------
    scene : plant.scene.Scene
        A loaded scene (``model = 'full3d'`` when its controller is enabled).

    Returns
    -------
    SceneSystem, dict
        The system (recorded outputs: per contact body X, Y, radial deflection, contact
        force; per site the strains C/E and the actuator power; the controller's forces) and
        ``{"plant": PlantSlave, "controller": ControllerSlave}`` (no controller when the
        scene's controller is disabled) for ``Execution(ss.system, slaves=...)``.
    """
    from drillcosim.cosim.master.system import Connection, FmuSpec, SystemSpec

    from .scene_system import cosim_settings

    settings = cosim_settings(scene)
    params = scene_controller(scene)
    plant = PlantSlave(PLANT, PlantSimulator(DrillstringModel(scene.plant, scene.model)))
    slaves: dict[str, Slave] = {PLANT: plant}
    sites = range(1, len(scene.plant.actuator_joints) + 1)
    outputs = [f"{PLANT}.body{b}_{q}" for b in scene.plant.contact_bodies
               for q in ("X", "Y", "radial_deflection", "contact_force")]
    outputs += [f"{PLANT}.{n}" for s in sites
                for n in (*(f"strain{s}_{a}" for a in AXES), f"actuator{s}_power")]
    missing = [o for o in outputs if o.split(".", 1)[1] not in plant.outputs]
    if missing:
        raise ValueError(f"{scene.source}: the plant has no output {', '.join(missing)}")
    fmus = [FmuSpec(PLANT, "<in-process plant>")]
    connections: list[Connection] = []
    order: tuple[str, ...] = (PLANT,)
    if params.enabled:
        if scene.model != "full3d":
            raise ValueError(f"{scene.source}: the controller needs model = 'full3d', "
                             f"got '{scene.model}'")
        ctrl = ControllerSlave(CONTROLLER, params, tuple(sites))
        slaves[CONTROLLER] = ctrl
        fmus.append(FmuSpec(CONTROLLER, "<in-process controller>", {},
                            settings.controller_sample_ticks))
        for s in sites:
            for a in AXES:
                connections.append(Connection(f"{PLANT}.strain{s}_{a}",
                                              f"{CONTROLLER}.strain{s}_{a}",
                                              settings.sensor_delay, settings.coupling))
                connections.append(Connection(f"{CONTROLLER}.actuator{s}_force_{a}",
                                              f"{PLANT}.actuator{s}_force_{a}",
                                              settings.actuator_delay, settings.coupling))
        outputs += [f"{CONTROLLER}.{n}" for n in ctrl.outputs]
        order = settings.order
    system = SystemSpec(fmus, connections, settings.step, settings.algorithm, order, 0.0,
                        settings.stop_time)
    return SceneSystem(scene, system, settings, tuple(outputs)), slaves
