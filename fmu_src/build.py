"""Build the project's FMUs with pythonfmu: ``python -m drillcosim.fmu_src.build --out DIR``.

Every FMU is described by one :class:`FmuRecipe` in :data:`REGISTRY`. ``build_all``
builds each registered FMU whose adapter script exists (an entry whose script is
missing is skipped with a printed note) and returns the written paths.

Vendoring without shadowing
---------------------------
An FMU must run in a Python that has only numpy, so the packages its adapter
needs are shipped inside it. pythonfmu puts every instance's ``resources/``
first on ``sys.path``; a package shipped as ``resources/controller/`` would
therefore shadow (or be shadowed by) a ``controller`` package the host process
imports. Each package is instead copied to ``resources/<vendored name>/`` with a
unique, versioned name (``controller/`` -> ``resources/_dcs_controller_0_1_0/``)
and the adapter imports it by that name. This needs all intra-package imports
to be relative (tested). At build time the copies are staged in a temporary
folder that is put first on ``sys.path`` so pythonfmu can import the adapter.

Builds isolated from each other
-------------------------------
A Python host imports a module name once (``sys.modules``): two FMUs that ship different code
under one name would both run the code of the one loaded first. So the names in the source
(``_dcs_plant_0_1_0``, ``_dcs_pythonfmu_0_7_0``, the slave module ``_dcs_<script>_<version>``)
are canonical names only: the build ships each module as ``<canonical name>_<hash>``
(:data:`BUILD_HASH_LENGTH` hex digits), the hash taken over the module's own files with the
names of the modules it imports already replaced by their shipped names (:func:`module_names`),
and rewrites the names in every shipped ``.py`` file. Two builds whose code differs in any
byte run their own code in one process, in either load order; instances of one build share
their modules, and so do builds that ship the same code (the scene variants of one plant
share the plant package, and numba's compiled kernels of it). ``resources/dcs_build.json``
records the hash of the whole build (:func:`build_hash`) and the names (:func:`shipped_modules`).

Each FMU is built in a fresh Python subprocess (pythonfmu imports and
instantiates the adapter and leaves entries on ``sys.path``; the calling process
stays clean) inside a temporary folder next to the target, and moved into place
with ``os.replace`` (atomic: readers see the old or the new FMU, never half).

After pythonfmu, ``modelDescription.xml`` is completed (pythonfmu 0.7.0 writes
no units and no output dependencies): units of Real variables from the adapter
class attribute ``VARIABLE_UNITS`` (name -> unit) with matching
``<UnitDefinitions>``, ``ModelStructure/Outputs`` dependencies from the optional
class attribute ``DIRECT_FEEDTHROUGH`` (output name -> input names; an output not
listed gets no ``dependencies`` attribute, meaning "depends on all"), and
``<InitialUnknowns>`` for outputs whose ``initial`` is not ``exact``.

FMI wrapper
-----------
pythonfmu's prebuilt C++ binaries are replaced by our C wrapper (:mod:`fmu_src.wrapper`,
compiled here against the stable ABI of CPython 3.10: one binary per platform for CPython 3.10
to 3.13, stated at the end of the modelDescription's ``description``), which returns fmi2Error
for exceptions and for statuses the adapter reports, survives exceptions, finds a Python in
hosts without one and moves Real inputs/outputs without Python calls. The platforms are those
of :func:`fmu_src.platforms.select`: ``binaries/linux64/<name>.so`` (``$CC`` or ``gcc``) and
``binaries/win64/<name>.dll`` (cross-compiled with mingw-w64), by default every one whose
compiler is found (:func:`build_all` prints one line naming a skipped one and why). Without any
C compiler the build stops with a one-line message.

The registry
------------
:data:`REGISTRY` is the plant's recipe (:data:`PLANT_RECIPE`) and one recipe per registered
controller law (``controller/registry.py``; :func:`law_recipe`: the generic adapter
``fmu_src/law_fmu.py`` as the variant ``<law.FMU>`` for the law's default layout): a new law
needs no edit here. A recipe of another FMU, e.g.::

    FmuRecipe(name="DrillstringPlant", script="fmu_src/drillstring_plant_fmu.py",
              vendored=(vendored("plant"),), extra_files=("scenes/x.toml",),
              requires=("numpy", "scipy", "numba"))

``name`` must equal the adapter class name (= modelIdentifier = file stem of
the ``.fmu``); the adapter imports the vendored package by its canonical name
(:func:`vendored`: ``_dcs_<folder>_0_1_0``); ``extra_files`` (paths
relative to the repository root, files or folders) land in ``resources/`` under
their own base name.

Variants: one adapter, another interface
----------------------------------------
An FMU whose interface is a variant of an adapter's (the plant built for a scene's layout,
the controller for its number of sites) is a recipe with ``base`` (the adapter class) and
``class_attributes`` (JSON: the layout): the build generates the slave module, a subclass
named ``name`` of ``base`` carrying those attributes, and ships the adapter script beside it
under its usual module name. The wrapper imports a slave module once per process
(``sys.modules``), so every variant has its own module name (:attr:`FmuRecipe.slave_module`,
with a hash of the layout): two variants, and the default FMU, live in one process. The
adapter module they share is the same file in every FMU of this version. ``resource_files``
copies single files to chosen places in ``resources/`` (e.g. a user's scene file into
``resources/scenes/``).
"""

from __future__ import annotations

import argparse
import fnmatch
import hashlib
import json
import math
import os
import pprint
import re
import shutil
import subprocess
import sys
import tempfile
import zipfile
from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any
from xml.etree import ElementTree as ET

from drillcosim._toolchain import user_cache
from drillcosim.controller.registry import LAWS
from drillcosim.fmu_src.platforms import Selection, select

