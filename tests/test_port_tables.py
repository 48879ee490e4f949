"""One port table per component: no code outside the tables formats or parses a variable name.

The tables are ``plant/signals.py`` (with ``plant/scene.py``'s parameter table, whose names it
forms there) and ``controller/ports.py``; everything else asks them. This test reads every
Python file of the package, the benchmarks and the examples' scripts and fails on

* a formatted variable name: an f-string that puts a number in a name of a numbered family
  (``f"body{b}_X"``, ``f"strain{s}_{a}"``, ``f"actuator{s}_force_{a}"``,
  ``f"gain_matrix_{i}_{j}"``, ``f"{side}_limit_{o}"``). (The study tables' per-site columns,
  ``site1_peak_force_N``, are no variables: ``cosim/study/scene_stats.py`` names them.)
* a parsed one: slicing or splitting a name to get its number back (``int(name[6:-2])``,
  ``name[8]``, ``n[len(PLANT) + 5:]``, ``name.split("_")[2:]``).

It also checks the two declarations of the row type (``plant.signals.Port`` and
``controller.ports.Port``: the packages are vendored apart) have the same fields.
"""

from __future__ import annotations

import re
from pathlib import Path

from fmpy import read_model_description

from drillcosim.controller import ports as controller_ports
from drillcosim.fmu_src.interface_doc import plant_ports
from drillcosim.plant import signals
from drillcosim.plant.params import PlantParams
from drillcosim.plant.scene import load_scene

ROOT = Path(__file__).resolve().parents[1]
#: The tables: the one place each side spells a numbered name.
TABLES = {ROOT / "plant" / "signals.py", ROOT / "controller" / "ports.py"}
SEARCHED = ("plant", "controller", "fmu_src", "cosim", "drillcosim", "benchmarks", "examples")

FORMATTED = re.compile(
    r"""f["'][^"']*(?:body|strain|actuator|gain_matrix_)\{[^}]*\}_"""  # body{b}_X ...
    r"""|f["'][^"']*\{[^}]*\}_limit_\{""")                                  # {side}_limit_{o}
PARSED = re.compile(
    r"""\bint\(\s*(?:name|n|var|v)\[|\b(?:name|n)\[\s*-?\d*\s*:\s*-?\d+\s*\]"""
    r"""|\b(?:name|n)\[\s*\d+\s*\]|\[len\((?:PLANT|CONTROLLER)\)"""
    r"""|\bname\.split\("_"\)|\bn\[len\(""")


def _sources() -> list[Path]:
    files = []
    for top in SEARCHED:
        files += sorted(p for p in (ROOT / top).rglob("*.py") if "__pycache__" not in p.parts)
    return [p for p in files if p not in TABLES]


def test_no_code_outside_the_tables_formats_or_parses_a_variable_name() -> None:
    found = []
    for path in _sources():
        for k, line in enumerate(path.read_text(encoding="utf-8").splitlines(), start=1):
            code = line.split("#", 1)[0]
            if FORMATTED.search(code) or PARSED.search(code):
                found.append(f"{path.relative_to(ROOT)}:{k}: {line.strip()}")
    assert not found, "\n".join(found)


def test_the_patterns_catch_what_they_are_for() -> None:
    """The searches find the forms the plug-in rework removed (so a pass above means something)."""
    for bad in ('column(data, PLANT, f"body{b}_X")', 'f"strain{s}_{a}"',
                'f"actuator{s}_force_{a}"', 'f"gain_matrix_{i}_{j}"',
                'f"{side}_limit_{o}"'):
        assert FORMATTED.search(bad), bad
    for bad in ("site, axis = int(name[6:-2]), name[-1]", "site = name[8]",
                'int(n[len(PLANT) + 5:].split("_")[0])', 'i, j = name.split("_")[2:]'):
        assert PARSED.search(bad), bad
    for good in ('body_signal(b, "X")', 'f"{prefix}.{key}"', "names[0]", 'f"site {s}"'):
        assert not (FORMATTED.search(good) or PARSED.search(good)), good


def test_the_two_row_types_have_the_same_fields() -> None:
    assert signals.Port._fields == controller_ports.Port._fields
    assert signals.Port._field_defaults == controller_ports.Port._field_defaults


def test_the_plant_fmu_declares_its_port_table(project_fmus) -> None:
    """The default plant FMU registers exactly the plant's table, in order (the README's
    generated tables are that table)."""
    md = read_model_description(str(project_fmus["DrillstringPlant"]))
    got = [(v.name, v.causality, v.variability, v.type, v.unit or "", v.description)
           for v in md.modelVariables]
    ports = plant_ports()
    want = [(p.name, p.causality, p.variability, p.type,
             p.unit if p.type == "Real" else "", p.description) for p in ports]
    assert got == want
    for v, p in zip(md.modelVariables, ports):
        if p.start is None:
            assert v.initial == "calculated" and v.start is None, p.name
        elif p.type == "Real":
            assert float(v.start) == p.start, p.name
        else:
            assert str(v.start).lower() == str(p.start).lower(), p.name


def test_the_default_plant_table_is_the_default_scenes() -> None:
    """The default FMU's layout is PlantParams' defaults, which paper_open_loop keeps."""
    scene = load_scene("paper_open_loop").plant
    assert scene.contact_bodies == PlantParams().contact_bodies
    assert scene.actuator_joints == PlantParams().actuator_joints


#: A vendored package's module name (``_dcs_plant_0_1_0``, ``_dcs_pythonfmu_0_7_0``, ...).
VENDORED = re.compile(r"\b_dcs_[a-z_]+?_\d+_\d+_\d+\b")


def _code_lines(path: Path) -> list[str]:
    """The lines of ``path`` outside docstrings, without comments."""
    lines, in_doc = [], False
    for line in path.read_text(encoding="utf-8").splitlines():
        quotes = line.count('"""')
        if in_doc or quotes:
            in_doc = in_doc != (quotes % 2 == 1)
            continue
        lines.append(line.split("#", 1)[0])
    return lines


def test_a_vendored_module_name_is_spelled_once_per_file() -> None:
    """Code names a vendored package at most once per file (its import; build.py's rule
    ``vendored(folder)`` makes the names), not at every use."""
    found = []
    for path in _sources():
        names = [m for line in _code_lines(path) for m in VENDORED.findall(line)]
        found += [f"{path.relative_to(ROOT)}: {n} x{names.count(n)}" for n in set(names)
                  if names.count(n) > 1]
    assert not found, "\n".join(found)
    assert VENDORED.findall('import _dcs_slave_support_0_1_0 as support') == [
        "_dcs_slave_support_0_1_0"]
