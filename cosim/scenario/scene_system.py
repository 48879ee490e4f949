"""Scene -> co-simulation system: the plant FMU, the controller FMU and their wiring.

:func:`scene_system` turns a :class:`plant.scene.Scene` into a
:class:`cosim.master.system.SystemSpec` with up to three FMU instances: ``plant`` (the plant
FMU), ``controller`` (the strain controller, when ``[controller] enabled``) and
``top_drive_controller`` (the top-drive speed controller, when ``[top_drive_controller]
enabled``), connected by name both ways:

* sensors: ``plant.strain<s>_<C|E>`` -> ``controller.strain<s>_<C|E>``,
  ``plant.top_rotary_speed`` / ``plant.top_torque`` -> ``top_drive_controller.*`` (delay
  ``sensor_delay``),
* actuators: ``controller.actuator<s>_force_<C|E>`` -> ``plant.actuator<s>_force_<C|E>``,
  ``top_drive_controller.top_drive_torque`` -> ``plant.top_drive_torque`` (delay
  ``actuator_delay``),

for every input of one FMU that another declares (:mod:`cosim.scenario.interface`: the
system is checked before the first step, every problem in one line; inputs of sites no
controller serves keep their start value, with a warning). Without a controller the plant
runs alone (its inputs stay at their start value 0).

Which FMUs: the project's, taken from ``build/fmus/`` (or the folder given) and built there
if missing or older than their sources: the default ``DrillstringPlant.fmu`` and
``StrainController.fmu`` when they fit the scene, else FMUs built for the scene's layout
(``DrillstringPlant_<scene>``, ``StrainController_<scene>``; :mod:`.scene_fmus`), and
``TopDriveController.fmu``. Other FMU files (any maker) are used as they are when given:
``[plant] fmu = "path"`` / ``[controller] fmu = "path"`` / ``[top_drive_controller] fmu =
"path"`` in the scene (relative to the scene file's folder), or the ``plant_fmu`` /
``controller_fmu`` arguments (``drillcosim run --plant-fmu P --controller-fmu C``), which take
precedence.

Parameters passed to the FMUs
-----------------------------
plant
    ``scene`` (String): the scene name when the scene file is a shipped one
    (``scenes/<name>.toml``), else its absolute path (passed only if the plant FMU declares
    ``scene``; otherwise a warning says the scene's plant tables are not applied); plus any
    plant parameter given in ``plant_overrides`` as a flattened ``section.key`` (scalar
    values only, e.g. ``top_drive.rotary_speed``; the FMU must declare each).
controller
    ``[controller]`` of the scene, validated by
    :class:`controller.ControllerParams`: ``gain`` [N per unit strain],
    ``mode`` (``"unrestricted"`` -> Integer 0, ``"compressive_only"`` -> 1),
    ``force_limit`` [N], ``symmetric_force_limit`` [N] (``inf`` is passed as
    1e30, the FMU's "no limit"), ``switch_on_time`` [s],
    ``lag_time_constant`` [s], ``enabled`` (Boolean), and ``gain_matrix`` as the relative
    gains ``gain_matrix_<i>_<j>`` (identity when not given). Each is passed if the
    controller FMU declares it; a key the scene sets explicitly that the FMU lacks is an
    interface problem, a default it lacks is not passed.
top_drive_controller
    ``[top_drive_controller]``, validated by :class:`controller.TopDriveControllerParams`:
    ``target_speed`` [rad/s], ``p_gain`` [N m s/rad], ``i_gain`` [N m/rad],
    ``torque_feedback`` [1], ``ramp_time`` [s], ``enabled``; passed the same way. The plant
    must be in ``top_drive.mode = "torque"``.

The ``[cosim]`` table of a scene
--------------------------------
Every key is optional::

    [cosim]
    step = 1e-3                    # base communication step H [s], > 0 (default 1e-3)
    stop_time = 30.0               # default stop time [s], > 0 (default 30)
    algorithm = "jacobi"           # "jacobi" | "gauss_seidel" (default "jacobi")
    order = ["plant", "controller"]  # Gauss-Seidel stepping order (default plant first; with a
                                   # top-drive controller also "top_drive_controller")
    coupling = "zoh"               # "zoh" | "linear" on all connections (default "zoh")
    actuator_delay = 0.0           # transport delay controller -> plant forces [s], >= 0
    sensor_delay = 0.0             # transport delay plant -> controller strains [s], >= 0
    controller_sample_period = 1e-3  # controllers' period [s], integer multiple of step
                                   # (default: step); the plant steps every base step
    output_interval = 1e-3         # recording interval [s], integer multiple of step
                                   # (default: the smallest multiple of step >= 1 ms)

Notes on timing: with Jacobi and zero delays the controller's force over
``[t_k, t_k+1]`` is computed from strains sampled at ``t_k`` and reaches the
plant at ``t_k+1``: the loop has one communication step of inherent delay (see
:mod:`cosim.master.algorithms`); ``gauss_seidel`` with the plant first removes the
delay on the sensor side. Delays act on the samples of the source FMU (see
:mod:`cosim.master.delays`; fractional multiples of the source period are
interpolated linearly).

Every error is a one-line ``ValueError`` naming the scene file and the key,
with a "did you mean" suggestion for unknown keys.
"""

