"""The one builder: a :class:`~.config.SceneConfig` becomes a co-simulation system and its slaves.

:func:`build_system` makes the system every caller runs (``drillcosim run``, the API, sweeps,
ensembles, the calibration, the conclusion study, SSP export) with up to three instances:
``plant``, ``controller`` (the strain controller, when ``[controller] enabled``: the P law, or
with ``kind = "state_space"`` a state-space law from a matrices file) and
``top_drive_controller`` (when ``[top_drive_controller] enabled``), connected by name both ways
(:mod:`.interface`; names from :mod:`plant.signals`):

* sensors: ``plant.strain<s>_<C|E>`` -> ``controller.strain<s>_<C|E>``,
  ``plant.top_rotary_speed`` / ``plant.top_torque`` -> ``top_drive_controller.*`` (delay
  ``sensor_delay``);
* actuators: ``controller.actuator<s>_force_<C|E>`` -> ``plant.actuator<s>_force_<C|E>``,
  ``top_drive_controller.top_drive_torque`` -> ``plant.top_drive_torque`` (delay
  ``actuator_delay``).

Two engines, one system:

``"fmu"``
    FMU files: the user's (:attr:`~.config.SceneConfig.fmu_files`), else the project's, taken
    from ``build/fmus/`` (or ``fmu_dir``) and built there if missing or stale
    (:mod:`.scene_fmus`). The plant FMU gets the scene (``scene``: the shipped name, or the
    file's absolute path) and the plant-parameter overrides as its parameters (scalars only);
    the controller FMUs get their law's parameters encoded for FMI (``Law.encode``).

    A foreign FMU (any maker) gets those of the law's values it declares a parameter of that
    name for, and its own parameters (``[<table>.parameters]``, ``[plant.parameters]``); a law
    key the scene file sets that the FMU does not have is not required of it (a warning names
    it), one set by an override is an error (it would change nothing).
``"inprocess"``
    The same models as in-process slaves (:mod:`.inprocess`), built from the configuration: no
    FMU file is read, the FMI boundary is saved, the numbers are the FMUs' bit for bit.

Either way the system is checked before the first step (causality, type, unit, nothing
connected twice, start values; every problem one line, :class:`InterfaceError`), and
:meth:`Master.simulate <cosim.master.master.Master.simulate>` runs it.
"""

from __future__ import annotations

import warnings
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from fmpy import read_model_description

from drillcosim.cosim.master.interface import FmuInterface, Port, read_interface
from drillcosim.cosim.master.slave import Slave
from drillcosim.cosim.master.system import Connection, FmuSpec, SystemSpec
from drillcosim.plant.scene import Scene, scenes_dir
from drillcosim.plant.signals import (
    AXES,
    CONTACT_QUANTITIES,
    CONTROLLER,
    PLANT,
    actuator_power,
    body_signal,
    fmi_unit,
    ref,
    strain,
)

from .config import ConfigError, SceneConfig, plant_parameter_paths
from .interface import InterfaceWarning, wire_system
from .scene_fmus import (
    built_for_scene,
    controller_recipe,
    embedded_scene_name,
    ensure_recipes,
    plant_recipe,
)

__all__ = ["ENGINES", "BuiltSystem", "build_system", "scene_recipes", "scene_reference"]

#: How the instances run: FMU files, or the same models in process.
ENGINES = ("fmu", "inprocess")


