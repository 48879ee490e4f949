"""Builds are isolated: two plant FMUs of different builds in one Python host each run their own
code, in either load order, and two instances of one build share its modules.

The second build is made from a copy of ``plant/`` whose ``hook_load`` output is patched to twice
the top spring's force (a real change of the shipped code, in a numba kernel): every output of
the patched build must equal the original's, except ``hook_load``, which must be exactly twice
the original's (a factor of 2 is exact in floating point). Before builds were isolated the
second FMU loaded in a process ran the first one's vendored package (one fixed module name).
Each load order runs in its own fresh Python (fmpy), as a user's comparison study would.
"""

from __future__ import annotations

import dataclasses
import json
import os
import shutil
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest
from fmpy import read_model_description

from drillcosim.fmu_src.build import (
    REGISTRY,
    TOML_VENDORED,
    build_one,
    module_names,
    shipped_modules,
)

pytestmark = [pytest.mark.needs_cc, pytest.mark.slow]

ROOT = Path(__file__).resolve().parents[1]
PLANT = next(r for r in REGISTRY if r.name == "DrillstringPlant")
CANONICAL = dict(PLANT.vendored)["plant"]
ORIGINAL_LINE = "    out[o + 3] = hook\n"
PATCHED_LINE = "    out[o + 3] = 2.0 * hook\n"

HOST = textwrap.dedent("""
    import json, sys
    from fmpy import extract, read_model_description
    from fmpy.fmi2 import FMU2Slave

    def open_instance(fmu, name):
        md = read_model_description(fmu)
        s = FMU2Slave(guid=md.guid, unzipDirectory=extract(fmu), instanceName=name,
                      modelIdentifier=md.coSimulation.modelIdentifier)
        vr = {v.name: v.valueReference for v in md.modelVariables}
        s.instantiate()
        s.setupExperiment(startTime=0.0)
        s.enterInitializationMode()
        s.setReal([vr["max_internal_step"]], [2.5e-4])
        s.exitInitializationMode()
        outs = [v.valueReference for v in md.modelVariables if v.causality == "output"]
        return s, vr, outs

    order = sys.argv[1:]  # (label, fmu) pairs, in load order
    pairs = list(zip(order[::2], order[1::2]))
    instances = [(label, *open_instance(fmu, label)) for label, fmu in pairs]  # all alive
    rows = {label: [] for label, *_ in instances}
    for k in range(10):  # interleaved steps: every instance runs while the others exist
        for label, s, vr, outs in instances:
            s.setReal([vr["actuator1_force_C"]], [1e3 * (k + 1)])
            s.doStep(k * 1e-3, 1e-3)
            rows[label].append(s.getReal(outs))
    names = sorted(m for m in sys.modules if m.startswith("_dcs_") and "." not in m)
    files = {m: sys.modules[m].__file__ for m in names}
    for _label, s, _vr, _outs in instances:
        s.terminate()
        s.freeInstance()
    print(json.dumps({"rows": rows, "modules": names, "files": files}))
""")