from __future__ import annotations

import dataclasses
import difflib
import math
import warnings
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, fields
from pathlib import Path
from typing import Any

from drillcosim.controller import MODES, ControllerParams, TopDriveControllerParams
from drillcosim.cosim.master.interface import (
    FmuInterface,
    read_interface,
)
from drillcosim.cosim.master.system import (
    ALGORITHMS,
    COUPLINGS,
    FmuSpec,
    SystemSpec,
    integer_multiple,
)
from drillcosim.plant.observables import output_names
from drillcosim.plant.scene import Scene, scenes_dir

from .instances import CONTROLLER, PLANT, TOP_DRIVE
from .interface import InterfaceWarning, connections_of, wire_system
from .scene_fmus import (
    TOP_DRIVE_CONTROLLER,
    controller_recipe,
    default_fmu_dir,
    embedded_scene_name,
    ensure_recipes,
    plant_recipe,
    recipe_named,
)

__all__ = [
    "CONTROLLER",
    "COSIM_KEYS",
    "PLANT",
    "TOP_DRIVE",
    "CosimSettings",
    "SceneSystem",
    "controller_parameters",
    "cosim_schema_markdown",
    "cosim_settings",
    "default_fmu_dir",
    "ensure_fmus",
    "scene_controller",
    "scene_instances",
    "scene_system",
    "scene_top_drive_controller",
    "span_info",
    "top_drive_controller_parameters",
]

AXES = ("C", "E")
NO_LIMIT = 1e30            #: the controller FMU's "no symmetric force limit"

#: ``[cosim]`` keys: (default, unit, meaning). ``None`` defaults are derived.
COSIM_KEYS: dict[str, tuple[Any, str, str]] = {
    "step": (1e-3, "s", "base communication step H, > 0"),
    "stop_time": (30.0, "s", "default stop time, > 0"),
    "algorithm": ("jacobi", "-", "'jacobi' (parallel) or 'gauss_seidel' (sequential)"),
    "order": (None, "-", "Gauss-Seidel stepping order, a permutation of "
              "['plant', 'controller'] (and 'top_drive_controller' when enabled; default "
              "plant first)"),
    "coupling": ("zoh", "-", "'zoh' (hold) or 'linear' (extrapolation) on every connection"),
    "actuator_delay": (0.0, "s", "transport delay of the forces controller -> plant, >= 0"),
    "sensor_delay": (0.0, "s", "transport delay of the strains plant -> controller, >= 0"),
    "controller_sample_period": (None, "s", "the controllers' step, an integer multiple of "
                                 "step (default: step)"),
    "output_interval": (None, "s", "recording interval, an integer multiple of step "
                        "(default: the smallest multiple of step >= 1 ms)"),
}


def _suggest(word: str, choices: Sequence[str]) -> str:
    close = difflib.get_close_matches(word, list(choices), n=1)
    return f" (did you mean '{close[0]}'?)" if close else f"; allowed: {', '.join(choices)}"


