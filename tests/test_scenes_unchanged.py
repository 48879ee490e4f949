"""Nothing moves: every shipped scene gives bit-identical outputs on today's plant and
controllers and on those of a reference commit.

The second implementation is the reference commit's own ``plant/`` and ``controller/``, taken
from this clone's git history (:mod:`support.baseline`) and imported under other names. Each
scene shipped at its reference commit is configured once (today's :func:`load_config`: the
scene file must be unchanged) and run for a short time through today's master twice, with the
same system (connections, delays, sample periods, algorithm):

* today's in-process slaves (``build_system(config, "inprocess")``: the compiled steps of the
  plant and the laws, the master's native loop where it applies);
* slaves over the reference commit's objects: its ``PlantSimulator`` (with its own compiled
  step) and its laws, stepped in Python through their own ``step``.

Every output of every instance, recorded at every base step, must be equal bit for bit (NaN
equal to NaN), and so must how the run ended.

The reference is a small table, :data:`REFERENCE` (scene -> commit, :data:`BASE` for the
others): a change that moves a scene's numbers on purpose moves that scene's row to its own
commit (a correction of the field physics would, for the hoisting and field scenes).
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from drillcosim.cosim.scenario.build import build_system
from drillcosim.cosim.scenario.config import SceneConfig, load_config
from drillcosim.cosim.scenario.inprocess import LawSlave, PlantSlave
from drillcosim.cosim.scenario.scene_fmus import plant_layout
from drillcosim.cosim.scenario.simulate import simulate
from drillcosim.plant.signals import PLANT
from support.baseline import ROOT, Baseline, baseline_packages, have_commit, scenes_at

#: The commit before controllers became plug-ins (7845e95).
BASE = "7845e9590345d585957ff0445135eeb60138a650"
#: Scenes whose reference is another commit (a change that moves them on purpose).
#: The field scenes: the 8.5-in bit's gauge is the hole's (bit.radius 0.10795 m, was 0.108 m,
#: 0.05 mm larger than its hole), the plant that integrates the drive's ramps exactly (9e4103d).
_FIELD_BIT = "9e4103d2854a110c54fefe13c66f9b8e13056c8d"
REFERENCE: dict[str, str] = {
    name: _FIELD_BIT for name in ("field_vertical_3km", "field_vertical_3km_soft_torque",
                                  "field_deviated_3km", "field_deviated_3km_bha_control")}
#: Base steps run per scene (at least this many controller periods too).
STEPS = 40
PERIODS = 4


def _reference(scene: str) -> str:
    return REFERENCE.get(scene, BASE)


def _scenes() -> list[str]:
    names = set()
    for commit in {BASE, *REFERENCE.values()}:
        if have_commit(commit):
            names.update(s for s in scenes_at(commit) if _reference(s) == commit)
    return sorted(names) or ["paper_open_loop"]  # skipped by the fixture without history


_BASELINES: dict[str, Baseline] = {}


def _baseline(commit: str) -> Baseline:
    if not have_commit(commit):
        pytest.skip(f"needs this repository's git history (commit {commit[:12]})")
    if commit not in _BASELINES:
        _BASELINES[commit] = baseline_packages(commit)
    return _BASELINES[commit]


class _OldLaw:
    """A reference commit's law in today's law interface (``controller/law.py``), stepped in
    Python: ``advance(law, t, h, u)`` returns the outputs at ``t + h``, ``start(law)`` the
    outputs at the start."""

    def __init__(self, law, advance, start):
        self.law, self._advance, self._start = law, advance, start

    def reset(self):
        self.law.reset()

    def initial_outputs(self):
        return self._start(self.law)

    def advance(self, t, h, u, y):
        y[:] = self._advance(self.law, t, h, u)

    def compiled_step(self, u, y):
        return None

    def get_state(self):
        return self.law.get_state()

    def set_state(self, state):
        self.law.set_state(state)


def _old_params(cls, new):
    """``new`` (a params dataclass of today) as the reference commit's class ``cls``."""
    return cls(**{f.name: getattr(new, f.name) for f in dataclasses.fields(cls)})


def _old_law(setting, n_sites: int, base: Baseline) -> _OldLaw:
    """The reference commit's law of today's controller setting (``n_sites`` sites)."""
    ctrl = base.module("controller")
    if setting.kind == "state_space":
        ss = base.module("controller", "state_space")
        return _OldLaw(ss.StateSpaceController(ss.load_state_space(setting.matrices)),
                       lambda law, t, h, u: law.step(t, h, u),
                       lambda law: law.workspace.outputs)
    if setting.kind == "proportional":
        return _OldLaw(ctrl.StrainController(_old_params(ctrl.ControllerParams, setting.params),
                                             n_sites),
                       lambda law, t, h, u: law.step(t, h, u), lambda law: law.forces)
    assert setting.kind == "pi", setting.kind
    return _OldLaw(ctrl.TopDriveController(_old_params(ctrl.TopDriveControllerParams,
                                                       setting.params)),
                   lambda law, t, h, u: [law.step(t, h, float(u[0]), float(u[1]))],
                   lambda law: [law.torque])


def _old_slaves(config: SceneConfig, base: Baseline) -> dict:
    """The reference commit's plant and laws behind slaves of today's names and ports."""
    scene_mod, model_mod, sim_mod = (base.module("plant", m)
                                     for m in ("scene", "model", "simulator"))
    old_scene = scene_mod.load_scene(config.name, base.scenes)
    kind = "full3d" if plant_layout(config.scene) is None else config.scene.model
    slaves = {PLANT: PlantSlave(PLANT, sim_mod.PlantSimulator(
        model_mod.DrillstringModel(old_scene.plant, kind)))}
    for instance in config.instances[1:]:
        setting = config.controllers[instance]
        law = _old_law(setting, config.n_sites, base)
        slaves[instance] = LawSlave(instance, law,
                                    setting.law.ports(setting.layout(config.n_sites)))
    return slaves


@pytest.mark.parametrize("name", _scenes())
def test_scene_is_bit_identical_to_its_reference(name: str, monkeypatch) -> None:
    base = _baseline(_reference(name))
    text = (base.scenes / f"{name}.toml").read_text()
    assert (ROOT / "scenes" / f"{name}.toml").read_text() == text, "the scene file changed"
    config = load_config(name)
    step, ticks = config.cosim.step, config.cosim.controller_ticks
    stop = config.cosim.seconds(max(STEPS, PERIODS * ticks))
    config = load_config(name, {"cosim.stop_time": stop, "cosim.output_interval": step})
    built = build_system(config, "inprocess")
    outputs = tuple(built.units)  # every output of every instance
    new = simulate(built, outputs=outputs)
    with monkeypatch.context() as m:  # the reference plant steps in Python: no cfunc to compile
        m.setenv("DRILLCOSIM_COMPILED_STEP", "0")
        slaves = _old_slaves(config, base)
    old = simulate(dataclasses.replace(built, slaves=slaves), outputs=outputs)
    assert new.data.dtype.names == old.data.dtype.names
    assert len(new.data) == len(old.data) >= 2
    assert (new.end_time, new.failure) == (old.end_time, old.failure)
    differ = [n for n in new.data.dtype.names
              if not np.array_equal(new.data[n], old.data[n], equal_nan=True)]
    assert not differ, f"{name}: outputs differ from {base.commit[:12]}: {differ[:8]}"
