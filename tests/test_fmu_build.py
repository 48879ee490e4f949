"""The FMU build (fmu_src/build.py): registry, atomic writes, vendoring, modelDescription."""

from __future__ import annotations

import ast
import json
import os
import re
import subprocess
import sys
import textwrap
import zipfile
from pathlib import Path
from xml.etree import ElementTree as ET

import pytest
from fmpy import read_model_description, simulate_fmu
from fmpy.validation import validate_fmu

from drillcosim.controller import LAWS
from drillcosim.fmu_src.build import (
    REGISTRY,
    UNIT_DEFINITIONS,
    FmuRecipe,
    base_units,
    build_all,
    build_one,
    finalize_model_description,
    shipped_modules,
    stale,
)
from drillcosim.fmu_src.platforms import select

pytestmark = [pytest.mark.needs_cc]


# ------------------------------------------------------------------------- registry
STRAIN = next(r for r in REGISTRY if r.name == "StrainController")
PLANT = next(r for r in REGISTRY if r.name == "DrillstringPlant")


def test_registry_entries() -> None:
    """The plant and one FMU per registered law (the generic adapter, one variant each)."""
    names = [s.name for s in REGISTRY]
    assert names == ["DrillstringPlant", *(law.FMU for law in LAWS)]
    modules = [s.slave_module for s in REGISTRY]
    assert len(set(modules)) == len(modules)  # pythonfmu: one module name per process
    assert PLANT.script == "fmu_src/drillstring_plant_fmu.py"
    assert dict(PLANT.vendored)["plant"] == "_dcs_plant_0_1_0"
    assert {r.script for r in REGISTRY if r is not PLANT} == {"fmu_src/law_fmu.py"}


@pytest.mark.parametrize("recipe", [STRAIN, PLANT], ids=lambda r: r.name)
def test_adapter_imports_the_registered_vendored_names_once(recipe) -> None:
    """Each canonical name an adapter imports is spelled once in it, and it is the recipe's
    (the build rewrites exactly those names to the shipped ones)."""
    text = recipe.script_path.read_text()
    tree = ast.parse(text)
    imported = {n.module for n in ast.walk(tree) if isinstance(n, ast.ImportFrom)}
    imported |= {a.name for n in ast.walk(tree) if isinstance(n, ast.Import) for a in n.names}
    strings = {n.value for n in ast.walk(tree) if isinstance(n, ast.Constant)
               and isinstance(n.value, str) and n.value.startswith("_dcs_")}
    for package, name in recipe.vendored:
        assert name in imported | strings, name
        assert Path(package).name not in imported
        code = "\n".join(line for line in text.splitlines() if not line.lstrip().startswith("#"))
        assert len(re.findall(rf"\b{name}\b", code.split('"""', 2)[-1])) == 1, name


def test_recipe_rejects_requirements_that_are_no_import_names() -> None:
    with pytest.raises(ValueError, match="import name"):
        FmuRecipe(name="X", script="x.py", requires=("numpy>=1",))


@pytest.mark.parametrize("bad", ["controller", "_dcs-x", "dcs_controller_0_1_0"])
def test_recipe_rejects_unversioned_or_invalid_vendored_names(bad: str) -> None:
    with pytest.raises(ValueError, match="_dcs_"):
        FmuRecipe(name="X", script="x.py", vendored=(("controller", bad),))