__all__ = [
    "DEFAULT_OUT",
    "REGISTRY",
    "ROOT",
    "UNIT_DEFINITIONS",
    "base_units",
    "FmuRecipe",
    "build_all",
    "build_one",
    "build_hash",
    "module_names",
    "finalize_model_description",
    "main",
    "shipped_modules",
    "stale",
]

#: The drillcosim package root: the repository in a checkout (editable install), the installed
#: ``drillcosim/`` folder otherwise; both hold ``plant/``, ``controller/``, ``fmu_src/``, ``scenes/``.
ROOT = Path(__file__).resolve().parents[1]


def _checkout() -> bool:
    """Whether ROOT is a source checkout (its ``pyproject.toml`` names this project)."""
    try:
        return 'name = "drillcosim"' in (ROOT / "pyproject.toml").read_text()
    except OSError:
        return False


def default_out() -> Path:
    """Where FMUs are built and found by default.

    ``build/fmus/`` of the checkout; for an installed package (no checkout) a per-user folder
    named by the version, ``<user_cache()>/fmus/<version>``, so ``drillcosim build`` and
    ``drillcosim run`` agree from any working directory.
    """
    if _checkout():
        return ROOT / "build" / "fmus"
    from drillcosim._version import __version__

    return user_cache() / "fmus" / __version__


DEFAULT_OUT = default_out()

#: Import name under which pythonfmu is shipped inside every FMU. pythonfmu's builder ships it
#: as ``resources/pythonfmu/``; an FMU loaded in a Python host would then put a ``pythonfmu``
#: from its (temporary) unzip folder into the host's ``sys.modules``, shadowing the host's own
#: copy for the rest of the process (a later FmuBuilder then wrote FMUs without binaries). The
#: adapters import it under this unique, versioned name instead, and the build replaces
#: ``resources/pythonfmu/`` by it.
PYTHONFMU_VENDORED = "_dcs_pythonfmu_0_7_0"

#: A TOML reader for Python 3.10 hosts, which have no ``tomllib``: a vendored package that does
#: ``import tomli as ...`` (plant/scene.py below 3.11) gets this copy instead, so the FMU needs
#: no ``tomli`` in the host. Staged from the builder's ``tomli`` if installed, else from the
#: standard library's ``tomllib`` (tomli's code, pure Python, runs on 3.10: tested).
TOML_VENDORED = "_dcs_tomli"

#: Hex digits of the build hash appended to every shipped module name (see the module docstring).
BUILD_HASH_LENGTH = 12
#: The record of a build's hash and module names inside the FMU.
BUILD_INFO = "resources/dcs_build.json"

#: SI base-unit exponents of the unit symbols an FMU unit is made of (FMI 2.0 BaseUnit).
UNIT_SYMBOLS: dict[str, dict[str, int]] = {
    "s": {"s": 1}, "m": {"m": 1}, "kg": {"kg": 1}, "rad": {"rad": 1},
    "N": {"kg": 1, "m": 1, "s": -2}, "Pa": {"kg": 1, "m": -1, "s": -2},
    "J": {"kg": 1, "m": 2, "s": -2}, "W": {"kg": 1, "m": 2, "s": -3},
}


def base_units(unit: str) -> dict[str, int]:
    """SI base-unit exponents of an FMU unit name: factors of :data:`UNIT_SYMBOLS` joined by
    ``.``, each with an optional integer power (``m2``, ``s2``), a denominator after one ``/``
    (``"N.m.s/rad"``); ``"1"`` is dimensionless. ValueError for anything else."""
    num, _, den = unit.partition("/")
    out: dict[str, int] = {}
    for part, sign in ((num, 1), (den, -1)):
        if part in ("1", "") and (sign == 1 or not part and not den):
            continue
        for factor in part.split("."):
            match = re.fullmatch(r"([A-Za-z]+)(\d*)", factor)
            if match is None or match.group(1) not in UNIT_SYMBOLS:
                raise ValueError(f"unit {unit!r}: {factor!r} is not one of "
                                 f"{', '.join(UNIT_SYMBOLS)} with an optional power")
            power = sign * int(match.group(2) or 1)
            for base, exp in UNIT_SYMBOLS[match.group(1)].items():
                out[base] = out.get(base, 0) + power * exp
    return {k: v for k, v in out.items() if v}


#: SI base-unit exponents of the units the project's FMUs declare, written out (a cross-check
#: of :func:`base_units`, which the build uses for any unit).
UNIT_DEFINITIONS: dict[str, dict[str, int]] = {
    "1": {},
    "s": {"s": 1},
    "1/s": {"s": -1},
    "m": {"m": 1},
    "m/s": {"m": 1, "s": -1},
    "m/s2": {"m": 1, "s": -2},
    "kg": {"kg": 1},
    "kg.m": {"kg": 1, "m": 1},
    "kg/m3": {"kg": 1, "m": -3},
    "kg.m2": {"kg": 1, "m": 2},
    "rad": {"rad": 1},
    "rad/s": {"rad": 1, "s": -1},
    "rad/s2": {"rad": 1, "s": -2},
    "N": {"kg": 1, "m": 1, "s": -2},
    "N/m": {"kg": 1, "s": -2},
    "N.s/m": {"kg": 1, "s": -1},
    "N.s/m2": {"kg": 1, "m": -1, "s": -1},
    "N.m": {"kg": 1, "m": 2, "s": -2},
    "N.m/rad": {"kg": 1, "m": 2, "s": -2, "rad": -1},
    "N.m.s/rad": {"kg": 1, "m": 2, "s": -1, "rad": -1},
    "Pa": {"kg": 1, "m": -1, "s": -2},
    "W": {"kg": 1, "m": 2, "s": -3},
    "J": {"kg": 1, "m": 2, "s": -2},
}

