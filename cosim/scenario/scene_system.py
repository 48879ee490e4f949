"""Scene -> co-simulation system: the plant FMU, the controller FMU and their wiring.

:func:`scene_system` turns a :class:`plant.scene.Scene` into a
:class:`cosim.master.system.SystemSpec` with two FMU instances, ``plant``
(``DrillstringPlant.fmu``) and ``controller`` (``StrainController.fmu``), connected
by name both ways:

* sensors: ``plant.strain<s>_<C|E>`` -> ``controller.strain<s>_<C|E>`` (delay
  ``sensor_delay``),
* actuators: ``controller.actuator<s>_force_<C|E>`` ->
  ``plant.actuator<s>_force_<C|E>`` (delay ``actuator_delay``),

for every input of one FMU that the other declares (:mod:`cosim.scenario.interface`: the
pair is checked before the first step, every problem in one line; inputs of sites the
controller does not serve keep their start value, with a warning). When
``[controller] enabled`` is false the plant runs alone (its actuator inputs stay at their
start value 0).

The FMUs are taken from ``build/fmus/`` (or the folder given) and built there
with :func:`fmu_src.build.build_all` if missing or older than their sources. Other FMU
files (any maker) are used as they are when given: ``[plant] fmu = "path"`` /
``[controller] fmu = "path"`` in the scene (relative to the scene file's folder), or the
``plant_fmu`` / ``controller_fmu`` arguments (``drillcosim run --plant-fmu P
--controller-fmu C``), which take precedence.

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
    ``lag_time_constant`` [s], ``enabled`` (Boolean). Each is passed if the controller FMU
    declares it; a key the scene sets explicitly that the FMU lacks is an interface problem,
    a default it lacks is not passed.

The ``[cosim]`` table of a scene
--------------------------------
Every key is optional::

    [cosim]
    step = 1e-3                    # base communication step H [s], > 0 (default 1e-3)
    stop_time = 30.0               # default stop time [s], > 0 (default 30)
    algorithm = "jacobi"           # "jacobi" | "gauss_seidel" (default "jacobi")
    order = ["plant", "controller"]  # Gauss-Seidel stepping order (default plant first)
    coupling = "zoh"               # "zoh" | "linear" on all connections (default "zoh")
    actuator_delay = 0.0           # transport delay controller -> plant forces [s], >= 0
    sensor_delay = 0.0             # transport delay plant -> controller strains [s], >= 0
    controller_sample_period = 1e-3  # controller period [s], integer multiple of step
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

import difflib
import math
import warnings
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, fields
from pathlib import Path
from typing import Any

from drillcosim.controller import MODES, ControllerParams
from drillcosim.cosim.master.interface import (
    FmuInterface,
    InterfaceError,
    check_system,
    read_interface,
)
from drillcosim.cosim.master.system import (
    ALGORITHMS,
    COUPLINGS,
    Connection,
    FmuSpec,
    SystemSpec,
    integer_multiple,
)
from drillcosim.plant.observables import output_names
from drillcosim.plant.scene import Scene, scenes_dir

from .interface import InterfaceWarning, connections_of, wire_pair

__all__ = [
    "CONTROLLER",
    "COSIM_KEYS",
    "PLANT",
    "CosimSettings",
    "SceneSystem",
    "controller_parameters",
    "cosim_schema_markdown",
    "cosim_settings",
    "default_fmu_dir",
    "ensure_fmus",
    "scene_controller",
    "scene_system",
    "span_info",
]

PLANT = "plant"            #: instance name of the plant FMU
CONTROLLER = "controller"  #: instance name of the controller FMU
PLANT_FMU = "DrillstringPlant.fmu"
CONTROLLER_FMU = "StrainController.fmu"
CONTROLLER_SITES = (1, 2)  #: actuator sites the controller FMU handles
AXES = ("C", "E")
NO_LIMIT = 1e30            #: the controller FMU's "no symmetric force limit"

#: ``[cosim]`` keys: (default, unit, meaning). ``None`` defaults are derived.
COSIM_KEYS: dict[str, tuple[Any, str, str]] = {
    "step": (1e-3, "s", "base communication step H, > 0"),
    "stop_time": (30.0, "s", "default stop time, > 0"),
    "algorithm": ("jacobi", "-", "'jacobi' (parallel) or 'gauss_seidel' (sequential)"),
    "order": (None, "-", "Gauss-Seidel stepping order, a permutation of "
              "['plant', 'controller'] (default plant first)"),
    "coupling": ("zoh", "-", "'zoh' (hold) or 'linear' (extrapolation) on every connection"),
    "actuator_delay": (0.0, "s", "transport delay of the forces controller -> plant, >= 0"),
    "sensor_delay": (0.0, "s", "transport delay of the strains plant -> controller, >= 0"),
    "controller_sample_period": (None, "s", "controller step, an integer multiple of step "
                                 "(default: step)"),
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
    order = get("order", [PLANT, CONTROLLER])
    if not isinstance(order, (list, tuple)) or sorted(order) != sorted([PLANT, CONTROLLER]):
        raise ValueError(f"{scene.source}: [cosim] order = {order!r} must be a permutation of "
                         f"['{PLANT}', '{CONTROLLER}']")
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
        return ControllerParams(**raw)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{scene.source}: [controller] {exc}") from None


def controller_parameters(scene: Scene) -> dict[str, float | int | bool]:
    """The controller FMU's parameters for the scene: :func:`scene_controller` encoded for the
    FMU (the one place that encoding happens).

    Returns
    -------
    dict
        ``gain`` [N], ``mode`` (Integer: index in :data:`controller.MODES`),
        ``force_limit`` [N], ``symmetric_force_limit`` [N] (inf -> 1e30),
        ``switch_on_time`` [s], ``lag_time_constant`` [s], ``enabled``.

    Raises
    ------
    ValueError
        Unknown key (with suggestion) or invalid value, naming the scene file.
    """
    p = scene_controller(scene)
    sym = p.symmetric_force_limit
    return {"gain": p.gain, "mode": MODES.index(p.mode), "force_limit": p.force_limit,
            "symmetric_force_limit": NO_LIMIT if math.isinf(sym) else sym,
            "switch_on_time": p.switch_on_time, "lag_time_constant": p.lag_time_constant,
            "enabled": p.enabled}


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


def default_fmu_dir() -> Path:
    """``build/fmus/`` in the repository."""
    from drillcosim.fmu_src.build import DEFAULT_OUT

    return DEFAULT_OUT


def _stale(fmu: Path, name: str) -> bool:
    from drillcosim.fmu_src.build import REGISTRY, stale

    recipe = next((r for r in REGISTRY if r.name == name), None)
    return recipe is not None and stale(fmu, recipe)


def ensure_fmus(fmu_dir: str | Path | None = None, names: Sequence[str] = (
        "DrillstringPlant", "StrainController")) -> dict[str, Path]:
    """Paths of the project FMUs in ``fmu_dir``, building missing (or stale) ones.

    In the default folder (``build/fmus``) an FMU that :func:`fmu_src.build.stale` calls
    stale (older than a file it is made of, or made by an earlier build) is rebuilt;
    an explicitly given folder is used as is (built only if missing), so a frozen
    set of FMUs stays frozen.

    Raises
    ------
    FileNotFoundError
        If an FMU is still missing after the build (e.g. no adapter yet).
    """
    from drillcosim.fmu_src.build import REGISTRY, build_one

    folder = Path(fmu_dir) if fmu_dir is not None else default_fmu_dir()
    paths = {}
    for name in names:
        path = folder / f"{name}.fmu"
        if not path.is_file() or (fmu_dir is None and _stale(path, name)):
            spec = next((s for s in REGISTRY if s.name == name), None)
            if spec is not None and spec.script_path.is_file():
                build_one(spec, folder)
        if not path.is_file():
            raise FileNotFoundError(f"FMU '{path}' does not exist and cannot be built "
                                    f"(no adapter for {name} yet)")
        paths[name] = path
    return paths


def _plant_outputs(scene: Scene, declared: Sequence[str]) -> list[str]:
    """The scene's plant outputs to record, those the plant FMU declares (in this order)."""
    plant = scene.plant
    names = [r[0] for r in output_names(scene.model == "full3d", list(plant.contact_bodies),
                                        len(plant.actuator_joints))]
    wanted = []
    for b in plant.contact_bodies:
        wanted += [f"body{b}_{q}" for q in ("X", "Y", "radial_deflection", "contact_force")]
    for s in range(1, len(plant.actuator_joints) + 1):
        wanted += [f"strain{s}_{a}" for a in AXES] + [f"actuator{s}_power"]
    wanted += ["bit_axial_force", "bit_torque", "hook_load", "top_rotary_speed",
               "bit_rotary_speed", "total_energy", *scene.outputs]
    out = []
    for n in wanted:
        if n in names and n in declared and n not in out:
            out.append(n)
    return out