@dataclass(frozen=True)
class CosimSettings:
    """Validated ``[cosim]`` table of a scene (times in seconds; periods of the controller and of
    the recording in base steps, ``*_ticks``)."""

    step: float
    stop_time: float
    algorithm: str
    order: tuple[str, ...]
    coupling: str
    actuator_delay: float
    sensor_delay: float
    controller_sample_ticks: int
    output_ticks: int

    @property
    def output_interval(self) -> float:
        """Recording interval [s] (``output_ticks`` base steps)."""
        return self.output_ticks * self.step


@dataclass(frozen=True)
class SceneSystem:
    """A scene ready to run.

    Attributes
    ----------
    scene : Scene
    system : SystemSpec
    settings : CosimSettings
    outputs : tuple of str
        ``'fmu.var'`` variables to record (plant outputs, then controller forces).
    """

    scene: Scene
    system: SystemSpec
    settings: CosimSettings
    outputs: tuple[str, ...]

    @property
    def stop_time(self) -> float:
        """Default stop time [s]."""
        return self.settings.stop_time

    @property
    def output_interval(self) -> float:
        """Recording interval [s]."""
        return self.settings.output_interval


def _number(scene: Scene, key: str, value: Any, *, positive: bool) -> float:
    where = f"{scene.source}: [cosim] {key}"
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise ValueError(f"{where} = {value!r} must be a finite number [s]")
    if (value <= 0) if positive else (value < 0):
        raise ValueError(f"{where} = {value!r} must be {'> 0' if positive else '>= 0'} [s]")
    return float(value)


def _multiple(scene: Scene, key: str, period: float, step: float) -> int:
    n = integer_multiple(period, step)
    if n is None:
        raise ValueError(f"{scene.source}: [cosim] {key} = {period!r} must be a positive "
                         f"integer multiple of step = {step!r} s")
    return n


def cosim_settings(scene: Scene) -> CosimSettings:
    """Validate the scene's ``[cosim]`` table (schema: module docstring).

    Raises
    ------
    ValueError
        One line naming the scene file and the key.
    """
    table = scene.cosim
    for key in table:
        if key not in COSIM_KEYS:
            raise ValueError(f"{scene.source}: [cosim] unknown key '{key}'"
                             f"{_suggest(key, list(COSIM_KEYS))}")
    get = table.get
    step = _number(scene, "step", get("step", COSIM_KEYS["step"][0]), positive=True)
    stop = _number(scene, "stop_time", get("stop_time", COSIM_KEYS["stop_time"][0]),
                   positive=True)
    for key, choices in (("algorithm", ALGORITHMS), ("coupling", COUPLINGS)):
        value = get(key, COSIM_KEYS[key][0])
        if value not in choices:
            raise ValueError(f"{scene.source}: [cosim] {key} = {value!r} is not allowed"
                             f"{_suggest(str(value), choices)}")
    names = [PLANT, CONTROLLER] + ([TOP_DRIVE] if TOP_DRIVE in scene_instances(scene) else [])
    order = get("order", names)
    if not isinstance(order, (list, tuple)) or sorted(order) != sorted(names):
        raise ValueError(f"{scene.source}: [cosim] order = {order!r} must be a permutation of "
                         f"{names}")
    delays = {k: _number(scene, k, get(k, 0.0), positive=False)
              for k in ("actuator_delay", "sensor_delay")}
    ctrl_period = _number(scene, "controller_sample_period",
                          get("controller_sample_period", step), positive=True)
    ticks = _multiple(scene, "controller_sample_period", ctrl_period, step)
    if "output_interval" in table:
        interval = _number(scene, "output_interval", table["output_interval"], positive=True)
        out_ticks = _multiple(scene, "output_interval", interval, step)
    else:
        out_ticks = max(1, math.ceil(1e-3 / step - 1e-9))
    return CosimSettings(step, stop, get("algorithm", "jacobi"), tuple(order),
                         get("coupling", "zoh"), delays["actuator_delay"],
                         delays["sensor_delay"], ticks, out_ticks)