_DEFAULT_OPTIONS: tuple[tuple[str, bool], ...] = (
    ("canGetAndSetFMUstate", True),
    ("canSerializeFMUstate", True),
)


@dataclass(frozen=True)
class FmuRecipe:
    """How to build one FMU (not to be confused with :class:`cosim.master.system.FmuSpec`, an
    FMU placed in a co-simulation system).

    Parameters
    ----------
    name : str
        Adapter class name = FMI modelIdentifier = ``<name>.fmu``.
    script : str
        Adapter script: absolute, or relative to :data:`ROOT`. It is shipped as the slave
        module :attr:`slave_module` (a unique ``_dcs_`` name, so an FMU loaded in a Python
        host never adds a generic module name to its ``sys.modules``).
    vendored : tuple of (str, str)
        ``(package folder relative to the root, vendored import name)``; each
        package is shipped as ``resources/<vendored import name>/``. The name must
        start with ``_dcs_`` and carry a version (e.g. ``_dcs_plant_0_1_0``).
    extra_files : tuple of str
        Further files or folders (relative to the root) copied into ``resources/``.
    options : tuple of (str, bool)
        pythonfmu model options (``<CoSimulation>`` capability flags).
    requires : tuple of str
        Modules (import names) a Python must have to run the FMU; a host without Python
        checks its candidates for them (``resources/python_requires.txt``).
    exclude : tuple of str
        Files of the vendored packages and the ``extra_files`` folders (relative to the root;
        ``fnmatch`` patterns, e.g. ``scenes/*.json``) left out of the FMU: code the FMU never
        imports (tests' and benchmarks' reference implementations, analysis tools), data it
        never reads.
    base : str
        For a variant (see the module docstring): the adapter class in ``script`` that the
        generated class ``name`` derives from; ``""`` (default): ``script`` defines ``name``.
    class_attributes : str
        For a variant: a JSON object, the class attributes of the generated class (JSON
        values: numbers, strings, lists, objects).
    resource_files : tuple of (str, str)
        ``(source file, destination relative to resources/)``: single files placed where the
        adapter looks for them (copied after ``extra_files``, replacing a file of that name).
    """

    name: str
    script: str
    vendored: tuple[tuple[str, str], ...] = ()
    extra_files: tuple[str, ...] = ()
    options: tuple[tuple[str, bool], ...] = field(default=_DEFAULT_OPTIONS)
    requires: tuple[str, ...] = ()
    exclude: tuple[str, ...] = ()
    base: str = ""
    class_attributes: str = ""
    resource_files: tuple[tuple[str, str], ...] = ()

    def __post_init__(self) -> None:
        if not self.name.isidentifier():
            raise ValueError(f"FMU name {self.name!r} is not a Python identifier")
        if self.base:
            if not self.base.isidentifier() or self.base == self.name:
                raise ValueError(f"base {self.base!r} must be the adapter class (an identifier "
                                 f"other than the variant's name {self.name!r})")
            attributes = json.loads(self.class_attributes or "{}")
            if not isinstance(attributes, dict) or not all(
                    isinstance(k, str) and k.isidentifier() for k in attributes):
                raise ValueError("class_attributes must be a JSON object of identifiers")
        elif self.class_attributes:
            raise ValueError("class_attributes need a base class (a variant)")
        for _src, dest in self.resource_files:
            parts = Path(dest).parts
            if Path(dest).is_absolute() or ".." in parts or not parts:
                raise ValueError(f"resource_files: destination {dest!r} must be a relative "
                                 "path inside resources/")
        for _package, vname in self.vendored:
            if not (vname.isidentifier() and vname.startswith("_dcs_")):
                raise ValueError(f"vendored name {vname!r} must be an identifier starting "
                                 f"with '_dcs_' (e.g. '_dcs_plant_0_1_0')")
        for module in self.requires:
            if not all(part.isidentifier() for part in module.split(".")):
                raise ValueError(f"requires: {module!r} is not an import name")

    @property
    def script_path(self) -> Path:
        """Path: absolute path of the adapter script."""
        path = Path(self.script)
        return path if path.is_absolute() else ROOT / path

    def sources(self) -> list[Path]:
        """Every file the FMU is made of: the adapter, the shipped package files, the extra
        files, the wrapper's C sources and this build module."""
        from drillcosim.fmu_src.wrapper import sources as wrapper_sources

        files = [self.script_path, Path(__file__).resolve(), *wrapper_sources()]
        for package, _ in self.vendored:
            files += [p for p in sorted((ROOT / package).rglob("*.py"))
                      if "__pycache__" not in p.parts and not self.excludes(p)]
        for extra in self.extra_files:
            path = ROOT / extra
            files += (sorted(p for p in path.rglob("*") if p.is_file() and not self.excludes(p))
                      if path.is_dir() else [path])
        files += [ROOT / src for src, _dest in self.resource_files]
        return files

    def excludes(self, path: Path) -> bool:
        """Whether ``path`` (a file under the root) is one of :attr:`exclude`."""
        try:
            rel = Path(path).resolve().relative_to(ROOT.resolve()).as_posix()
        except ValueError:
            return False
        return any(fnmatch.fnmatchcase(rel, pattern) for pattern in self.exclude)

    @property
    def script_module(self) -> str:
        """str: import name of the adapter script inside the FMU, ``_dcs_<stem>_<version>``."""
        from drillcosim._version import __version__

        return f"_dcs_{self.script_path.stem}_{__version__.replace('.', '_')}"

    @property
    def slave_module(self) -> str:
        """str: the module the wrapper imports: :attr:`script_module`, or for a variant
        ``_dcs_<name>_<hash of base and attributes>_<version>`` (unique per layout)."""
        if not self.base:
            return self.script_module
        from drillcosim._version import __version__

        digest = hashlib.sha256(json.dumps([self.name, self.base, self.class_attributes])
                                .encode()).hexdigest()[:10]
        return f"_dcs_{self.name.lower()}_{digest}_{__version__.replace('.', '_')}"

    def variant_source(self) -> str:
        """Python source of a variant's slave module: the subclass ``name`` of ``base``."""
        attributes = json.loads(self.class_attributes or "{}")
        lines = [f'"""{self.name}: a variant of {self.base} generated by drillcosim\'s FMU '
                 f'build (fmu_src/build.py); the class attributes are its layout."""', "",
                 f"from {self.script_module} import {self.base}", "", "",
                 f"class {self.name}({self.base}):",
                 f'    """{self.base} with the layout below."""', ""]
        for key, value in attributes.items():
            text = pprint.pformat(value, width=92, sort_dicts=False)
            lines.append(f"    {key} = " + text.replace("\n", "\n" + " " * (7 + len(key))))
        return "\n".join(lines) + "\n"


