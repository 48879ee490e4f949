"""Which project FMUs run a scene: the default build, or FMUs built for the scene's layout.

The default plant FMU (``DrillstringPlant.fmu``) declares the paper's layout: the 3D model's
outputs for contact bodies 11 and 26 and two actuator sites, and the four actuator forces as
inputs. It runs every scene whose 3D model has exactly that interface (the paper's scenes, the
Table 1 tests). Any other scene (another number of sites, other contact bodies, the extended
outputs of wellbore friction or a cutting bit, a top-drive input, the axial-torsional chain of
``stick_slip``) gets a plant FMU built for it: ``DrillstringPlant_<scene>``, a variant of the
same adapter (``fmu_src/build.py``, "Variants") whose variables are the scene's model's
(:class:`PlantLayout`: the inputs that act on it, every output, with units and descriptions)
and whose ``scene`` and ``model`` parameters start at the scene and its model kind.

Likewise each registered controller law (:mod:`controller.registry`) has a default FMU for its
default layout (``StrainController.fmu``: two sites, one P law per channel;
``TopDriveController.fmu``, ...), and a scene whose law needs another layout
(``Law.layout_for``: another number of sites, a ``[controller] gain_matrix``) gets the variant
``<FMU>_<scene>`` of the same generic adapter (``fmu_src/law_fmu.py``). A law with a resource
file (``[controller] kind = "state_space"``) always gets ``StateSpaceController_<scene>``, which
carries the scene's matrices file as ``resources/state_space.json``.

A variant's model identifier, file name, slave module and GUID differ from the default's
(the module name carries a hash of the layout), so variants of several scenes and the default
FMUs live in one folder and one process. :func:`scene_recipes` says which FMUs a scene needs,
:func:`ensure_recipes` builds missing (or stale) ones; ``drillcosim build --scene SCENE``
builds them ahead of time, ``drillcosim run SCENE`` on demand.
"""

from __future__ import annotations

import functools
import json
import re
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from drillcosim.fmu_src.build import (
    DEFAULT_OUT,
    PLANT_RECIPE,
    REGISTRY,
    FmuRecipe,
    build_one,
    law_recipe,
    stale,
)
from drillcosim.plant.model import DrillstringModel
from drillcosim.plant.params import PlantParams
from drillcosim.plant.scene import Scene, scene_files, scenes_dir
from drillcosim.plant.signals import (
    TOP_DRIVE_SPEED_COMMAND,
    TOP_DRIVE_TORQUE,
    actuator_force,
    body_signal,
)

__all__ = ["DEFAULT_PLANT", "PlantLayout", "built_for_scene", "controller_recipe",
           "default_fmu_dir",
           "ensure_recipes", "plant_layout", "plant_recipe", "recipe_named", "variant_name"]

DEFAULT_PLANT = PLANT_RECIPE.name

Row = tuple[str, str, str]


@dataclass(frozen=True)
class PlantLayout:
    """The interface of a plant FMU built for a scene.

    Attributes
    ----------
    scene : str
        The scene as the FMU finds it among ``resources/scenes/`` (its name).
    model : str
        Model kind, ``"full3d"`` or ``"axial_torsional"``.
    extended : bool
        The extended outputs (whirl, cutting bit) are listed.
    inputs, outputs : tuple of (name, unit, description)
        In the model's order; units as the plant states them (``"N m"``, ``"rad/s"``).
    """

    scene: str
    model: str
    extended: bool
    inputs: tuple[Row, ...]
    outputs: tuple[Row, ...]

    def attributes(self, description: str) -> dict:
        """The ``LAYOUT`` class attribute of the adapter variant."""
        return {"LAYOUT": {"scene": self.scene, "model": self.model, "extended": self.extended,
                           "inputs": [list(r) for r in self.inputs],
                           "outputs": [list(r) for r in self.outputs],
                           "description": description}}


def recipe_named(name: str) -> FmuRecipe:
    """The registered recipe ``name`` (:data:`fmu_src.build.REGISTRY`)."""
    return next(r for r in REGISTRY if r.name == name)


def built_for_scene(recipe: FmuRecipe) -> bool:
    """Whether ``recipe`` is an FMU built for a scene (not one of the default FMUs of
    :data:`fmu_src.build.REGISTRY`)."""
    return recipe not in REGISTRY


def default_fmu_dir() -> Path:
    """Where the project's FMUs are built and found by default (``build/fmus/`` of a checkout)."""
    return DEFAULT_OUT


def variant_name(base: str, scene: Scene) -> str:
    """``<base>_<scene name>``, non-identifier characters replaced by ``_``."""
    return f"{base}_{re.sub(r'[^A-Za-z0-9_]', '_', scene.name)}"


@functools.lru_cache(maxsize=1)
def _default_plant_interface() -> tuple[tuple[str, ...], tuple[str, ...]]:
    """(inputs, outputs) the default plant FMU declares (its model: defaults, 3D)."""
    model = DrillstringModel(PlantParams(), "full3d")
    return tuple(model.acting_inputs), tuple(model.output_names)


def _scene_files(scene: Scene) -> tuple[str, tuple[tuple[str, str], ...]]:
    """The scene's name inside the FMU and the files to copy into ``resources/scenes/``
    (the scene file and those it extends that are not shipped)."""
    src = Path(scene.source)
    shipped = scenes_dir()
    if not src.is_file():
        if (shipped / f"{scene.name}.toml").is_file():
            return scene.name, ()
        raise ValueError(f"scene {scene.name!r} ({scene.source}) has no file: an FMU can only "
                         "be built for a scene file")
    copies = []
    for path in scene_files(src):
        if path.resolve() != (shipped / path.name).resolve():
            copies.append((str(path.resolve()), f"scenes/{path.name}"))
    return src.stem, tuple(copies)