def _scene_fmu(scene: Scene, table: str, given: str | Path | None) -> Path | None:
    """An FMU file chosen by argument, else by the scene's ``[<table>] fmu`` (None: default).

    A relative path in the scene is resolved against the scene file's folder.
    """
    if given:
        return Path(given)
    raw = scene.plant_fmu if table == "plant" else scene.controller
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


def scene_system(scene: Scene, fmu_dir: str | Path | None = None, *,
                 plant_fmu: str | Path | None = None,
                 controller_fmu: str | Path | None = None,
                 plant_overrides: Mapping[str, Any] | None = None) -> SceneSystem:
    """Build the co-simulation system of a scene and check its FMU pair.

    Parameters
    ----------
    scene : Scene
    fmu_dir : path-like, optional
        Folder of ``DrillstringPlant.fmu`` and ``StrainController.fmu``
        (default ``build/fmus/``); missing or stale FMUs are built there.
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
        Invalid ``[cosim]``, ``[controller]`` or ``[plant]`` keys or values (one line,
        naming the scene file and the key).
    cosim.master.interface.InterfaceError
        The plant and controller FMUs do not fit (a ``ValueError``; one line per problem,
        each naming both FMUs and the variable).
    FileNotFoundError
        An FMU is missing and cannot be built.

    Warns
    -----
    InterfaceWarning
        Plant inputs of sites the controller does not serve (they keep their start value),
        or a plant FMU without a ``scene`` parameter.
    """
    settings = cosim_settings(scene)
    ctrl = controller_parameters(scene)
    enabled = bool(ctrl["enabled"])
    n_sites = len(scene.plant.actuator_joints)
    if controller_fmu and not enabled:
        raise ValueError(f"{scene.source}: a controller FMU was given ({controller_fmu}) but "
                         "the scene's controller is off: set controller.enabled=true")
    plant_fmu = _scene_fmu(scene, "plant", plant_fmu)
    controller_fmu = _scene_fmu(scene, "controller", controller_fmu) if enabled else None
    if enabled and scene.model != "full3d":
        raise ValueError(f"{scene.source}: the controller needs model = 'full3d', "
                         f"got '{scene.model}'")
    if enabled and controller_fmu is None and n_sites != len(CONTROLLER_SITES):
        raise ValueError(f"{scene.source}: [actuators] the controller FMU handles "
                         f"{len(CONTROLLER_SITES)} sites, the plant has {n_sites}")
    overrides = _flatten(plant_overrides or {}, scene.source)
    need = ([] if plant_fmu else ["DrillstringPlant"]) + \
        ([] if controller_fmu or not enabled else ["StrainController"])
    paths = ensure_fmus(fmu_dir, need) if need else {}
    plant_face = read_interface(PLANT, plant_fmu or paths["DrillstringPlant"])
    plant_params: dict[str, float | int | bool | str] = {}
    if "scene" in plant_face.ports:
        plant_params["scene"] = scene_reference(scene)
    else:
        warnings.warn(InterfaceWarning(
            f"{plant_face.label} has no 'scene' parameter: the plant tables of "
            f"{scene.source} are not applied to it"), stacklevel=2)
    plant_params.update(overrides)
    fmus = [FmuSpec(PLANT, plant_face.path, plant_params)]
    connections: list[Connection] = []
    outputs = [f"{PLANT}.{n}" for n in _plant_outputs(scene, plant_face.outputs())]
    order: tuple[str, ...] = (PLANT,)
    if enabled:
        ctrl_face = read_interface(CONTROLLER, controller_fmu or paths["StrainController"])
        fmus.append(FmuSpec(CONTROLLER, ctrl_face.path,
                            {k: v for k, v in ctrl.items() if k in ctrl_face.ports},
                            settings.controller_sample_ticks))
        wiring = wire_pair(plant_face, ctrl_face, fmus, _lacking(scene, ctrl_face))
        connections = connections_of(wiring, {CONTROLLER: settings.sensor_delay,
                                              PLANT: settings.actuator_delay}, settings.coupling)
        outputs += [s for s, t in wiring.connections if s.startswith(f"{CONTROLLER}.")]
        order = settings.order
    elif overrides:
        # the plant alone: its start values are checked the same way
        problems = check_system(fmus, (), {PLANT: plant_face}).problems
        if problems:
            raise InterfaceError(f"{plant_face.label} cannot take the scene's settings",
                                 problems)
    system = SystemSpec(fmus, connections, settings.step, settings.algorithm, order,
                        0.0, settings.stop_time)
    return SceneSystem(scene, system, settings, tuple(outputs))