#: The version part of the canonical names the adapters import the vendored packages under.
PACKAGES_VERSION = "0_1_0"
#: The adapter of every controller law (``controller/registry.py``): a variant per law and layout.
LAW_ADAPTER = "fmu_src/law_fmu.py"


def vendored(folder: str) -> tuple[str, str]:
    """``(folder, canonical name)`` of a vendored package: ``_dcs_<folder's name>_0_1_0``."""
    return folder, f"_dcs_{Path(folder).name}_{PACKAGES_VERSION}"


def law_recipe(law: type, layout: Mapping[str, Any] | None = None, name: str = "",
               resource: str | Path = "") -> FmuRecipe:
    """The recipe of a registered law's FMU (``controller/registry.py``): the generic adapter
    :data:`LAW_ADAPTER` as the variant ``name`` (default the law's ``FMU``) with the class
    attributes ``KIND`` and ``LAYOUT`` (default the law's default layout); a law with a
    resource file carries ``resource`` (default its ``DEFAULT_RESOURCE``)."""
    layout = law.default_layout() if layout is None else dict(layout)
    files: tuple[tuple[str, str], ...] = ()
    if law.RESOURCE:
        src = Path(resource) if resource else Path("controller") / law.DEFAULT_RESOURCE
        files = ((str(src), law.RESOURCE),)
    return FmuRecipe(
        name=name or law.FMU, script=LAW_ADAPTER,
        vendored=(vendored("controller"), vendored("fmu_src/slave_support")),
        requires=("numpy",), base="LawController",
        class_attributes=json.dumps({"KIND": law.KIND, "LAYOUT": layout}), resource_files=files)


#: The plant's FMU.
PLANT_RECIPE = FmuRecipe(
    name="DrillstringPlant",
    script="fmu_src/drillstring_plant_fmu.py",
    vendored=(vendored("plant"), vendored("fmu_src/slave_support")),
    extra_files=("scenes",),
    requires=("numpy", "scipy", "numba"),
    exclude=("scenes/*.json",),   # controller matrices (the plant reads only the TOML)
)

#: The FMUs of the project: the plant, and the default FMU of every registered controller law.
REGISTRY: tuple[FmuRecipe, ...] = (PLANT_RECIPE, *(law_recipe(law) for law in LAWS))


