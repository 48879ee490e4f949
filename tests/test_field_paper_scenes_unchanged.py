"""Today's scenes give bit-identical outputs to the plant before the field-scale extension
("today's scenes are unchanged").

The second implementation is main's own plant: the package ``plant/`` at :data:`BASE` (the main
commit the field branch last merged, before the field-scale plant), taken from this clone's git
history with ``git archive`` and imported under another name (the plant package is
self-contained, as the FMUs vendor it). Every scene shipped at :data:`BASE` is built by both
plants from the same scene file and stepped with the same pseudo-random actuator and top-drive
inputs at its communication step (the automatic method for that step: RK4 at 1 ms, Kutta's
method at 0.25 ms), then run alone through the recording loop; outputs and states must be equal
bit for bit. A deliberate change of main's plant moves :data:`BASE`.

The numpy reference right-hand side (``tests/support/numpy_rhs.py``) is a second implementation too, but
it sums in another order (equal to 1e-12, ``tests/test_integrators.py``): it cannot tell a bit
apart. The extracted plant is cached per commit under the user cache (numba's cache beside it).
"""

from __future__ import annotations

import importlib
import os
import shutil
import subprocess
import sys
import tarfile
import tempfile
from pathlib import Path
from types import ModuleType

import numpy as np
import pytest

from drillcosim._toolchain import user_cache
from drillcosim.cosim.scenario.config import load_config
from drillcosim.plant.model import DrillstringModel
from drillcosim.plant.scene import load_scene
from drillcosim.plant.simulator import PlantSimulator, simulate
from support.required import missing

ROOT = Path(__file__).resolve().parents[1]
#: the main line when the field-scale work last merged it, without the field-scale plant
BASE = "d30ca1b00e05bf1b8ad0d0ce76d3b9a61b7329e4"
STEPS = 120  # communication steps with inputs
ALONE = 0.1  # s, the plant alone through the recording loop


def _git(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run(["git", "-C", str(ROOT), *args], capture_output=True)


def _have_base() -> bool:
    """Is :data:`BASE` in this clone's history?"""
    return shutil.which("git") is not None and _git(
        "cat-file", "-e", f"{BASE}^{{commit}}").returncode == 0


@pytest.fixture(scope="module")
def base_plant() -> tuple[tuple[ModuleType, ModuleType, ModuleType], Path]:
    """main's plant (imported as ``plant_<sha>``): its scene, model and simulator modules; its
    scenes folder."""
    if not _have_base():
        missing("git-history", f"git, or commit {BASE[:12]} in this clone's history")
    name = f"plant_{BASE[:12]}"
    home = user_cache() / "baseline" / BASE[:12]
    if not (home / name / "__init__.py").exists():
        home.parent.mkdir(parents=True, exist_ok=True)
        tmp = Path(tempfile.mkdtemp(dir=home.parent))
        arc = _git("archive", "--format=tar", BASE, "plant", "scenes")
        assert arc.returncode == 0, arc.stderr.decode()
        tar = tmp / "base.tar"
        tar.write_bytes(arc.stdout)
        with tarfile.open(tar) as tf:
            # our own history: trusted; the "data" filter where this Python has it
            tf.extractall(tmp, **({"filter": "data"} if hasattr(tarfile, "data_filter") else {}))
        tar.unlink()
        (tmp / "plant").rename(tmp / name)
        try:
            os.replace(tmp, home)  # atomic: a concurrent run finds all or nothing
        except OSError:  # another run put it there first
            shutil.rmtree(tmp, ignore_errors=True)
        for old in home.parent.iterdir():  # the copies of earlier bases
            if old.is_dir() and old.name != home.name and not old.name.startswith("tmp"):
                shutil.rmtree(old, ignore_errors=True)
    sys.path.insert(0, str(home))
    try:
        scene = importlib.import_module(f"{name}.scene")
        model = importlib.import_module(f"{name}.model")
        simulator = importlib.import_module(f"{name}.simulator")
    finally:
        sys.path.remove(str(home))
    return (scene, model, simulator), home / "scenes"


def _base_scenes() -> list[str]:
    if not _have_base():
        return ["paper_open_loop"]  # skipped by the fixture
    out = _git("ls-tree", "--name-only", BASE, "scenes/").stdout.decode().split()
    return sorted(Path(p).stem for p in out if p.endswith(".toml"))


def _drive(sim, H: float, rng: np.random.Generator) -> tuple[np.ndarray, list]:
    """Step with pseudo-random inputs; outputs after every step and the step results."""
    rows, results = [], []
    for k in range(STEPS):
        sim.set_inputs(rng.normal(0.0, 2e3, sim.u.size))
        res = sim.do_step(k * H, H)
        results.append((res.ok, res.message))
        rows.append(sim.outputs().copy())
        if not res.ok:
            break
    return np.array(rows), results


@pytest.mark.parametrize("name", _base_scenes())
def test_scene_is_bit_identical_to_main(base_plant, name: str) -> None:
    (b_scene, b_model, b_sim), b_folder = base_plant
    text = (b_folder / f"{name}.toml").read_text()
    assert (ROOT / "scenes" / f"{name}.toml").read_text() == text, "the scene file changed"
    H = load_config(name).cosim.step
    new_sc = load_scene(name)
    old_sc = b_scene.load_scene(name, b_folder)
    new = DrillstringModel(new_sc.plant, new_sc.model)
    old = b_model.DrillstringModel(old_sc.plant, old_sc.model)
    assert new.output_names == old.output_names and new.input_names == old.input_names
    assert new.n_state == old.n_state

    a, b = PlantSimulator(new), b_sim.PlantSimulator(old)
    out_a, res_a = _drive(a, H, np.random.default_rng(7))
    out_b, res_b = _drive(b, H, np.random.default_rng(7))
    assert a.method == b.method
    assert res_a == res_b
    assert np.array_equal(out_a, out_b, equal_nan=True)
    assert np.array_equal(a.y, b.y, equal_nan=True)

    ta, va, ra = simulate(DrillstringModel(new_sc.plant, new_sc.model), ALONE, 1e-3)
    tb, vb, rb = b_sim.simulate(b_model.DrillstringModel(old_sc.plant, old_sc.model), ALONE,
                                1e-3)
    assert (ra.ok, ra.message) == (rb.ok, rb.message) and np.array_equal(ta, tb)
    for key in vb:
        assert np.array_equal(va[key], vb[key], equal_nan=True), key