def _lacking(scene: Scene, ctrl_face: FmuInterface) -> list[str]:
    """``[controller]`` keys the scene sets explicitly that the controller FMU does not declare."""
    return [f"{ctrl_face.label} has no parameter '{key}' for [controller] {key} of "
            f"{scene.source}" for key in scene.controller
            if key not in ("enabled", "fmu") and key not in ctrl_face.ports]


def cosim_schema_markdown() -> str:
    """The ``[controller]`` and ``[cosim]`` tables as markdown (for ``docs/scenes.md``).

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
                  "switch_on_time": "s", "lag_time_constant": "s", "enabled": "-"}
    ctrl_text = {
        "gain": "force per unit strain, >= 0 (paper: 1e9)",
        "mode": "'unrestricted' (push and pull) or 'compressive_only' (push only)",
        "force_limit": "peak push force in compressive_only mode",
        "symmetric_force_limit": "limit on abs(force) in unrestricted mode (inf = none)",
        "switch_on_time": "controller output is zero before this time",
        "lag_time_constant": "first-order actuator lag; 0 = none",
        "enabled": "false = open loop (the plant runs alone)",
        "fmu": "path of a controller FMU (any maker; relative to the scene file's folder) "
               "instead of the built StrainController.fmu; `drillcosim run --controller-fmu` "
               "overrides it",
    }
    defaults: dict[str, Any] = {f.name: f.default for f in fields(ControllerParams)}
    defaults["enabled"] = False
    ctrl_units["fmu"] = "-"
    for name in ctrl_units:
        if name == "fmu":
            lines.append(f"| fmu | - | - | {ctrl_text['fmu']} |")
            continue
        d = defaults[name]
        ds = ("inf" if isinstance(d, float) and math.isinf(d) else
              str(d).lower() if isinstance(d, bool) else f'"{d}"' if isinstance(d, str)
              else f"{d:g}")
        lines.append(f"| {name} | {ds} | {ctrl_units[name]} | {ctrl_text[name]} |")
    lines += ["", "The plant and controller FMUs connect by name; before the first step the pair "
              "is checked (causality, type, unit, nothing connected twice, start values), "
              "every problem in one line naming both FMUs and the variable (exit code 2). "
              "Plant inputs of sites the controller does not serve keep their start value, "
              "with a warning naming them ([interop.md](interop.md)).",
              "", "## [cosim]", "",
              "Co-simulation settings (`cosim.scenario.scene_system.cosim_settings`).", "",
              "| key | default | unit | meaning |", "|---|---|---|---|"]
    for key, (default, unit, text) in COSIM_KEYS.items():
        ds = "-" if default is None else (f'"{default}"' if isinstance(default, str)
                                          else f"{default:g}")
        lines.append(f"| {key} | {ds} | {unit} | {text} |")
    lines.append("")
    return "\n".join(lines)