# ------------------------------------------------------------------ modelDescription
def finalize_model_description(
    xml: bytes,
    units: Mapping[str, str],
    direct_feedthrough: Mapping[str, Sequence[str]] | None = None,
    runtime_note: str = "",
    ranges: Mapping[str, tuple[float, float]] | None = None,
) -> bytes:
    """Add units, unit definitions and output dependencies to a modelDescription.

    Parameters
    ----------
    xml : bytes
        modelDescription.xml as written by pythonfmu.
    units : mapping of str to str
        Variable name -> unit (:func:`base_units` knows it); Real variables only.
    direct_feedthrough : mapping of str to sequence of str, optional
        Output name -> names of the inputs it depends on directly. Outputs not
        in the mapping (or all, if None) get no ``dependencies`` attribute.
    runtime_note : str
        Appended to the model's ``description`` (e.g. the Python versions it runs in).
    ranges : mapping of str to (float, float), optional
        Variable name -> declared ``(min, max)`` (Real or Integer; an infinite bound is not
        written).

    Returns
    -------
    bytes
        The completed modelDescription.xml (UTF-8).

    Raises
    ------
    ValueError
        Unknown variable or unit names, or a dependency that is not an input.
    """
    root = ET.fromstring(xml)
    if runtime_note:
        text = root.get("description", "").rstrip()
        root.set("description", f"{text} {runtime_note}".strip())
    variables = root.find("ModelVariables")
    if variables is None:
        raise ValueError("modelDescription.xml has no <ModelVariables>")
    svs = list(variables.findall("ScalarVariable"))
    index = {sv.get("name"): i + 1 for i, sv in enumerate(svs)}
    by_name = {sv.get("name"): sv for sv in svs}

    used_units: list[str] = []
    for name, unit in units.items():
        if name not in by_name:
            raise ValueError(f"VARIABLE_UNITS names unknown variable {name!r}")
        base_units(unit)  # ValueError naming it
        real = by_name[name].find("Real")
        if real is None:
            raise ValueError(f"variable {name!r} has a unit but is not a Real")
        real.set("unit", unit)
        if unit not in used_units:
            used_units.append(unit)

    for name, bounds in (ranges or {}).items():
        if name not in by_name:
            raise ValueError(f"VARIABLE_RANGES names unknown variable {name!r}")
        node = by_name[name].find("Real")
        if node is None:
            node = by_name[name].find("Integer")
        if node is None:
            raise ValueError(f"variable {name!r} has a range but is not a Real or an Integer")
        for attr, bound in zip(("min", "max"), bounds):
            if math.isfinite(bound):
                node.set(attr, repr(float(bound)) if node.tag == "Real" else str(int(bound)))

    for old in root.findall("UnitDefinitions"):
        root.remove(old)
    if used_units:
        unit_defs = ET.Element("UnitDefinitions")
        for unit in sorted(used_units):
            node = ET.SubElement(unit_defs, "Unit", name=unit)
            ET.SubElement(node, "BaseUnit",
                          {k: str(v) for k, v in base_units(unit).items()})
        position = 0
        for i, child in enumerate(list(root)):
            if child.tag in ("ModelExchange", "CoSimulation"):
                position = i + 1
        root.insert(position, unit_defs)

    structure = root.find("ModelStructure")
    if structure is None:
        structure = ET.SubElement(root, "ModelStructure")
    for tag in ("Outputs", "Derivatives", "InitialUnknowns"):
        for old in structure.findall(tag):
            structure.remove(old)
    outputs = [sv for sv in svs if sv.get("causality") == "output"]
    inputs = {sv.get("name") for sv in svs if sv.get("causality") == "input"}
    feed = dict(direct_feedthrough or {})
    unknown_outputs = set(feed) - {sv.get("name") for sv in outputs}
    if unknown_outputs:
        raise ValueError(f"DIRECT_FEEDTHROUGH names non-outputs {sorted(unknown_outputs)}")
    if outputs:
        node = ET.SubElement(structure, "Outputs")
        for sv in outputs:
            attrib = {"index": str(index[sv.get("name")])}
            if direct_feedthrough is not None and sv.get("name") in feed:
                deps = list(feed[sv.get("name")])
                bad = [d for d in deps if d not in inputs]
                if bad:
                    raise ValueError(f"{sv.get('name')!r} depends on non-inputs {bad}")
                attrib["dependencies"] = " ".join(str(index[d]) for d in deps)
            ET.SubElement(node, "Unknown", attrib)
    initial_unknowns = [
        sv for sv in svs
        if (sv.get("causality") == "output" and sv.get("initial") != "exact")
        or sv.get("causality") == "calculatedParameter"
    ]
    if initial_unknowns:
        node = ET.SubElement(structure, "InitialUnknowns")
        for sv in initial_unknowns:
            ET.SubElement(node, "Unknown", index=str(index[sv.get("name")]))

    ET.indent(root, space="  ")
    return ET.tostring(root, encoding="UTF-8", xml_declaration=True)


def _drop_zip_members(fmu: Path, prefix: str) -> None:
    """Remove every member whose name starts with ``prefix`` (rewrites the archive)."""
    tmp = fmu.with_suffix(".tmp")
    with zipfile.ZipFile(fmu) as src, zipfile.ZipFile(tmp, "w", zipfile.ZIP_DEFLATED) as dst:
        for info in src.infolist():
            if not info.filename.startswith(prefix):
                dst.writestr(info.filename, src.read(info.filename),
                             compress_type=zipfile.ZIP_DEFLATED)
    os.replace(tmp, fmu)


def _rewrite_zip_member(fmu: Path, member: str, data: bytes) -> None:
    """Replace one member of a zip file (rewrites the archive)."""
    tmp = fmu.with_suffix(".tmp")
    with zipfile.ZipFile(fmu) as src, zipfile.ZipFile(tmp, "w", zipfile.ZIP_DEFLATED) as dst:
        for info in src.infolist():
            payload = data if info.filename == member else src.read(info.filename)
            dst.writestr(info.filename, payload, compress_type=zipfile.ZIP_DEFLATED)
    os.replace(tmp, fmu)


# -------------------------------------------------------------------------- worker
def _vendor(recipe: FmuRecipe, package: str, dst: Path) -> None:
    """Copy one vendored package to ``dst`` without caches and the recipe's excluded files."""
    src = ROOT / package
    if not (src / "__init__.py").is_file():
        raise FileNotFoundError(f"vendored package {src} has no __init__.py")
    shutil.copytree(src, dst, ignore=_ignore(recipe))


def _ignore(recipe: FmuRecipe):
    """``copytree`` ignore: caches and the recipe's excluded files."""
    def ignore(folder: str, names: list[str]) -> set[str]:
        return {n for n in names if n == "__pycache__" or n.endswith(".pyc")
                or recipe.excludes(Path(folder) / n)}

    return ignore


def _stage_resources(recipe: FmuRecipe, dest: Path) -> list[Path]:
    """Copy ``extra_files`` then ``resource_files`` into ``dest``; its top-level entries."""
    dest.mkdir(parents=True)
    for extra in recipe.extra_files:
        path = ROOT / extra
        if not path.exists():
            raise FileNotFoundError(f"extra file {path} of {recipe.name} does not exist")
        if path.is_dir():
            shutil.copytree(path, dest / path.name, ignore=_ignore(recipe))
        else:
            shutil.copy2(path, dest / path.name)
    for src, rel in recipe.resource_files:
        path = ROOT / src
        if not path.is_file():
            raise FileNotFoundError(f"resource file {path} of {recipe.name} does not exist")
        target = dest / rel
        target.parent.mkdir(parents=True, exist_ok=True)
        shutil.copy2(path, target)
    return sorted(dest.iterdir())


def build_hash(folders: Sequence[Path]) -> str:
    """Hash of every file under ``folders`` (names relative to each folder's parent, bytes;
    caches left out): :data:`BUILD_HASH_LENGTH` hex digits of SHA-256."""
    digest = hashlib.sha256()
    for folder in folders:
        for path in sorted(p for p in folder.rglob("*") if p.is_file()):
            if "__pycache__" in path.parts or path.suffix == ".pyc":
                continue
            digest.update(path.relative_to(folder.parent).as_posix().encode() + b"\0")
            digest.update(path.read_bytes() + b"\0")
    return digest.hexdigest()[:BUILD_HASH_LENGTH]