def scene_controller(scene: Scene) -> ControllerParams:
    """The scene's ``[controller]`` table as validated, typed parameters.

    Raises
    ------
    ValueError
        Unknown key (with suggestion) or invalid value, naming the scene file.
    """
    names = [f.name for f in fields(ControllerParams)]
    for key in scene.controller:
        if key not in names and key != "fmu":
            raise ValueError(f"{scene.source}: [controller] unknown key '{key}'"
                             f"{_suggest(key, [*names, 'fmu'])}")
    raw = {"enabled": False, **{k: v for k, v in scene.controller.items() if k != "fmu"}}
    try:
        params = ControllerParams(**raw)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{scene.source}: [controller] {exc}") from None
    n_sites = len(scene.plant.actuator_joints)
    if params.gain_matrix and len(params.gain_matrix) != n_sites:
        size = len(params.gain_matrix)
        raise ValueError(f"{scene.source}: [controller] gain_matrix is {size} x {size}; the "
                         f"scene has {n_sites} actuator sites: allowed an {n_sites} x {n_sites} "
                         "matrix")
    return params


def scene_instances(scene: Scene) -> list[str]:
    """The FMU instances of the scene's system: the plant, then each enabled controller."""
    out = [PLANT]
    for name, table in ((CONTROLLER, scene.controller), (TOP_DRIVE, scene.top_drive_controller)):
        if table.get("enabled", False) is True:
            out.append(name)
    return out


def scene_top_drive_controller(scene: Scene) -> TopDriveControllerParams:
    """The scene's ``[top_drive_controller]`` table as validated, typed parameters
    (``enabled`` false when the scene does not enable it).

    Raises
    ------
    ValueError
        Unknown key (with suggestion), invalid value, or an enabled controller with a plant
        whose top drive is not in mode "torque", naming the scene file.
    """
    table = scene.top_drive_controller
    names = [f.name for f in fields(TopDriveControllerParams)]
    for key in table:
        if key not in names and key != "fmu":
            raise ValueError(f"{scene.source}: [top_drive_controller] unknown key '{key}'"
                             f"{_suggest(key, [*names, 'fmu'])}")
    raw = {"enabled": False, **{k: v for k, v in table.items() if k != "fmu"}}
    try:
        params = TopDriveControllerParams(**raw)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{scene.source}: [top_drive_controller] {exc}") from None
    mode = scene.plant.top_drive.mode
    if params.enabled and mode != "torque":
        raise ValueError(f"{scene.source}: [top_drive_controller] drives the motor torque of a "
                         f"top drive in mode 'torque', but top_drive.mode = {mode!r}: set "
                         "[top_drive] mode = \"torque\" and inertia")
    return params


def top_drive_controller_parameters(scene: Scene) -> dict[str, float | bool]:
    """The top-drive controller FMU's parameters for the scene (:func:`scene_top_drive_controller`).

    Raises
    ------
    ValueError
        As :func:`scene_top_drive_controller`.
    """
    return dataclasses.asdict(scene_top_drive_controller(scene))


def controller_parameters(scene: Scene) -> dict[str, float | int | bool]:
    """The controller FMU's parameters for the scene: :func:`scene_controller` encoded for the
    FMU (the one place that encoding happens).

    Returns
    -------
    dict
        ``gain`` [N], ``mode`` (Integer: index in :data:`controller.MODES`),
        ``force_limit`` [N], ``symmetric_force_limit`` [N] (inf -> 1e30),
        ``switch_on_time`` [s], ``lag_time_constant`` [s], ``enabled``, and the relative
        gains ``gain_matrix_<i>_<j>`` [1] (the identity when the scene gives no matrix).

    Raises
    ------
    ValueError
        Unknown key (with suggestion) or invalid value, naming the scene file.
    """
    p = scene_controller(scene)
    sym = p.symmetric_force_limit
    out: dict[str, float | int | bool] = {
        "gain": p.gain, "mode": MODES.index(p.mode), "force_limit": p.force_limit,
        "symmetric_force_limit": NO_LIMIT if math.isinf(sym) else sym,
        "switch_on_time": p.switch_on_time, "lag_time_constant": p.lag_time_constant,
        "enabled": p.enabled}
    n = len(scene.plant.actuator_joints)
    matrix = p.gain_matrix or tuple(tuple(float(i == j) for j in range(n)) for i in range(n))
    for i, row in enumerate(matrix, start=1):
        for j, value in enumerate(row, start=1):
            out[f"gain_matrix_{i}_{j}"] = value
    return out