@dataclass(frozen=True)
class BuiltSystem:
    """A configuration ready to run.

    Attributes
    ----------
    config : SceneConfig
    engine : {"fmu", "inprocess"}
    system : SystemSpec
        Instances, connections (with the delays and coupling) and the master's settings.
    slaves : dict of str -> Slave
        Ready-made in-process slaves by instance (``inprocess``; single use: a run closes
        them); empty for ``fmu`` (the execution loads the FMU files).
    outputs : tuple of str
        ``'instance.variable'`` to record: per contact body X, Y, radial deflection and contact
        force; per site the strains and the actuator power; the bit and top-drive scalars;
        the scene's ``outputs``; then the controllers' outputs.
    units : dict of str -> str
        Every output of every instance (what can be recorded) and its unit (``"1"`` for a
        strain, ``""`` if undeclared), as the instances declare them.
    """

    config: SceneConfig
    engine: str
    system: SystemSpec
    slaves: dict[str, Slave]
    outputs: tuple[str, ...]
    units: dict[str, str]

    def components(self) -> dict[str, dict[str, Any]]:
        """What runs each instance (``summary.json``, a sweep's ``sweep.json``): engine
        ``fmu``: the FMU file, its GUID, model name and generation tool, and the parameters
        the system sets on it; ``inprocess``: the plant's scene and model kind, or the law's
        kind and its parameters (as its FMU would get them). Both: the drillcosim version
        that runs it."""
        from drillcosim._version import __version__

        out: dict[str, dict[str, Any]] = {}
        for spec in self.system.fmus:
            rec: dict[str, Any] = {"engine": self.engine}
            if self.engine == "fmu":
                md = read_model_description(str(spec.path), validate=False)
                rec.update({"fmu": str(Path(spec.path).resolve()), "guid": md.guid,
                            "model_name": md.modelName, "generation_tool": md.generationTool,
                            "parameters": dict(spec.parameters)})
            elif spec.name == PLANT:
                rec.update({"scene": self.config.source, "model": self.slaves[PLANT].sim.model.kind})
            else:
                setting = self.config.controllers[spec.name]
                layout = setting.layout(self.config.n_sites)
                rec.update({"law": setting.kind,
                            "parameters": setting.law.encode(setting.params, layout)})
            rec["drillcosim"] = __version__
            out[spec.name] = rec
        return out


def scene_reference(scene: Scene) -> str:
    """Value of the plant FMU's ``scene`` parameter: the name if shipped, else the absolute path."""
    src = Path(scene.source)
    if not src.is_file():
        return scene.name
    shipped = scenes_dir() / f"{src.stem}.toml"
    if shipped.is_file() and shipped.resolve() == src.resolve():
        return src.stem
    return str(src.resolve())


def scene_recipes(config: SceneConfig) -> dict[str, Any]:
    """The project FMUs the system runs where the configuration names no FMU file, by instance:
    ``{"plant": FmuRecipe, "controller": ..., "top_drive_controller": ...}`` (controllers only
    when enabled). Building them ahead: :func:`.scene_fmus.ensure_recipes`."""
    recipes: dict[str, Any] = {PLANT: plant_recipe(config.scene)}
    for instance in config.instances[1:]:
        recipes[instance] = controller_recipe(config.controllers[instance], config.scene,
                                              config.n_sites)
    return recipes


def _recorded(config: SceneConfig, declared: list[str]) -> list[str]:
    """The plant outputs to record, those the plant declares (in this order)."""
    plant = config.scene.plant
    wanted = [body_signal(b, q) for b in plant.contact_bodies for q in CONTACT_QUANTITIES]
    for s in range(1, config.n_sites + 1):
        wanted += [strain(s, a) for a in AXES] + [actuator_power(s)]
    wanted += ["bit_axial_force", "bit_torque", "hook_load", "top_rotary_speed",
               "bit_rotary_speed", "total_energy", *config.scene.outputs]
    if plant.top_drive.mode != "prescribed":
        wanted.append("top_torque")
    have = set(declared)
    out: list[str] = []
    for n in wanted:
        if n in have and n not in out:
            out.append(n)
    return out


def _slave_interface(instance: str, slave: Slave, inputs: list[str], units: Mapping[str, str]
                     ) -> FmuInterface:
    """An in-process slave's variables as the interface check sees an FMU's."""
    ports = {n: Port(n, "input", "Real", fmi_unit(units.get(n, ""))) for n in inputs}
    ports.update({n: Port(n, "output", "Real", fmi_unit(units.get(n, ""))) for n in slave.outputs})
    return FmuInterface(instance, Path(f"<in-process {instance}>"), ports)