def _module_files(staging: Path, name: str) -> list[Path]:
    """The files of staged module ``name`` (a package folder or one ``.py``; caches left out)."""
    folder = staging / name
    if folder.is_dir():
        return sorted(p for p in folder.rglob("*") if p.is_file() and
                      "__pycache__" not in p.parts and p.suffix != ".pyc")
    return [staging / f"{name}.py"]


def module_names(staging: Path, canonical: Sequence[str]) -> dict[str, str]:
    """The shipped name of every canonical module staged in ``staging``.

    ``<canonical>_<hash>``, the hash (:data:`BUILD_HASH_LENGTH` hex digits of SHA-256) taken
    over the module's files with the canonical names of the modules it refers to replaced by
    their shipped names, dependencies first. Equal code ships under an equal name whatever else
    a build carries: the scene variants of one plant share its package (and numba's cache of
    its kernels, which is kept per package content), while code that differs in any byte, or
    that imports a module that does, gets another name.

    Raises
    ------
    RuntimeError
        If the modules refer to each other in a cycle (no order gives every module its
        dependencies' names first).
    """
    pattern = re.compile(r"\b(" + "|".join(map(re.escape, sorted(canonical, key=len,
                                                                  reverse=True))) + r")\b")
    files = {name: _module_files(staging, name) for name in canonical}
    texts = {path: path.read_text(encoding="utf-8") for name in canonical
             for path in files[name] if path.suffix == ".py"}
    refers = {name: {m for path in files[name] if path in texts
                     for m in pattern.findall(texts[path])} - {name} for name in canonical}
    names: dict[str, str] = {}
    while len(names) < len(canonical):
        ready = [n for n in canonical if n not in names and refers[n] <= names.keys()]
        if not ready:
            raise RuntimeError(f"the vendored modules {sorted(set(canonical) - names.keys())} "
                               f"refer to each other in a cycle")
        for name in ready:
            digest = hashlib.sha256()
            for path in files[name]:
                data = (pattern.sub(lambda m: names.get(m.group(1), m.group(1)),
                                    texts[path]).encode() if path in texts
                        else path.read_bytes())
                digest.update(path.relative_to(staging).as_posix().encode() + b"\0" + data
                              + b"\0")
            names[name] = f"{name}_{digest.hexdigest()[:BUILD_HASH_LENGTH]}"
    return names


def _rename_modules(staging: Path, names: Mapping[str, str]) -> None:
    """Ship every canonical module name of ``staging`` under its build name: the package
    folders and module files are renamed and the names rewritten in every ``.py`` file (whole
    identifiers only: imports, and the adapters' ``VENDORED_*`` constants)."""
    pattern = re.compile(r"\b(" + "|".join(map(re.escape, sorted(names, key=len, reverse=True)))
                         + r")\b")
    for path in staging.rglob("*.py"):
        text = path.read_text(encoding="utf-8")
        new = pattern.sub(lambda m: names[m.group(1)], text)
        if new != text:
            path.write_text(new, encoding="utf-8")
    for old, new in names.items():
        for src, dst in ((staging / old, staging / new),
                         (staging / f"{old}.py", staging / f"{new}.py")):
            if src.exists():
                src.rename(dst)


def _vendor_toml_reader(staging: Path) -> bool:
    """If a staged module imports ``tomli``, ship a TOML reader as :data:`TOML_VENDORED` and
    point those imports at it; whether it did."""
    pattern = re.compile(r"^(\s*)import tomli as ", re.M)
    users = [p for p in staging.rglob("*.py") if pattern.search(p.read_text(encoding="utf-8"))]
    if users:
        import importlib.util

        spec = importlib.util.find_spec("tomli") or importlib.util.find_spec("tomllib")
        if spec is None or spec.origin is None:
            raise RuntimeError("the FMU needs a TOML reader for Python 3.10: install tomli")
        shutil.copytree(Path(spec.origin).parent, staging / TOML_VENDORED,
                        ignore=shutil.ignore_patterns("__pycache__", "*.pyc", "*.typed"))
        for path in users:
            text = path.read_text(encoding="utf-8")
            path.write_text(pattern.sub(rf"\1import {TOML_VENDORED} as ", text), encoding="utf-8")
    return bool(users)


def shipped_modules(fmu: Path | str) -> dict[str, str]:
    """Canonical module name -> the name an FMU of ours ships it under (its build record).

    Raises
    ------
    KeyError
        The FMU has no build record (not built by this build, or before isolated builds).
    """
    with zipfile.ZipFile(fmu) as zf:
        return dict(json.loads(zf.read(BUILD_INFO))["modules"])


