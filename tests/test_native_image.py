"""Native images (``fmu_src/slave_support/native.py``): the compiled steps' machine code, kept
beside the stable copy of a vendored package, loaded without setting numba up.

* A closed loop through the FMUs in a fresh process that finds the images never sets numba up
  (none of its typing and lowering registries is imported), and its outputs equal, bit for bit,
  those of the same run with images off (numba compiles or loads the cfuncs) and those of the
  Python steps (``DRILLCOSIM_COMPILED_STEP=0``, the reference).
* An image round trip on a small cfunc, in fresh processes: the loaded function computes what
  numba's does; an image of another key, a truncated one or one without the entry point asked
  for is not used.
"""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]
STOP = 0.05  # s: 200 steps of the closed loop

RUN = textwrap.dedent(r"""
    import json, sys
    import numpy as np
    from drillcosim.api import simulate
    res = simulate("paper_closed_loop", stop_time=float(sys.argv[3]), engine="fmu",
                   fmu_dir=sys.argv[1])
    np.save(sys.argv[2], res.to_pandas().to_numpy())
    sources = {}
    for name, module in list(sys.modules.items()):
        if name.startswith("_dcs_slave_support_0_1_0") and name.endswith(".native"):
            for entry, where in module.sources().items():
                sources[entry.split("_0_1_0")[0].lstrip("_").replace("dcs_", "")] = where
    print(json.dumps({"sources": sources, "numba_set_up": "numba.np.arraymath" in sys.modules}))
""")