# ---------------------------------------------------------------------------- build
def test_build_all_builds_existing_and_skips_missing_scripts(
        tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    missing = FmuRecipe(name="NotYet", script="fmu_src/not_yet_written_fmu.py")
    built = build_all(tmp_path, recipes=(STRAIN, missing))
    assert built == [tmp_path.resolve() / "StrainController.fmu"]
    out = capsys.readouterr().out
    assert "skipping NotYet" in out and "not_yet_written_fmu.py" in out
    assert sorted(p.name for p in tmp_path.iterdir()) == ["StrainController.fmu"]  # no temp dirs
    assert validate_fmu(str(built[0])) == []


def test_build_replaces_atomically_and_keeps_old_fmu_on_failure(tmp_path: Path) -> None:
    first = build_one(STRAIN, tmp_path)
    guid1 = read_model_description(str(first)).guid
    second = build_one(STRAIN, tmp_path)
    assert second == first
    assert read_model_description(str(second)).guid != guid1  # replaced

    broken = tmp_path / "broken_src" / "broken_fmu.py"
    broken.parent.mkdir()
    broken.write_text("raise RuntimeError('adapter import fails')\n")
    target = tmp_path / "StrainController.fmu"
    before = target.read_bytes()
    with pytest.raises(RuntimeError, match="adapter import fails"):
        build_one(FmuRecipe(name="StrainController", script=str(broken)), tmp_path)
    assert target.read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["StrainController.fmu", "broken_src"]


def test_build_leaves_the_calling_process_untouched(tmp_path: Path) -> None:
    path_before = list(sys.path)
    modules_before = set(sys.modules)
    build_one(STRAIN, tmp_path)
    assert sys.path == path_before
    new = set(sys.modules) - modules_before
    assert not {m for m in new if m.startswith(("_dcs_", "strain_controller_fmu", "pythonfmu"))}


def test_cli(tmp_path: Path) -> None:
    proc = subprocess.run([sys.executable, "-m", "drillcosim.fmu_src.build", "--out",
                           str(tmp_path), "--only", "StrainController"], cwd=tmp_path,
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    with zipfile.ZipFile(tmp_path / "StrainController.fmu") as zf:
        names = zf.namelist()
        assert zf.read("resources/python_requires.txt").decode().split() == ["numpy"]
    # our wrapper only, for each platform with a compiler here: pythonfmu's binaries (a win64
    # one that cannot report errors) are gone
    assert [n for n in names if n.startswith("binaries/")] == [
        p.library_name("StrainController") for p in select().platforms]
    bad = subprocess.run([sys.executable, "-m", "drillcosim.fmu_src.build", "--out",
                          str(tmp_path), "--only", "Nope"], cwd=tmp_path, capture_output=True,
                         text=True, timeout=300)
    assert bad.returncode == 2 and "unknown FMU" in bad.stderr
    gone = subprocess.run([sys.executable, "-m", "drillcosim.fmu_src.build", "--out",
                           str(tmp_path), "--wrapper", "pythonfmu"], cwd=tmp_path,
                          capture_output=True, text=True, timeout=300)
    assert gone.returncode == 2 and "--wrapper" in gone.stderr  # the fallback is removed


def test_build_without_a_compiler_fails_in_one_line(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("CC", "no-such-compiler-dcs")
    with pytest.raises(RuntimeError, match="no-such-compiler-dcs"):
        build_one(STRAIN, tmp_path)
    proc = subprocess.run([sys.executable, "-m", "drillcosim.fmu_src.build", "--out",
                           str(tmp_path), "--only", "StrainController"], cwd=tmp_path,
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 1
    assert proc.stderr.count("\n") == 1 and "Traceback" not in proc.stderr, proc.stderr
    assert "no-such-compiler-dcs" in proc.stderr and "C compiler" in proc.stderr
    assert not list(tmp_path.iterdir())  # nothing written


def test_stale_knows_what_an_fmu_is_made_of(tmp_path: Path,
                                            project_fmus: dict[str, Path]) -> None:
    plant = PLANT
    names = {p.name for p in plant.sources()}
    assert {"drillstring_plant_fmu.py", "kernels.py", "fmi2_functions.c", "dcs_wrapper.h",
            "build.py", "paper_open_loop.toml"} <= names
    fmu = tmp_path / "DrillstringPlant.fmu"
    fmu.write_bytes(project_fmus["DrillstringPlant"].read_bytes())
    newest = max(p.stat().st_mtime for p in plant.sources())
    os.utime(fmu, (newest + 10, newest + 10))
    assert not stale(fmu, plant)
    os.utime(fmu, (newest - 10, newest - 10))
    assert stale(fmu, plant)  # older than a source
    assert stale(tmp_path / "missing.fmu", plant)
    old = tmp_path / "old" / "DrillstringPlant.fmu"  # an earlier build's FMU
    old.parent.mkdir()
    with zipfile.ZipFile(fmu) as src, zipfile.ZipFile(old, "w") as dst:
        for info in src.infolist():
            if info.filename != "resources/python_requires.txt":
                dst.writestr(info, src.read(info.filename))
    os.utime(old, (newest + 10, newest + 10))
    assert stale(old, plant)


# ------------------------------------------------------- registering one more FMU
DUMMY_ADAPTER = textwrap.dedent('''
    """A second FMU registered like the plant will be: vendored package + extra file."""
    import os

    from _dcs_dummy_0_1_0 import scale
    from _dcs_pythonfmu_0_7_0 import Fmi2Causality, Fmi2Slave, Fmi2Variability, Real
    from _dcs_pythonfmu_0_7_0.enums import Fmi2Initial


    class DummyScaler(Fmi2Slave):
        VARIABLE_UNITS = {"u": "m", "y": "N"}
        DIRECT_FEEDTHROUGH = {"y": ("u",)}

        def __init__(self, **kwargs):
            super().__init__(**kwargs)
            self.u = 0.0
            self.y = 0.0
            with open(os.path.join(self.resources, "factor.txt")) as f:
                self.factor = float(f.read())
            self.register_variable(Real("u", causality=Fmi2Causality.input,
                                        variability=Fmi2Variability.continuous))
            self.register_variable(Real("y", causality=Fmi2Causality.output,
                                        variability=Fmi2Variability.continuous,
                                        initial=Fmi2Initial.calculated))

        def do_step(self, current_time, step_size):
            self.y = scale(self.u, self.factor)
            return True
''')


def test_registering_another_fmu_with_vendored_package_and_extra_file(tmp_path: Path) -> None:
    src = tmp_path / "src"
    pkg = src / "dummypkg"
    pkg.mkdir(parents=True)
    (pkg / "__init__.py").write_text("from .core import scale\n")
    (pkg / "core.py").write_text("def scale(u, k):\n    return k * u\n")
    (src / "factor.txt").write_text("3.0")
    (src / "dummy_scaler_fmu.py").write_text(DUMMY_ADAPTER)
    spec = FmuRecipe(name="DummyScaler", script=str(src / "dummy_scaler_fmu.py"),
                   vendored=((str(pkg), "_dcs_dummy_0_1_0"),),
                   extra_files=(str(src / "factor.txt"),))
    fmu = build_one(spec, tmp_path / "out")
    names = zipfile.ZipFile(fmu).namelist()
    dummy = shipped_modules(fmu)["_dcs_dummy_0_1_0"]  # <canonical>_<build hash>
    assert dummy.startswith("_dcs_dummy_0_1_0_") and f"resources/{dummy}/core.py" in names
    assert "resources/factor.txt" in names
    assert not any(n.startswith("resources/dummypkg/") for n in names)
    assert validate_fmu(str(fmu)) == []
    md = read_model_description(str(fmu))
    y = next(v for v in md.modelVariables if v.name == "y")
    assert y.unit == "N"
    assert [v.name for v in md.outputs[0].dependencies] == ["u"]
    assert [u.variable.name for u in md.initialUnknowns] == ["y"]
    res = simulate_fmu(str(fmu), stop_time=0.002, step_size=1e-3, output_interval=1e-3,
                       start_values={"u": 2.0}, output=["y"])
    assert res["y"][-1] == 6.0


# ------------------------------------------------------------- modelDescription
MINIMAL_XML = b"""<?xml version="1.0" encoding="UTF-8"?>
<fmiModelDescription fmiVersion="2.0" modelName="M" guid="g">
  <CoSimulation modelIdentifier="M"/>
  <LogCategories><Category name="logAll"/></LogCategories>
  <ModelVariables>
    <ScalarVariable name="a" valueReference="0" causality="input" variability="continuous">
      <Real start="0"/></ScalarVariable>
    <ScalarVariable name="b" valueReference="1" causality="input" variability="continuous">
      <Real start="0"/></ScalarVariable>
    <ScalarVariable name="y" valueReference="2" causality="output" variability="continuous">
      <Real/></ScalarVariable>
    <ScalarVariable name="z" valueReference="3" causality="output" variability="continuous"
      initial="exact"><Real start="0"/></ScalarVariable>
    <ScalarVariable name="n" valueReference="4" causality="parameter" variability="fixed">
      <Integer start="1"/></ScalarVariable>
  </ModelVariables>
  <ModelStructure><Outputs><Unknown index="3"/><Unknown index="4"/></Outputs></ModelStructure>
</fmiModelDescription>"""


def test_finalize_model_description_units_and_structure() -> None:
    out = finalize_model_description(MINIMAL_XML, {"a": "m", "y": "N", "z": "N"},
                                     {"y": ("b", "a")})
    root = ET.fromstring(out)
    assert [c.tag for c in root][:3] == ["CoSimulation", "UnitDefinitions", "LogCategories"]
    units = {u.get("name"): u.find("BaseUnit").attrib for u in root.iter("Unit")}
    assert units == {"m": {"m": "1"}, "N": {"kg": "1", "m": "1", "s": "-2"}}
    reals = {sv.get("name"): sv.find("Real") for sv in root.iter("ScalarVariable")}
    assert reals["a"].get("unit") == "m" and reals["b"].get("unit") is None
    outputs = root.find("ModelStructure/Outputs")
    assert [u.attrib for u in outputs] == [{"index": "3", "dependencies": "2 1"},
                                          {"index": "4"}]
    assert [u.attrib for u in root.find("ModelStructure/InitialUnknowns")] == [{"index": "3"}]


@pytest.mark.parametrize(
    ("units", "feed", "message"),
    [
        ({"nope": "m"}, None, "unknown variable 'nope'"),
        ({"a": "furlong"}, None, "unit 'furlong'"),
        ({"n": "s"}, None, "not a Real"),
        ({}, {"a": ()}, "non-outputs"),
        ({}, {"y": ("z",)}, "non-inputs"),
    ],
)
def test_finalize_model_description_rejects_mistakes(units: dict, feed: dict | None,
                                                     message: str) -> None:
    with pytest.raises(ValueError, match=message):
        finalize_model_description(MINIMAL_XML, units, feed)


def test_unit_definitions_are_dimensionally_consistent() -> None:
    assert UNIT_DEFINITIONS["N.m"] == {"kg": 1, "m": 2, "s": -2}
    assert UNIT_DEFINITIONS["1"] == {}
    for name, exps in UNIT_DEFINITIONS.items():
        assert set(exps) <= {"kg", "m", "s", "A", "K", "mol", "cd", "rad"}, name
        assert base_units(name) == exps, name  # the parser agrees with the written-out table
    assert base_units("N.s") == {"kg": 1, "m": 1, "s": -1}
    for bad in ("furlong", "N.m/s/rad", "m^2", "N..m"):
        with pytest.raises(ValueError, match="unit"):
            base_units(bad)


def test_an_adapter_importing_generic_pythonfmu_is_refused(tmp_path: Path) -> None:
    script = tmp_path / "generic_fmu.py"
    script.write_text(DUMMY_ADAPTER.replace("_dcs_pythonfmu_0_7_0", "pythonfmu"))
    with pytest.raises(RuntimeError, match="_dcs_pythonfmu_0_7_0"):
        build_one(FmuRecipe(name="DummyScaler", script=str(script)), tmp_path / "out")


HOST_THEN_BUILD = textwrap.dedent("""
    import json, shutil, sys, zipfile
    from pathlib import Path
    from fmpy import extract, read_model_description
    from fmpy.fmi2 import FMU2Slave
    fmu, script, out = sys.argv[1], sys.argv[2], sys.argv[3]
    md = read_model_description(fmu)
    d = extract(fmu)
    s = FMU2Slave(guid=md.guid, unzipDirectory=d,
                  modelIdentifier=md.coSimulation.modelIdentifier, instanceName="x")
    s.instantiate(); s.setupExperiment(startTime=0.0)
    s.enterInitializationMode(); s.exitInitializationMode(); s.doStep(0.0, 1e-3)
    s.terminate(); s.freeInstance()
    shutil.rmtree(d)  # as fmpy.simulate_fmu does after a run
    generic = "pythonfmu" in sys.modules
    from pythonfmu import FmuBuilder  # the host's own copy, as a test process would
    import pythonfmu
    built = FmuBuilder.build_FMU(script, dest=out)
    print(json.dumps({"generic_after_fmu": generic, "pythonfmu": pythonfmu.__file__,
                      "names": zipfile.ZipFile(built).namelist()}))
""")


def test_an_fmu_loaded_in_a_python_host_leaves_its_pythonfmu_alone(
        project_fmus: dict[str, Path], tmp_path: Path) -> None:
    """Regression (fresh-machine failure): the root cause of the 3-file test FMUs.

    pythonfmu's builder ships ``resources/pythonfmu/``; an FMU loaded in-process imported it
    as ``pythonfmu`` from its unzip folder, and a later ``FmuBuilder`` in that process (whose
    ``HERE`` was the deleted folder) wrote FMUs without ``binaries/`` and without
    ``resources/pythonfmu/``. Our FMUs ship it only as ``_dcs_pythonfmu_0_7_0``.
    """
    script = tmp_path / "plain_slave.py"
    script.write_text(textwrap.dedent("""
        from pythonfmu import Fmi2Causality, Fmi2Slave, Real

        class PlainSlave(Fmi2Slave):
            def __init__(self, **kwargs):
                super().__init__(**kwargs)
                self.y = 1.0
                self.register_variable(Real("y", causality=Fmi2Causality.output))

            def do_step(self, current_time, step_size):
                return True
    """))
    proc = subprocess.run([sys.executable, "-c", HOST_THEN_BUILD,
                           str(project_fmus["StrainController"]), str(script), str(tmp_path)],
                          capture_output=True, text=True, timeout=300, cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr[-3000:]
    out = json.loads(proc.stdout.strip().splitlines()[-1])
    assert not out["generic_after_fmu"]
    assert "site-packages" in out["pythonfmu"]
    names = out["names"]
    assert any(n.startswith("binaries/linux64/") for n in names)
    assert "resources/pythonfmu/fmi2slave.py" in names