def _build_in_this_process(recipe: FmuRecipe, workdir: Path, platforms: Sequence[str]) -> Path:
    """Build one FMU into ``workdir/out`` with binaries for ``platforms`` (run in a dedicated
    subprocess)."""
    import pythonfmu
    from pythonfmu import FmuBuilder

    from drillcosim.fmu_src.wrapper import install_native_wrapper, python_range, wrapper_library

    staging = workdir / "vendor"
    staging.mkdir(parents=True)
    expected = "_dcs_pythonfmu_" + pythonfmu.__version__.replace(".", "_")
    if expected != PYTHONFMU_VENDORED:
        raise RuntimeError(f"pythonfmu {pythonfmu.__version__} is installed; the adapters import "
                           f"{PYTHONFMU_VENDORED} (install the pinned version)")
    # the wrapper first: without a compiler nothing else is worth doing
    libraries = {name: wrapper_library(name) for name in platforms}
    source = recipe.script_path.read_text()
    if re.search(r"^\s*(from|import)\s+pythonfmu\b", source, re.M):
        raise RuntimeError(f"{recipe.script_path}: import pythonfmu as {PYTHONFMU_VENDORED} "
                           f"(the FMU ships it under that name only)")

    # stage under the canonical names: pythonfmu, the vendored packages, the slave module(s)
    vend_pfmu = staging / PYTHONFMU_VENDORED
    vend_pfmu.mkdir()
    for src in Path(pythonfmu.__file__).parent.glob("*.py"):
        shutil.copy2(src, vend_pfmu / src.name)
    for package, vname in recipe.vendored:
        _vendor(recipe, package, staging / vname)
    canonical = [PYTHONFMU_VENDORED, *(vname for _, vname in recipe.vendored),
                 recipe.slave_module]
    if _vendor_toml_reader(staging):
        canonical.append(TOML_VENDORED)
    if recipe.base:  # the adapter under its own module name, the variant as the slave module
        shutil.copy2(recipe.script_path, staging / f"{recipe.script_module}.py")
        (staging / f"{recipe.slave_module}.py").write_text(recipe.variant_source())
        canonical.append(recipe.script_module)
    else:
        shutil.copy2(recipe.script_path, staging / f"{recipe.slave_module}.py")
    resource_entries = _stage_resources(recipe, workdir / "resources")

    # isolated builds: every module under <canonical>_<hash of its code and its imports'>
    names = module_names(staging, canonical)
    _rename_modules(staging, names)
    digest = build_hash([staging, workdir / "resources"])  # the build's identity, recorded
    low, high = python_range()
    info = workdir / "info" / Path(BUILD_INFO).name
    info.parent.mkdir()
    info.write_text(json.dumps({"build": digest, "modules": names,
                                "cpython": f"3.{low}-3.{high}"}, indent=1) + "\n")
    project_files = [*sorted(staging.iterdir()), *resource_entries, info]

    # pythonfmu aliased under its shipped name, so the adapter's classes derive from the very
    # Fmi2Slave the builder checks for
    for name, module in list(sys.modules.items()):
        if name == "pythonfmu" or name.startswith("pythonfmu."):
            sys.modules[names[PYTHONFMU_VENDORED] + name[len("pythonfmu"):]] = module
    script = staging / f"{names[recipe.slave_module]}.py"
    project_files.remove(script)
    sys.path.insert(0, str(staging))  # so pythonfmu can import the adapter at build time
    fmu = FmuBuilder.build_FMU(script, dest=workdir / "out",
                               project_files=project_files, **dict(recipe.options))
    fmu = Path(fmu)
    if fmu.name != f"{recipe.name}.fmu":
        raise RuntimeError(f"pythonfmu built {fmu.name}, expected {recipe.name}.fmu: the "
                           f"adapter class must be named {recipe.name}")

    cls = getattr(sys.modules[names[recipe.slave_module]], recipe.name)
    with zipfile.ZipFile(fmu) as zf:
        members = set(zf.namelist())
        xml = zf.read("modelDescription.xml")
    xml = finalize_model_description(
        xml, getattr(cls, "VARIABLE_UNITS", {}), getattr(cls, "DIRECT_FEEDTHROUGH", None),
        ranges=getattr(cls, "VARIABLE_RANGES", None),
        runtime_note=f"[Runs in CPython 3.{low} to 3.{high}: one binary, see "
                     f"{BUILD_INFO} and drillcosim's docs/interop.md.]")
    _rewrite_zip_member(fmu, "modelDescription.xml", xml)
    # the generic resources/pythonfmu/ copy goes: the adapter imports the vendored name
    _drop_zip_members(fmu, "resources/pythonfmu/")
    members = {n for n in members if not n.startswith("resources/pythonfmu/")}
    expected_members = [f"resources/{names[PYTHONFMU_VENDORED]}/fmi2slave.py", BUILD_INFO]
    expected_members += [f"resources/{names[vname]}/__init__.py" for _, vname in recipe.vendored]
    for member in expected_members:
        if member not in members:
            raise RuntimeError(f"{fmu.name}: {member} missing")
    for package, _ in recipe.vendored:
        if any(n.startswith(f"resources/{Path(package).name}/") for n in members):
            raise RuntimeError(f"{fmu.name}: unversioned resources/{package}/ would shadow")
    install_native_wrapper(fmu, recipe.name, libraries, recipe.requires)
    return fmu


# ------------------------------------------------------------------------- public
def _selection(platforms: Selection | str | Sequence[str] | None) -> Selection:
    """The platforms to build (:func:`fmu_src.platforms.select`); RuntimeError (one line)
    when no platform has a compiler, ValueError for a bad explicit choice."""
    if isinstance(platforms, Selection):
        return platforms
    if platforms is None:
        try:
            return select()
        except ValueError as exc:
            raise RuntimeError(f"building the FMUs needs a C compiler: {exc}") from None
    return select(platforms)