def _run(folder: Path, out: Path, **env: str) -> dict:
    import os

    proc = subprocess.run([sys.executable, "-c", RUN, str(folder), str(out), repr(STOP)], cwd=ROOT,
                          env={**os.environ, **env}, capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr[-3000:]
    return json.loads(proc.stdout.strip().splitlines()[-1])


@pytest.mark.slow
def test_a_process_with_images_sets_no_numba_up_and_gives_the_same_bits(project_fmus, tmp_path):
    folder = next(iter(project_fmus.values())).parent
    first = _run(folder, tmp_path / "first.npy")  # makes the images if none exist yet
    assert set(first["sources"]) == {"plant", "controller"}, first
    imaged = _run(folder, tmp_path / "image.npy")
    assert imaged == {"sources": {"plant": "image", "controller": "image"},
                      "numba_set_up": False}
    numba = _run(folder, tmp_path / "numba.npy", DRILLCOSIM_NATIVE_IMAGE="0")
    assert numba == {"sources": {"plant": "numba", "controller": "numba"}, "numba_set_up": True}
    python = _run(folder, tmp_path / "python.npy", DRILLCOSIM_COMPILED_STEP="0")
    assert python["sources"] == {}
    a = np.load(tmp_path / "image.npy")
    assert a.shape[0] > 10
    assert np.isfinite(a).all() and np.abs(a).max() > 0.0
    for other in ("first", "numba", "python"):
        np.testing.assert_array_equal(a, np.load(tmp_path / f"{other}.npy"), err_msg=other)


# --- the image format, on a small cfunc ----------------------------------------------------
TINY = textwrap.dedent("""
    import math
    from numba import cfunc, types

    def scaled_sine(context, t, h):
        return int(1e6 * math.sin(t) * h)

    def cfuncs():
        return {"scaled_sine": cfunc(types.int32(types.voidptr, types.float64, types.float64),
                                     nopython=True, cache=True)(scaled_sine)}
""")

LOAD = textwrap.dedent(r"""
    import ctypes, json, sys
    sys.path.insert(0, sys.argv[1])
    from ssx import native
    path, entries = sys.argv[2], json.loads(sys.argv[3])
    found = native.read_image(path, entries)
    value = None
    if found is not None:
        f = ctypes.CFUNCTYPE(ctypes.c_int32, ctypes.c_void_p, ctypes.c_double,
                             ctypes.c_double)(found["scaled_sine"])
        value = f(None, 0.7, 3.0)
    print(json.dumps({"value": value, "numba_set_up": "numba.np.arraymath" in sys.modules}))
""")

WRITE = textwrap.dedent(r"""
    import sys
    sys.path.insert(0, sys.argv[1])
    from ssx import native
    import tiny
    cf = tiny.cfuncs()
    assert native.write_image(__import__("pathlib").Path(sys.argv[2]), cf)
    print(cf["scaled_sine"].ctypes(None, 0.7, 3.0))
""")


def _py(*args: str) -> str:
    proc = subprocess.run([sys.executable, "-c", *args], capture_output=True, text=True,
                          timeout=300)
    assert proc.returncode == 0, proc.stderr[-3000:]
    return proc.stdout.strip().splitlines()[-1]


@pytest.fixture(scope="module")
def tiny_image(tmp_path_factory) -> tuple[Path, Path, int]:
    """(folder on sys.path, image, numba's value) of a one-entry image."""
    where = tmp_path_factory.mktemp("native")
    pkg = where / "ssx"
    pkg.mkdir()
    (pkg / "__init__.py").write_text("")
    for name in ("native.py", "vendored.py"):
        shutil.copy(ROOT / "fmu_src" / "slave_support" / name, pkg / name)
    (where / "tiny.py").write_text(TINY)
    image = where / "tiny.bin"
    value = int(_py(WRITE, str(where), str(image)))
    return where, image, value


def _load(where: Path, image: Path, entries=("scaled_sine",)) -> dict:
    return json.loads(_py(LOAD, str(where), str(image), json.dumps(list(entries))))


def test_an_image_loads_in_a_fresh_process_without_numba_and_computes_the_same(tiny_image):
    where, image, value = tiny_image
    assert value == int(1e6 * np.sin(0.7) * 3.0)
    assert _load(where, image) == {"value": value, "numba_set_up": False}


def test_an_image_of_another_key_cut_damaged_or_without_the_entry_is_not_used(tiny_image,
                                                                               tmp_path):
    where, image, _value = tiny_image
    data = image.read_bytes()
    magic_end = data.index(b"\n") + 1
    end = data.index(b"\n", magic_end)
    header = json.loads(data[magic_end:end])
    header["key"]["numba"] = "0.0.0"
    other = tmp_path / "other_key.bin"
    other.write_bytes(data[:magic_end] + json.dumps(header).encode() + data[end:])
    cut = tmp_path / "cut.bin"
    cut.write_bytes(data[:-100])
    bad_magic = tmp_path / "bad_magic.bin"
    bad_magic.write_bytes(b"X" + data[1:])
    damaged = tmp_path / "damaged.bin"
    middle = (end + 1 + len(data)) // 2        # a byte inside the object code
    damaged.write_bytes(data[:middle] + bytes([data[middle] ^ 0xFF]) + data[middle + 1:])
    not_a_table = tmp_path / "not_a_table.bin"
    not_a_table.write_bytes(data[:magic_end] + b"[1, 2]" + data[end:])
    for path in (other, cut, bad_magic, damaged, not_a_table, tmp_path / "missing.bin"):
        assert _load(where, path)["value"] is None, path.name
    assert _load(where, image, ("scaled_sine", "another"))["value"] is None


# --- the spectral-radius memo the plant FMU keeps beside its stable copy -----------------------
KEY = textwrap.dedent("""
    import sys
    from drillcosim.plant.model import spectral_key
    from drillcosim.plant.scene import load_scene
    print(spectral_key(load_scene(sys.argv[1]).plant, "full3d"))
""")


def test_the_spectral_memo_key_is_the_same_in_every_process_and_tells_scenes_apart():
    """A key that changed between processes would only miss; one shared by two parameter sets
    would give a model another's stable step: neither happens."""
    keys = {scene: {_py(KEY, scene) for _ in range(2)}
            for scene in ("paper_closed_loop", "paper_calibrated_closed_loop")}
    assert all(len(k) == 1 for k in keys.values()), keys
    assert keys["paper_closed_loop"] != keys["paper_calibrated_closed_loop"]


def test_a_remembered_spectral_radius_gives_the_computed_one_bit_for_bit():
    from drillcosim.plant import model as model_mod
    from drillcosim.plant.scene import load_scene

    scene = load_scene("paper_closed_loop")
    saved = dict(model_mod.SPECTRAL_RADII)
    try:
        model_mod.SPECTRAL_RADII.clear()
        computed = model_mod.DrillstringModel(scene.plant, scene.model).max_eigenvalue
        stored = json.loads(json.dumps(model_mod.SPECTRAL_RADII))  # the memo file's round trip
        assert list(stored.values()) == [computed]
        model_mod.SPECTRAL_RADII.clear()
        model_mod.SPECTRAL_RADII.update(stored)
        again = model_mod.DrillstringModel(scene.plant, scene.model)
        assert "initial_jacobian" not in again.__dict__
        assert again.max_eigenvalue == computed
        assert "initial_jacobian" not in again.__dict__          # taken from the memo
    finally:
        model_mod.SPECTRAL_RADII.clear()
        model_mod.SPECTRAL_RADII.update(saved)


ENABLED = textwrap.dedent(r"""
    import sys
    sys.path.insert(0, sys.argv[1])
    import numba
    numba.__version__ = sys.argv[2]
    from ssx import native
    print(native.enabled())
""")


@pytest.mark.parametrize(("release", "env", "expected"), [
    ("0.68.1", "1", "True"), ("0.58.0", "1", "True"),
    ("0.69.0", "1", "False"),       # a release whose helper registration is not checked
    ("0.57.1", "1", "False"), ("0.68.1", "0", "False")])
def test_images_only_with_the_checked_numba_releases_and_not_when_switched_off(
        tiny_image, release, env, expected, monkeypatch):
    monkeypatch.setenv("DRILLCOSIM_NATIVE_IMAGE", env)
    where, _image, _value = tiny_image
    assert _py(ENABLED, str(where), release) == expected