def embedded_scene_name(scene: Scene) -> str:
    """The name under which a plant FMU built for ``scene`` carries it (``resources/scenes/``):
    the value of that FMU's ``scene`` parameter, valid on any machine."""
    return _scene_files(scene)[0]


def plant_layout(scene: Scene) -> PlantLayout | None:
    """The interface of the plant FMU for ``scene``; None when the default FMU serves it.

    The default serves a scene whose 3D model has exactly the default's inputs and outputs;
    otherwise the layout is the scene's own model (``scene.model``): the inputs that act on it
    (:attr:`plant.model.DrillstringModel.acting_inputs`) and all its outputs.
    """
    full = DrillstringModel(scene.plant, "full3d")
    if (tuple(full.acting_inputs), tuple(full.output_names)) == _default_plant_interface():
        return None
    model = full if scene.model == "full3d" else DrillstringModel(scene.plant, scene.model)
    name, _copies = _scene_files(scene)
    inputs = tuple((n, model.input_units[n], model.input_docs[n]) for n in model.acting_inputs)
    outputs = tuple((n, model.output_units[n], model.output_docs[n])
                    for n in model.output_names)
    return PlantLayout(name, model.kind, model.extended_outputs, inputs, outputs)


def plant_recipe(scene: Scene) -> FmuRecipe:
    """The recipe of the plant FMU that runs ``scene``: the default, or its variant."""
    base = recipe_named(DEFAULT_PLANT)
    layout = plant_layout(scene)
    if layout is None:
        return base
    _name, copies = _scene_files(scene)
    inputs = {n for n, _u, _d in layout.inputs}
    outputs = {n for n, _u, _d in layout.outputs}
    sites = sum(1 for s in range(1, len(scene.plant.actuator_joints) + 1)
                if actuator_force(s, "C") in inputs)
    bodies = [str(b) for b in scene.plant.contact_bodies if body_signal(b, "X") in outputs]
    drive = [n for n in (TOP_DRIVE_TORQUE, TOP_DRIVE_SPEED_COMMAND) if n in inputs]
    description = (f"Drillstring vibration plant built for scene '{layout.scene}' "
                   f"({layout.model} model): {sites} actuator sites, contact bodies "
                   f"[{', '.join(bodies)}]" + (f", top-drive input {drive[0]}" if drive else "")
                   + ". Parameters: scene (shipped name or TOML path) first, then every "
                   "parameter set to a value different from its start overrides the scene")
    return FmuRecipe(
        name=variant_name(DEFAULT_PLANT, scene), script=base.script, vendored=base.vendored,
        extra_files=base.extra_files, options=base.options, requires=base.requires,
        exclude=base.exclude, base=DEFAULT_PLANT,
        class_attributes=json.dumps(layout.attributes(description)), resource_files=copies)


def controller_recipe(setting: Any, scene: Scene, n_sites: int) -> FmuRecipe:
    """The recipe of the FMU that runs a controller (a :class:`.controllers.ControllerSetting`)
    of ``scene`` (``n_sites`` actuator sites): its law's default FMU where the law's layout for
    the scene is the default one, else the variant ``<FMU>_<scene>`` (a law with a resource
    file: always, carrying the scene's file)."""
    law = setting.law
    layout = setting.layout(n_sites)
    if not law.RESOURCE and layout == law.default_layout():
        return recipe_named(law.FMU)
    ports = law.ports(layout)
    n_in = sum(p.causality == "input" for p in ports)
    n_out = sum(p.causality == "output" for p in ports)
    description = (f"{law.DESCRIPTION}. Built for scene '{scene.name}': {n_in} inputs, {n_out} "
                   f"outputs" + (f". {setting.params.description}" if law.RESOURCE else ""))
    return law_recipe(law, {**layout, "description": description},
                      name=variant_name(law.FMU, scene),
                      resource=Path(setting.matrices).resolve() if law.RESOURCE else "")


def ensure_recipes(recipes: Sequence[FmuRecipe], fmu_dir: str | Path | None = None
                   ) -> dict[str, Path]:
    """Paths of the FMUs of ``recipes`` in ``fmu_dir``, building missing (or stale) ones.

    In the default folder (``build/fmus``) an FMU that :func:`fmu_src.build.stale` calls
    stale (older than a file it is made of, made by an earlier build, or from another layout)
    is rebuilt; an explicitly given folder is used as is (built only if missing), so a frozen
    set of FMUs stays frozen.

    Returns
    -------
    dict
        ``{recipe name: path}``.

    Raises
    ------
    FileNotFoundError
        If an FMU is still missing after the build (e.g. no adapter yet).
    """
    folder = Path(fmu_dir) if fmu_dir is not None else default_fmu_dir()
    paths = {}
    for recipe in recipes:
        path = folder / f"{recipe.name}.fmu"
        if not path.is_file() or (fmu_dir is None and stale(path, recipe)):
            if recipe.script_path.is_file():
                build_one(recipe, folder)
        if not path.is_file():
            raise FileNotFoundError(f"FMU '{path}' does not exist and cannot be built "
                                    f"(no adapter for {recipe.name} yet)")
        paths[recipe.name] = path
    return paths