def _inprocess_faces(config: SceneConfig, slaves: Mapping[str, Slave]) -> dict[str, FmuInterface]:
    model = slaves[PLANT].sim.model
    faces = {PLANT: _slave_interface(PLANT, slaves[PLANT], list(model.acting_inputs),
                                     {**model.output_units, **model.input_units})}
    for instance in config.instances[1:]:
        setting = config.controllers[instance]
        ports = setting.law.ports(setting.layout(config.n_sites))
        faces[instance] = _slave_interface(instance, slaves[instance], slaves[instance].inputs,
                                           {p.name: p.unit for p in ports})
    return faces


def _plant_fmu_parameters(config: SceneConfig, face: FmuInterface, built_for_scene: bool
                          ) -> dict[str, Any]:
    params: dict[str, Any] = {}
    if "scene" in face.ports:
        # a plant FMU built for this scene carries the scene file: name it as the FMU does, so
        # the system (and an SSP written from it) holds no path of this machine
        params["scene"] = (embedded_scene_name(config.scene) if built_for_scene
                           else scene_reference(config.scene))
    else:
        warnings.warn(InterfaceWarning(
            f"{face.label} has no 'scene' parameter: the plant tables of {config.source} are "
            "not applied to it"), stacklevel=3)
    for path, value in plant_parameter_paths(config.overrides).items():
        if not isinstance(value, (bool, int, float, str)):
            raise ConfigError(f"{config.source}: {path} = {value!r} is not a scalar and cannot "
                              "be passed to the plant FMU; put it in a scene file, or run the "
                              "models in process (engine 'inprocess')")
        params[path] = value
    return params


def _controller_parameters(config: SceneConfig, face: FmuInterface, foreign: bool
                           ) -> tuple[dict[str, Any], list[str]]:
    """The start values an instance's controller FMU gets, and the problems (one line each).

    The project's FMU gets the law's parameters (``Law.encode``). A foreign FMU gets those of
    them it declares (by name), then its own parameters (``[<table>.parameters]``); the law keys
    the scene sets that it does not declare are not required of it (an :class:`InterfaceWarning`
    names the file's; an override of one is a problem: it would change nothing).
    """
    setting = config.controllers[face.instance]
    values = setting.law.encode(setting.params, setting.layout(config.n_sites))
    if not foreign:
        return {k: v for k, v in values.items() if k in face.ports}, []
    params = {k: v for k, v in values.items() if k in face.ports}
    missing = [k for k in setting.set_keys if k not in values or k not in face.ports]
    overridden = [k for k in missing if f"{face.instance}.{k}" in config.overrides]
    problems = [f"override {face.instance}.{k} = {config.overrides[f'{face.instance}.{k}']!r}: "
                f"{face.label} has no parameter '{k}' (its own parameters are set with "
                f"{face.instance}.parameters.NAME)" for k in overridden]
    unused = [k for k in missing if k not in overridden]
    if unused:
        warnings.warn(InterfaceWarning(
            f"{face.label} has no parameter {', '.join(map(repr, unused))}: [{face.instance}] "
            f"{', '.join(unused)} of {config.source} not applied"), stacklevel=4)
    params.update(setting.parameters)
    return params, problems


def _unfit_state_space(config: SceneConfig, faces: Mapping[str, FmuInterface]) -> list[str]:
    """A state-space controller's inputs that are no output of the plant and outputs that are
    no input of it (a linear law fed by nothing, or feeding nothing, is a wrong matrices file;
    the P law's rule for sites one side does not serve does not apply)."""
    setting = config.controllers[CONTROLLER]
    if setting.matrices is None or CONTROLLER not in faces:
        return []
    plant, face = faces[PLANT], faces[CONTROLLER]
    src = f"[controller] matrices {setting.matrices.name}"
    return ([f"{face.label} input '{n}' ({src}) is no output of {plant.label}"
             for n in face.inputs() if n not in plant.outputs()]
            + [f"{face.label} output '{n}' ({src}) is no input of {plant.label}"
               for n in face.outputs() if n not in plant.inputs()])