def _flatten(overrides: Mapping[str, Any], source: str) -> dict[str, float | int | bool | str]:
    flat: dict[str, float | int | bool | str] = {}
    for section, table in overrides.items():
        if section in ("controller", "cosim", "description", "extends", "outputs"):
            continue
        if not isinstance(table, Mapping):
            if isinstance(table, (bool, int, float, str)):
                flat[section] = table
                continue
            raise ValueError(f"{source}: '{section}' cannot be passed to the plant FMU as a "
                             "parameter; put it in a scene file")
        for key, value in table.items():
            if not isinstance(value, (bool, int, float, str)):
                raise ValueError(f"{source}: {section}.{key} = {value!r} is not a scalar and "
                                 "cannot be passed to the plant FMU; put it in a scene file")
            flat[f"{section}.{key}"] = value
    return flat


def scene_reference(scene: Scene) -> str:
    """Value of the plant's ``scene`` parameter: the name if shipped, else the absolute path."""
    src = Path(scene.source)
    if not src.is_file():
        return scene.name
    shipped = scenes_dir() / f"{src.stem}.toml"
    if shipped.is_file() and shipped.resolve() == src.resolve():
        return src.stem
    return str(src.resolve())


def span_info(scene: Scene) -> dict[int, dict[str, float | str]]:
    """Per contact body: its span's length [m] and 'long'/'short'.

    Returns
    -------
    dict
        ``{body: {"span_length": L_span [m], "span": "long" | "short" | "only"}}``.
    """
    plant = scene.plant
    dx = plant.pipe.segment_length
    spans = plant.spans()
    out: dict[int, dict[str, float | str]] = {}
    lengths = [b - a for a, b in spans]
    for body in plant.contact_bodies:
        z = (body - 0.5) * dx
        length = next((b - a for a, b in spans if a <= z <= b), float("nan"))
        if len(set(round(x, 9) for x in lengths)) < 2 or math.isnan(length):
            kind = "only"
        else:
            kind = "long" if length >= max(lengths) - 1e-9 else "short"
        out[body] = {"span_length": length, "span": kind}
    return out


def ensure_fmus(fmu_dir: str | Path | None = None, names: Sequence[str] = (
        "DrillstringPlant", "StrainController")) -> dict[str, Path]:
    """Paths of the registered project FMUs ``names`` in ``fmu_dir``, building missing (or
    stale) ones (:func:`.scene_fmus.ensure_recipes`).

    Raises
    ------
    FileNotFoundError
        If an FMU is still missing after the build (e.g. no adapter yet).
    """
    return ensure_recipes([recipe_named(n) for n in names], fmu_dir)


def _plant_outputs(scene: Scene, declared: Sequence[str]) -> list[str]:
    """The scene's plant outputs to record, those the plant FMU declares (in this order)."""
    plant = scene.plant
    names = [r[0] for r in output_names(scene.model == "full3d", list(plant.contact_bodies),
                                        len(plant.actuator_joints), extended=True)]
    wanted = []
    for b in plant.contact_bodies:
        wanted += [f"body{b}_{q}" for q in ("X", "Y", "radial_deflection", "contact_force")]
    for s in range(1, len(plant.actuator_joints) + 1):
        wanted += [f"strain{s}_{a}" for a in AXES] + [f"actuator{s}_power"]
    wanted += ["bit_axial_force", "bit_torque", "hook_load", "top_rotary_speed",
               "bit_rotary_speed", "total_energy", *scene.outputs]
    if plant.top_drive.mode != "prescribed":
        wanted.append("top_torque")
    out = []
    for n in wanted:
        if n in names and n in declared and n not in out:
            out.append(n)
    return out


#: Scene table of each controller instance.
_TABLES = {CONTROLLER: "controller", TOP_DRIVE: "top_drive_controller"}