@pytest.fixture(scope="module")
def patched_plant(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A plant FMU built from a copy of ``plant/`` whose hook_load is doubled."""
    src = tmp_path_factory.mktemp("patched_src") / "plant"
    shutil.copytree(ROOT / "plant", src, ignore=shutil.ignore_patterns("__pycache__"))
    observables = src / "observables.py"
    text = observables.read_text()
    assert text.count(ORIGINAL_LINE) == 1  # the patch point still exists
    observables.write_text(text.replace(ORIGINAL_LINE, PATCHED_LINE))
    exclude = tuple(str(src / Path(e).relative_to("plant")) if e.startswith("plant/") else e
                    for e in PLANT.exclude)
    recipe = dataclasses.replace(PLANT, exclude=exclude,
                                 vendored=((str(src), CANONICAL), *PLANT.vendored[1:]))
    return build_one(recipe, tmp_path_factory.mktemp("patched_fmu"))


def run_host(*pairs: str) -> dict:
    proc = subprocess.run([sys.executable, "-c", HOST, *pairs], cwd=ROOT, capture_output=True,
                          text=True, timeout=600,
                          env=dict(os.environ, OPENBLAS_NUM_THREADS="1"))
    assert proc.returncode == 0, proc.stderr[-4000:]
    return json.loads(proc.stdout.strip().splitlines()[-1])


@pytest.mark.parametrize("first", ["original", "patched"])
def test_two_builds_in_one_host_each_run_their_own_code(
        project_fmus: dict[str, Path], patched_plant: Path, first: str) -> None:
    original = project_fmus["DrillstringPlant"]
    a, b = shipped_modules(original), shipped_modules(patched_plant)
    # names follow the code: the plant package and the adapter importing it differ; modules
    # whose code is the same in both builds (pythonfmu, the slave base class) keep one name
    changed = {CANONICAL, PLANT.slave_module}
    assert {k for k in a if a[k] != b[k]} == changed, (a, b)
    fmus = {"original": original, "patched": patched_plant}
    second = "patched" if first == "original" else "original"
    # the first build twice (two unzip folders, as two simulate_fmu calls make), the other once
    out = run_host(first, str(fmus[first]), second, str(fmus[second]), f"{first}_2",
                   str(fmus[first]))
    rows = {k: np.array(v) for k, v in out["rows"].items()}
    np.testing.assert_array_equal(rows[f"{first}_2"], rows[first])  # same build, same result
    names = [v.name for v in read_model_description(str(original)).modelVariables
             if v.causality == "output"]
    hook = names.index("hook_load")
    others = [j for j in range(len(names)) if j != hook]
    np.testing.assert_array_equal(rows["patched"][:, others], rows["original"][:, others])
    np.testing.assert_array_equal(rows["patched"][:, hook], 2.0 * rows["original"][:, hook])
    assert np.all(np.abs(rows["original"][:, hook]) > 1e3)  # a real signal, not zeros
    # two instances of one build share its modules: each build's modules are there once
    shipped = set(a.values()) | set(b.values())
    imported = {n for names in (a, b) for k, n in names.items()  # the TOML reader: 3.10 only
                if k != TOML_VENDORED or sys.version_info < (3, 11)}
    assert imported <= set(out["modules"]) <= shipped, out["modules"]
    assert out["files"][a[CANONICAL]] != out["files"][b[CANONICAL]]



def _stage(root: Path, files: dict[str, str]) -> Path:
    for rel, text in files.items():
        (root / rel).parent.mkdir(parents=True, exist_ok=True)
        (root / rel).write_text(text)
    return root


def test_shipped_names_follow_each_modules_code_and_imports(tmp_path: Path) -> None:
    """A name changes exactly when the module's code, or the code of a module it imports,
    changes; a cycle of imports is refused."""
    base = {"_dcs_a_1/__init__.py": "from . import k\n", "_dcs_a_1/k.py": "X = 1\n",
            "_dcs_b_1/__init__.py": "import _dcs_a_1\n",
            "_dcs_c_1.py": "import _dcs_b_1\nP = '_dcs_a_1'\n",
            "_dcs_d_1.py": "Y = 2\n"}
    canonical = ["_dcs_c_1", "_dcs_b_1", "_dcs_a_1", "_dcs_d_1"]  # any order
    first = module_names(_stage(tmp_path / "1", base), canonical)
    again = module_names(_stage(tmp_path / "2", base), canonical)
    assert first == again and len(set(first.values())) == 4
    assert all(v.startswith(k + "_") for k, v in first.items())
    leaf = module_names(_stage(tmp_path / "3", {**base, "_dcs_a_1/k.py": "X = 2\n"}), canonical)
    assert {k for k in first if first[k] != leaf[k]} == {"_dcs_a_1", "_dcs_b_1", "_dcs_c_1"}
    top = module_names(_stage(tmp_path / "4", {**base, "_dcs_c_1.py": "import _dcs_b_1\n"}),
                       canonical)
    assert {k for k in first if first[k] != top[k]} == {"_dcs_c_1"}
    cycle = {**base, "_dcs_a_1/k.py": "import _dcs_c_1\n"}
    with pytest.raises(RuntimeError, match="cycle"):
        module_names(_stage(tmp_path / "5", cycle), canonical)