def build_system(config: SceneConfig, engine: str = "fmu", *,
                 fmu_dir: str | Path | None = None) -> BuiltSystem:
    """Build the co-simulation system of a configuration and check it.

    Parameters
    ----------
    config : SceneConfig
        From :func:`.config.load_config`.
    engine : {"fmu", "inprocess"}
        FMU files, or the same models in process (module docstring).
    fmu_dir : path-like, optional
        Folder of the project's FMUs (``fmu`` engine; default ``build/fmus/``); missing or stale
        ones are built there (the default ones, or those built for the scene's layout).

    Returns
    -------
    BuiltSystem

    Raises
    ------
    ConfigError
        A bad engine, or a plant override a plant FMU cannot take (one line).
    cosim.master.interface.InterfaceError
        The instances do not fit (one line per problem, each naming both and the variable).
    FileNotFoundError
        A project FMU is missing and cannot be built.

    Warns
    -----
    InterfaceWarning
        Plant inputs no controller feeds (they keep their start value), or a plant FMU without
        a ``scene`` parameter.
    """
    if engine not in ENGINES:
        raise ConfigError(f"engine = {engine!r} is not allowed; allowed: {', '.join(ENGINES)}")
    instances = config.instances
    controllers = instances[1:]
    cosim = config.cosim
    if engine == "inprocess":
        from .inprocess import inprocess_slaves  # the FMU engine's start-up does not need it

        slaves = inprocess_slaves(config)
        faces = _inprocess_faces(config, slaves)
        params: dict[str, dict[str, Any]] = {i: {} for i in instances}
        problems: list[str] = []
    else:
        slaves = {}
        recipes = scene_recipes(config)
        need = [recipes[i] for i in instances if i not in config.fmu_files]
        built = ensure_recipes(need, fmu_dir) if need else {}
        paths = {i: config.fmu_files.get(i) or built[recipes[i].name] for i in instances}
        faces = {i: read_interface(i, paths[i]) for i in instances}
        for_scene = PLANT not in config.fmu_files and built_for_scene(recipes[PLANT])
        params = {PLANT: {**_plant_fmu_parameters(config, faces[PLANT], for_scene),
                          **config.plant_parameters}}
        problems = []
        for i in controllers:
            params[i], found = _controller_parameters(config, faces[i], i in config.fmu_files)
            problems += found
    problems += _unfit_state_space(config, faces)
    fmus = [FmuSpec(PLANT, faces[PLANT].path, params[PLANT])]
    fmus += [FmuSpec(i, faces[i].path, params[i], cosim.controller_ticks) for i in controllers]
    wiring = wire_system(faces[PLANT], [faces[i] for i in controllers], fmus, problems)
    # what the plant receives (forces, torque) is delayed by actuator_delay, what the
    # controllers receive (strains, speeds) by sensor_delay
    delay = {PLANT: cosim.actuator_delay, **dict.fromkeys(controllers, cosim.sensor_delay)}
    receiver = {ref(i, n): i for i in instances for n in faces[i].inputs()}
    connections = [Connection(s, t, delay[receiver[t]], cosim.coupling)
                   for s, t in wiring.connections]
    recorded = [(PLANT, n) for n in _recorded(config, faces[PLANT].outputs())]
    fed_by = {ref(i, n): (i, n) for i in controllers for n in faces[i].outputs()}
    recorded += [fed_by[s] for s, _t in wiring.connections if s in fed_by]
    outputs = tuple(ref(i, n) for i, n in recorded)
    units = {ref(i, n): faces[i].ports[n].unit or "" for i in instances
             for n in faces[i].outputs()}
    order = tuple(i for i in cosim.order if i in instances) if controllers else (PLANT,)
    system = SystemSpec(fmus, connections, cosim.step, cosim.algorithm, order, 0.0,
                        cosim.stop_time)
    return BuiltSystem(config, engine, system, slaves, outputs, units)