def build_one(recipe: FmuRecipe, out_dir: Path | str = DEFAULT_OUT,
              platforms: Selection | str | Sequence[str] | None = None) -> Path:
    """Build one FMU atomically into ``out_dir``.

    Parameters
    ----------
    recipe : FmuRecipe
        What to build.
    out_dir : path-like
        Target folder (created if missing).
    platforms : Selection, str or sequence of str, optional
        The binary platforms (``"linux64,win64"``); default every one whose compiler is found
        (:func:`fmu_src.platforms.select`).

    Returns
    -------
    pathlib.Path
        ``out_dir / f"{recipe.name}.fmu"``.

    Raises
    ------
    RuntimeError
        Without a C compiler (one line), or if the build subprocess fails (its output is
        included).
    ValueError
        An unknown platform, or one named whose compiler is missing.
    """
    selection = _selection(platforms)
    out_dir = Path(out_dir).resolve()
    out_dir.mkdir(parents=True, exist_ok=True)
    target = out_dir / f"{recipe.name}.fmu"
    workdir = Path(tempfile.mkdtemp(prefix=f".{recipe.name}-", dir=out_dir))
    try:
        env = dict(os.environ)
        env["PYTHONDONTWRITEBYTECODE"] = "1"
        cmd = [sys.executable, "-m", "drillcosim.fmu_src.build", "--worker-recipe",
               json.dumps(asdict(recipe)), "--workdir", str(workdir),
               "--platforms", ",".join(selection.names)]
        # a fresh interpreter in an empty folder: nothing of the calling process (its
        # sys.modules, a shadowing pythonfmu, the working directory) reaches the build
        proc = subprocess.run(cmd, cwd=workdir, env=env, capture_output=True, text=True)
        if proc.returncode != 0:
            raise RuntimeError(f"building {recipe.name} failed (exit {proc.returncode}):\n"
                               f"{proc.stdout}\n{proc.stderr}")
        os.replace(workdir / "out" / f"{recipe.name}.fmu", target)
    finally:
        shutil.rmtree(workdir, ignore_errors=True)
    return target


def build_all(out_dir: Path | str = DEFAULT_OUT,
              recipes: Sequence[FmuRecipe] = REGISTRY,
              platforms: Selection | str | Sequence[str] | None = None) -> list[Path]:
    """Build every FMU of ``recipes`` whose adapter script exists.

    Parameters
    ----------
    out_dir : path-like
        Target folder, default ``build/fmus/`` in the repository.
    recipes : sequence of FmuRecipe
        Default :data:`REGISTRY`.
    platforms : Selection, str or sequence of str, optional
        As for :func:`build_one`; a platform left out by default is named in one printed line.

    Returns
    -------
    list of pathlib.Path
        The FMUs written (skipped entries are not listed).
    """
    selection = _selection(platforms)
    if selection.note():
        print(selection.note())
    built = []
    for recipe in recipes:
        if not recipe.script_path.is_file():
            print(f"note: skipping {recipe.name}: adapter {recipe.script} does not exist yet")
            continue
        built.append(build_one(recipe, out_dir, selection))
        print(f"built {built[-1]}")
    return built


def stale(fmu: Path | str, recipe: FmuRecipe) -> bool:
    """Whether ``fmu`` must be (re)built from ``recipe``.

    True if it is missing or unreadable, was made by an earlier build (pythonfmu's binary, our
    wrapper before ``resources/python_requires.txt``, or before isolated builds), was made
    from another recipe (another slave module: e.g. a variant for another layout under the
    same name), or is older than any file it is made of (:meth:`FmuRecipe.sources`).
    """
    fmu = Path(fmu)
    try:
        with zipfile.ZipFile(fmu) as zf:
            if not {"resources/python_requires.txt", BUILD_INFO} <= set(zf.namelist()):
                return True
        if recipe.slave_module not in shipped_modules(fmu):
            return True
        mtime = fmu.stat().st_mtime
    except (OSError, KeyError, ValueError, zipfile.BadZipFile):
        return True
    return any(p.stat().st_mtime > mtime for p in recipe.sources() if p.is_file())


def _recipe_from_json(text: str) -> FmuRecipe:
    raw = json.loads(text)
    return FmuRecipe(
        name=raw["name"], script=raw["script"],
        vendored=tuple(tuple(v) for v in raw["vendored"]),
        extra_files=tuple(raw["extra_files"]),
        options=tuple(tuple(o) for o in raw["options"]),
        requires=tuple(raw["requires"]),
        exclude=tuple(raw["exclude"]),
        base=raw["base"], class_attributes=raw["class_attributes"],
        resource_files=tuple(tuple(r) for r in raw["resource_files"]),
    )


def main(argv: Sequence[str] | None = None) -> int:
    """Command-line entry point; returns the exit status."""
    parser = argparse.ArgumentParser(prog="python -m drillcosim.fmu_src.build", description=__doc__
                                     .split("\n")[0])
    parser.add_argument("--out", type=Path, default=DEFAULT_OUT,
                        help=f"output folder (default {DEFAULT_OUT})")
    parser.add_argument("--only", action="append", default=None, metavar="NAME",
                        help="build only this FMU (repeatable)")
    parser.add_argument("--platforms", default=None, metavar="LIST",
                        help="binary platforms, comma-separated (linux64,win64); default: "
                        "every one whose C compiler is found")
    parser.add_argument("--worker-recipe", help=argparse.SUPPRESS)
    parser.add_argument("--workdir", type=Path, help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.worker_recipe is not None:
        _build_in_this_process(_recipe_from_json(args.worker_recipe), args.workdir,
                               args.platforms.split(","))
        return 0
    recipes = REGISTRY
    if args.only:
        unknown = set(args.only) - {r.name for r in REGISTRY}
        if unknown:
            parser.error(f"unknown FMU(s) {sorted(unknown)}; registered: "
                         f"{[r.name for r in REGISTRY]}")
        recipes = tuple(r for r in REGISTRY if r.name in args.only)
    try:
        selection = _selection(args.platforms)
    except ValueError as exc:
        parser.error(str(exc))
    except RuntimeError as exc:  # no compiler for this machine
        print(f"python -m drillcosim.fmu_src.build: {exc}", file=sys.stderr)
        return 1
    try:
        build_all(args.out, recipes, selection)
    except RuntimeError as exc:
        print(f"python -m drillcosim.fmu_src.build: {exc}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