def _scene_fmu(scene: Scene, table: str, given: str | Path | None) -> Path | None:
    """An FMU file chosen by argument, else by the scene's ``[<table>] fmu`` (None: default).

    A relative path in the scene is resolved against the scene file's folder.
    """
    if given:
        return Path(given)
    raw = {"plant": scene.plant_fmu, "controller": scene.controller,
           "top_drive_controller": scene.top_drive_controller}[table]
    if table == "plant":
        for key in raw:
            if key != "fmu":
                raise ValueError(f"{scene.source}: [plant] unknown key '{key}'; allowed: fmu "
                                 "(the plant's own parameters are top-level tables)")
    if "fmu" not in raw:
        return None
    value = raw["fmu"]
    if not isinstance(value, str) or not value:
        raise ValueError(f"{scene.source}: [{table}] fmu = {value!r} must be the path of an "
                         ".fmu file")
    path = Path(value).expanduser()
    src = Path(scene.source)
    if not path.is_absolute() and src.is_file():
        path = src.resolve().parent / path
    if not path.is_file():
        raise FileNotFoundError(f"{scene.source}: [{table}] fmu = {value!r}: no file '{path}'")
    return path


def scene_recipes(scene: Scene) -> dict[str, Any]:
    """The project FMUs the scene's system uses where it names no FMU file, by instance:
    ``{"plant": FmuRecipe, "controller": ..., "top_drive_controller": ...}`` (controllers only
    when enabled). Building them ahead: :func:`.scene_fmus.ensure_recipes`.

    Raises
    ------
    ValueError
        Invalid ``[controller]`` / ``[top_drive_controller]`` tables (one line).
    """
    ctrl = scene_controller(scene)
    recipes: dict[str, Any] = {PLANT: plant_recipe(scene)}
    if ctrl.enabled:
        recipes[CONTROLLER] = controller_recipe(scene, len(scene.plant.actuator_joints),
                                                ctrl.gain_matrix)
    if scene_top_drive_controller(scene).enabled:
        recipes[TOP_DRIVE] = recipe_named(TOP_DRIVE_CONTROLLER)
    return recipes


def scene_system(scene: Scene, fmu_dir: str | Path | None = None, *,
                 plant_fmu: str | Path | None = None,
                 controller_fmu: str | Path | None = None,
                 plant_overrides: Mapping[str, Any] | None = None) -> SceneSystem:
    """Build the co-simulation system of a scene and check its FMUs.

    Parameters
    ----------
    scene : Scene
    fmu_dir : path-like, optional
        Folder of the project's FMUs (default ``build/fmus/``); missing or stale FMUs are built
        there (the default ones, or those built for the scene's layout, :mod:`.scene_fmus`).
    plant_fmu, controller_fmu : path-like, optional
        Use these FMU files instead (nothing is built for them); they take precedence over
        ``[plant] fmu`` / ``[controller] fmu`` of the scene.
    plant_overrides : mapping, optional
        Plant parameters overridden on top of the scene file (the nested dict
        given to :func:`plant.scene.load_scene`); passed to the plant FMU as
        flattened ``section.key`` parameters (scalars only).

    Returns
    -------
    SceneSystem

    Raises
    ------
    ValueError
        Invalid ``[cosim]``, ``[controller]``, ``[top_drive_controller]`` or ``[plant]`` keys or
        values (one line, naming the scene file and the key).
    cosim.master.interface.InterfaceError
        The FMUs do not fit (a ``ValueError``; one line per problem, each naming both FMUs and
        the variable).
    FileNotFoundError
        An FMU is missing and cannot be built.

    Warns
    -----
    InterfaceWarning
        Plant inputs no controller feeds (they keep their start value), or a plant FMU without
        a ``scene`` parameter.
    """
    settings = cosim_settings(scene)
    params = {CONTROLLER: controller_parameters(scene),
              TOP_DRIVE: top_drive_controller_parameters(scene)}
    enabled = [name for name in (CONTROLLER, TOP_DRIVE) if params[name]["enabled"]]
    if controller_fmu and CONTROLLER not in enabled:
        raise ValueError(f"{scene.source}: a controller FMU was given ({controller_fmu}) but "
                         "the scene's controller is off: set controller.enabled=true")
    files = {PLANT: _scene_fmu(scene, "plant", plant_fmu),
             CONTROLLER: _scene_fmu(scene, "controller", controller_fmu)
             if CONTROLLER in enabled else None,
             TOP_DRIVE: _scene_fmu(scene, "top_drive_controller", None)
             if TOP_DRIVE in enabled else None}
    if CONTROLLER in enabled and scene.model != "full3d":
        raise ValueError(f"{scene.source}: the controller needs model = 'full3d', "
                         f"got '{scene.model}'")
    overrides = _flatten(plant_overrides or {}, scene.source)
    recipes = scene_recipes(scene)
    need = [recipes[i] for i in (PLANT, *enabled) if files[i] is None]
    built = ensure_recipes(need, fmu_dir) if need else {}
    path = {i: files[i] or built[recipes[i].name] for i in (PLANT, *enabled)}
    plant_face = read_interface(PLANT, path[PLANT])
    plant_params: dict[str, float | int | bool | str] = {}
    if "scene" in plant_face.ports:
        # a plant FMU built for this scene carries the scene file: name it as the FMU does, so
        # the system (and an SSP written from it) holds no path of this machine
        built_for_scene = files[PLANT] is None and bool(recipes[PLANT].base)
        plant_params["scene"] = (embedded_scene_name(scene) if built_for_scene
                                 else scene_reference(scene))
    else:
        warnings.warn(InterfaceWarning(
            f"{plant_face.label} has no 'scene' parameter: the plant tables of "
            f"{scene.source} are not applied to it"), stacklevel=2)
    plant_params.update(overrides)
    fmus = [FmuSpec(PLANT, plant_face.path, plant_params)]
    faces = [read_interface(i, path[i]) for i in enabled]
    for face in faces:
        fmus.append(FmuSpec(face.instance, face.path,
                            {k: v for k, v in params[face.instance].items() if k in face.ports},
                            settings.controller_sample_ticks))
    wiring = wire_system(plant_face, faces, fmus,
                         [p for face in faces for p in _lacking(scene, face)])
    delays = {PLANT: settings.actuator_delay, **dict.fromkeys(enabled, settings.sensor_delay)}
    connections = connections_of(wiring, delays, settings.coupling)
    outputs = [f"{PLANT}.{n}" for n in _plant_outputs(scene, plant_face.outputs())]
    outputs += [s for s, _t in wiring.connections if not s.startswith(f"{PLANT}.")]
    order = tuple(i for i in settings.order if i in (PLANT, *enabled)) if enabled else (PLANT,)
    system = SystemSpec(fmus, connections, settings.step, settings.algorithm, order,
                        0.0, settings.stop_time)
    return SceneSystem(scene, system, settings, tuple(outputs))


def _lacking(scene: Scene, face: FmuInterface) -> list[str]:
    """Keys of the instance's scene table the scene sets explicitly that the FMU does not
    declare (``gain_matrix``: its entries ``gain_matrix_1_1`` ...)."""
    table = _TABLES[face.instance]
    raw = scene.controller if face.instance == CONTROLLER else scene.top_drive_controller
    port = {"gain_matrix": "gain_matrix_1_1"}
    return [f"{face.label} has no parameter '{key}' for [{table}] {key} of "
            f"{scene.source}" for key in raw
            if key not in ("enabled", "fmu") and port.get(key, key) not in face.ports]


def _default_text(name: str, d: Any) -> str:
    """A default value as the schema tables show it."""
    if name == "gain_matrix":
        return str(d)
    return ("inf" if isinstance(d, float) and math.isinf(d) else
            str(d).lower() if isinstance(d, bool) else f'"{d}"' if isinstance(d, str)
            else f"{d:g}")


def cosim_schema_markdown() -> str:
    """The ``[plant]``, ``[controller]``, ``[top_drive_controller]`` and ``[cosim]`` tables as
    markdown (for ``docs/scenes.md``).

    Meant to replace the placeholder section "## [controller] and [cosim]" written
    by :func:`plant.scene.schema_markdown`.
    """
    lines = ["## [plant]", "",
             "Which plant FMU runs the scene (`cosim.scenario.scene_system`).", "",
             "| key | default | unit | meaning |", "|---|---|---|---|",
             "| fmu | - | - | path of a plant FMU (any maker; relative to the scene file's "
             "folder) instead of the built DrillstringPlant.fmu; `drillcosim run --plant-fmu` "
             "overrides it |", "",
             "## [controller]", "",
             "Strain P-feedback controller (`controller.ControllerParams`; passed to "
             "StrainController.fmu).", "",
             "| key | default | unit | meaning |", "|---|---|---|---|"]
    ctrl_units = {"gain": "N", "mode": "-", "force_limit": "N", "symmetric_force_limit": "N",
                  "switch_on_time": "s", "lag_time_constant": "s", "enabled": "-",
                  "gain_matrix": "1"}
    ctrl_text = {
        "gain": "force per unit strain, >= 0 (paper: 1e9)",
        "mode": "'unrestricted' (push and pull) or 'compressive_only' (push only)",
        "force_limit": "peak push force in compressive_only mode",
        "symmetric_force_limit": "limit on abs(force) in unrestricted mode (inf = none)",
        "switch_on_time": "controller output is zero before this time",
        "lag_time_constant": "first-order actuator lag; 0 = none",
        "enabled": "false = open loop (the plant runs alone)",
        "gain_matrix": "relative gains M (n_sites x n_sites, row i = force of site i from the "
                       "strain of site j), the same for both axes: F_axis = gain * M @ "
                       "strain_axis (MIMO across the sites); [] or the identity = one P law "
                       "per channel. A scene with another number of sites than 2 or a matrix "
                       "runs StrainController_<scene>.fmu (`drillcosim build --scene`)",
        "fmu": "path of a controller FMU (any maker; relative to the scene file's folder) "
               "instead of the built StrainController.fmu; `drillcosim run --controller-fmu` "
               "overrides it",
    }
    defaults: dict[str, Any] = {f.name: f.default for f in fields(ControllerParams)}
    defaults["enabled"] = False
    defaults["gain_matrix"] = "[]"
    ctrl_units["fmu"] = "-"
    for name in ctrl_units:
        if name == "fmu":
            lines.append(f"| fmu | - | - | {ctrl_text['fmu']} |")
            continue
        lines.append(f"| {name} | {_default_text(name, defaults[name])} | {ctrl_units[name]} | "
                     f"{ctrl_text[name]} |")
    lines += ["", "The plant and controller FMUs connect by name; before the first step the pair "
              "is checked (causality, type, unit, nothing connected twice, start values), "
              "every problem in one line naming both FMUs and the variable (exit code 2). "
              "Plant inputs of sites the controller does not serve keep their start value, "
              "with a warning naming them ([interop.md](interop.md)).", "",
              "## [top_drive_controller]", "",
              "Top-drive speed controller (`controller.TopDriveControllerParams`; passed to "
              "TopDriveController.fmu): motor torque T_m = p_gain e + i_gain integral(e) + "
              "torque_feedback top_torque, e = speed reference - top_rotary_speed. Needs "
              "`[top_drive] mode = \"torque\"` (docs/physics.md section 6).", "",
              "| key | default | unit | meaning |", "|---|---|---|---|"]
    td_text = {"target_speed": ("rad/s", "target rotary speed of the drive, abs <= 1e3"),
               "p_gain": ("N m s/rad", "proportional gain P, >= 0"),
               "i_gain": ("N m/rad", "integral gain I, >= 0"),
               "torque_feedback": ("1", "top-torque feedback gain k_T, -10 <= k_T < 1 "
                                        "(0 = plain PI)"),
               "ramp_time": ("s", "the speed reference ramps from 0 over this time, >= 0"),
               "enabled": ("-", "false = no top-drive controller"),
               "fmu": ("-", "path of a top-drive controller FMU (any maker) instead of the "
                            "built TopDriveController.fmu")}
    td_defaults: dict[str, Any] = {f.name: f.default for f in fields(TopDriveControllerParams)}
    td_defaults["enabled"] = False
    for name, (unit, text) in td_text.items():
        ds = "-" if name == "fmu" else _default_text(name, td_defaults[name])
        lines.append(f"| {name} | {ds} | {unit} | {text} |")
    lines += ["", "## [cosim]", "",
              "Co-simulation settings (`cosim.scenario.scene_system.cosim_settings`).", "",
              "| key | default | unit | meaning |", "|---|---|---|---|"]
    for key, (default, unit, text) in COSIM_KEYS.items():
        ds = "-" if default is None else (f'"{default}"' if isinstance(default, str)
                                          else f"{default:g}")
        lines.append(f"| {key} | {ds} | {unit} | {text} |")
    lines.append("")
    return "\n".join(lines)
