"""Build the project's FMUs with pythonfmu: ``python -m drillcosim.fmu_src.build --out DIR``.

Every FMU is described by one :class:`FmuSpec` in :data:`REGISTRY`. ``build_all``
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

FMI wrapper (``--wrapper``)
---------------------------
``native`` (the default) replaces pythonfmu's prebuilt C++ wrapper
``binaries/linux64/<name>.so`` by our C wrapper (:mod:`fmu_src.wrapper`,
compiled here against the running Python: needs a C compiler, ``$CC`` or
``gcc``, and a shared libpython; linux64 only), which returns fmi2Error for
exceptions and for statuses the adapter reports, and survives exceptions; see
that module for the status convention. ``pythonfmu`` (the fallback) keeps
pythonfmu's binary, which can report errors only as fmi2Discard (or fmi2Fatal).
Choose with ``--wrapper``, ``build_one(..., wrapper=...)`` or, for a process,
``$DRILLCOSIM_FMU_WRAPPER``. Without a C compiler the native build stops with a
one-line message naming the fallback.

Registering the plant FMU
-------------------------
Add (or edit) one entry in :data:`REGISTRY`, e.g.::

    FmuSpec(name="DrillstringPlant", script="fmu_src/drillstring_plant_fmu.py",
            vendored=(("plant", "_dcs_plant_0_1_0"),), extra_files=("scenes/x.toml",))

``name`` must equal the adapter class name (= modelIdentifier = file stem of
the ``.fmu``); the adapter imports ``_dcs_plant_0_1_0``; ``extra_files`` (paths
relative to the repository root, files or folders) land in ``resources/`` under
their own base name.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import shutil
import subprocess
import sys
import tempfile
import zipfile
from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from xml.etree import ElementTree as ET

__all__ = [
    "DEFAULT_OUT",
    "WRAPPERS",
    "REGISTRY",
    "ROOT",
    "UNIT_DEFINITIONS",
    "FmuSpec",
    "WrapperUnavailableError",
    "build_all",
    "build_one",
    "default_wrapper",
    "finalize_model_description",
    "main",
    "wrapper_of",
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


def user_cache() -> Path:
    """Per-user cache folder: ``$DRILLCOSIM_CACHE``, else ``$XDG_CACHE_HOME/drillcosim``."""
    env = os.environ.get("DRILLCOSIM_CACHE")
    if env:
        return Path(env)
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(base) / "drillcosim"


def default_out() -> Path:
    """Where FMUs are built and found by default.

    ``build/fmus/`` of the checkout; for an installed package (no checkout) a per-user folder
    named by the version, ``<user_cache()>/fmus/<version>``, so ``drillcosim build`` and
    ``drillcosim run`` agree from any working directory.
    """
    if _checkout():
        return ROOT / "build" / "fmus"
    from drillcosim import __version__

    return user_cache() / "fmus" / __version__


DEFAULT_OUT = default_out()

#: Import name under which pythonfmu is shipped inside every FMU. pythonfmu's builder ships it
#: as ``resources/pythonfmu/``; an FMU loaded in a Python host would then put a ``pythonfmu``
#: from its (temporary) unzip folder into the host's ``sys.modules``, shadowing the host's own
#: copy for the rest of the process (a later FmuBuilder then wrote FMUs without binaries). The
#: adapters import it under this unique, versioned name instead, and the build replaces
#: ``resources/pythonfmu/`` by it.
PYTHONFMU_VENDORED = "_dcs_pythonfmu_0_7_0"

#: SI base-unit exponents of the units the FMUs may declare (FMI 2.0 BaseUnit).
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
    "N.m": {"kg": 1, "m": 2, "s": -2},
    "N.m/rad": {"kg": 1, "m": 2, "s": -2, "rad": -1},
    "Pa": {"kg": 1, "m": -1, "s": -2},
    "W": {"kg": 1, "m": 2, "s": -3},
    "J": {"kg": 1, "m": 2, "s": -2},
}

#: FMI wrappers ``build_one`` can ship; the first is the default.
WRAPPERS: tuple[str, ...] = ("native", "pythonfmu")


class WrapperUnavailableError(RuntimeError):
    """The native wrapper cannot be built here (no C compiler or no shared libpython)."""


def _wrapper(wrapper: str | None) -> str:
    """The wrapper to use: ``wrapper``, else ``$DRILLCOSIM_FMU_WRAPPER``, else native."""
    chosen = wrapper or os.environ.get("DRILLCOSIM_FMU_WRAPPER") or WRAPPERS[0]
    if chosen not in WRAPPERS:
        raise ValueError(f"wrapper {chosen!r} is not one of {', '.join(WRAPPERS)}")
    return chosen


def default_wrapper() -> str:
    """The wrapper a build without ``wrapper=`` uses (``$DRILLCOSIM_FMU_WRAPPER`` or native)."""
    return _wrapper(None)


def wrapper_of(fmu: Path | str) -> str:
    """The wrapper an FMU was built with: "native" if it ships ``resources/slaveclass.txt``."""
    with zipfile.ZipFile(fmu) as zf:
        return "native" if "resources/slaveclass.txt" in zf.namelist() else "pythonfmu"


def _check_native_prerequisites() -> None:
    """Raise :class:`WrapperUnavailableError` (one line) if the native wrapper cannot be built."""
    from drillcosim.fmu_src.wrapper import libpython_path

    cc = os.environ.get("CC") or "gcc"
    fallback = ("build with --wrapper pythonfmu (or DRILLCOSIM_FMU_WRAPPER=pythonfmu) "
                "for pythonfmu's prebuilt binary")
    if shutil.which(cc) is None:
        raise WrapperUnavailableError(f"the native FMI wrapper needs a C compiler and {cc!r} "
                                 f"(from $CC or the default gcc) was not found; install "
                                 f"one or {fallback}")
    try:
        libpython_path()
    except RuntimeError as exc:
        raise WrapperUnavailableError(f"{exc}; {fallback}") from None


_DEFAULT_OPTIONS: tuple[tuple[str, bool], ...] = (
    ("canGetAndSetFMUstate", True),
    ("canSerializeFMUstate", True),
)


@dataclass(frozen=True)
class FmuSpec:
    """One FMU to build.

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
    """

    name: str
    script: str
    vendored: tuple[tuple[str, str], ...] = ()
    extra_files: tuple[str, ...] = ()
    options: tuple[tuple[str, bool], ...] = field(default=_DEFAULT_OPTIONS)

    def __post_init__(self) -> None:
        if not self.name.isidentifier():
            raise ValueError(f"FMU name {self.name!r} is not a Python identifier")
        for _package, vname in self.vendored:
            if not (vname.isidentifier() and vname.startswith("_dcs_")):
                raise ValueError(f"vendored name {vname!r} must be an identifier starting "
                                 f"with '_dcs_' (e.g. '_dcs_plant_0_1_0')")

    @property
    def script_path(self) -> Path:
        """Path: absolute path of the adapter script."""
        path = Path(self.script)
        return path if path.is_absolute() else ROOT / path

    @property
    def slave_module(self) -> str:
        """str: import name of the adapter inside the FMU, ``_dcs_<script stem>_<version>``."""
        from drillcosim import __version__

        return f"_dcs_{self.script_path.stem}_{__version__.replace('.', '_')}"


#: The FMUs of the project. The plant entry is skipped until its adapter exists.
REGISTRY: tuple[FmuSpec, ...] = (
    FmuSpec(
        name="StrainController",
        script="fmu_src/strain_controller_fmu.py",
        vendored=(("controller", "_dcs_controller_0_1_0"),
                  ("fmu_src/slave_support", "_dcs_slave_support_0_1_0")),
    ),
    FmuSpec(
        name="DrillstringPlant",
        script="fmu_src/drillstring_plant_fmu.py",
        vendored=(("plant", "_dcs_plant_0_1_0"),
                  ("fmu_src/slave_support", "_dcs_slave_support_0_1_0")),
        extra_files=("scenes",),
    ),
)


# ------------------------------------------------------------------ modelDescription
def finalize_model_description(
    xml: bytes,
    units: Mapping[str, str],
    direct_feedthrough: Mapping[str, Sequence[str]] | None = None,
) -> bytes:
    """Add units, unit definitions and output dependencies to a modelDescription.

    Parameters
    ----------
    xml : bytes
        modelDescription.xml as written by pythonfmu.
    units : mapping of str to str
        Variable name -> unit (keys of :data:`UNIT_DEFINITIONS`); Real variables only.
    direct_feedthrough : mapping of str to sequence of str, optional
        Output name -> names of the inputs it depends on directly. Outputs not
        in the mapping (or all, if None) get no ``dependencies`` attribute.

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
        if unit not in UNIT_DEFINITIONS:
            raise ValueError(f"unit {unit!r} of {name!r} is not in UNIT_DEFINITIONS; add it")
        real = by_name[name].find("Real")
        if real is None:
            raise ValueError(f"variable {name!r} has a unit but is not a Real")
        real.set("unit", unit)
        if unit not in used_units:
            used_units.append(unit)

    for old in root.findall("UnitDefinitions"):
        root.remove(old)
    if used_units:
        unit_defs = ET.Element("UnitDefinitions")
        for unit in sorted(used_units):
            node = ET.SubElement(unit_defs, "Unit", name=unit)
            ET.SubElement(node, "BaseUnit",
                          {k: str(v) for k, v in UNIT_DEFINITIONS[unit].items()})
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
def _build_in_this_process(spec: FmuSpec, workdir: Path, wrapper: str = "native") -> Path:
    """Build one FMU into ``workdir/out`` (run in a dedicated subprocess)."""
    import pythonfmu
    from pythonfmu import FmuBuilder

    staging = workdir / "vendor"
    staging.mkdir(parents=True)
    expected = "_dcs_pythonfmu_" + pythonfmu.__version__.replace(".", "_")
    if expected != PYTHONFMU_VENDORED:
        raise RuntimeError(f"pythonfmu {pythonfmu.__version__} is installed; the adapters import "
                           f"{PYTHONFMU_VENDORED} (install the pinned version)")
    # pythonfmu under its vendored name: shipped (runtime), and aliased here so the adapter's
    # classes derive from the very Fmi2Slave the builder checks for
    vend_pfmu = staging / PYTHONFMU_VENDORED
    vend_pfmu.mkdir()
    for src in Path(pythonfmu.__file__).parent.glob("*.py"):
        shutil.copy2(src, vend_pfmu / src.name)
    for name, module in list(sys.modules.items()):
        if name == "pythonfmu" or name.startswith("pythonfmu."):
            sys.modules[PYTHONFMU_VENDORED + name[len("pythonfmu"):]] = module
    project_files: list[Path] = [vend_pfmu]
    for package, vname in spec.vendored:
        src = ROOT / package
        if not (src / "__init__.py").is_file():
            raise FileNotFoundError(f"vendored package {src} has no __init__.py")
        dst = staging / vname
        shutil.copytree(src, dst, ignore=shutil.ignore_patterns("__pycache__", "*.pyc"))
        project_files.append(dst)
    for extra in spec.extra_files:
        path = ROOT / extra
        if not path.exists():
            raise FileNotFoundError(f"extra file {path} of {spec.name} does not exist")
        project_files.append(path)

    source = spec.script_path.read_text()
    if re.search(r"^\s*(from|import)\s+pythonfmu\b", source, re.M):
        raise RuntimeError(f"{spec.script_path}: import pythonfmu as {PYTHONFMU_VENDORED} (the "
                           f"FMU ships it under that name only)")
    script = staging / f"{spec.slave_module}.py"
    shutil.copy2(spec.script_path, script)
    sys.path.insert(0, str(staging))  # so pythonfmu can import the adapter at build time
    fmu = FmuBuilder.build_FMU(script, dest=workdir / "out",
                               project_files=project_files, **dict(spec.options))
    fmu = Path(fmu)
    if fmu.name != f"{spec.name}.fmu":
        raise RuntimeError(f"pythonfmu built {fmu.name}, expected {spec.name}.fmu: the "
                           f"adapter class must be named {spec.name}")

    cls = getattr(sys.modules[spec.slave_module], spec.name)
    with zipfile.ZipFile(fmu) as zf:
        names = set(zf.namelist())
        xml = zf.read("modelDescription.xml")
    xml = finalize_model_description(xml, getattr(cls, "VARIABLE_UNITS", {}),
                                     getattr(cls, "DIRECT_FEEDTHROUGH", None))
    _rewrite_zip_member(fmu, "modelDescription.xml", xml)
    # the generic resources/pythonfmu/ copy goes: the adapter imports PYTHONFMU_VENDORED
    _drop_zip_members(fmu, "resources/pythonfmu/")
    names = {n for n in names if not n.startswith("resources/pythonfmu/")}
    if f"resources/{PYTHONFMU_VENDORED}/fmi2slave.py" not in names:
        raise RuntimeError(f"{fmu.name}: resources/{PYTHONFMU_VENDORED}/ missing")

    for package, vname in spec.vendored:
        if f"resources/{vname}/__init__.py" not in names:
            raise RuntimeError(f"{fmu.name}: resources/{vname}/ missing")
        if any(n.startswith(f"resources/{package}/") for n in names):
            raise RuntimeError(f"{fmu.name}: unversioned resources/{package}/ would shadow")
    if wrapper == "native":
        from drillcosim.fmu_src.wrapper import compile_wrapper, install_native_wrapper

        library = compile_wrapper(workdir / "dcs_fmi2_native.so")
        install_native_wrapper(fmu, spec.name, library)
    return fmu


# ------------------------------------------------------------------------- public
def build_one(spec: FmuSpec, out_dir: Path | str = DEFAULT_OUT,
              wrapper: str | None = None) -> Path:
    """Build one FMU atomically into ``out_dir``.

    Parameters
    ----------
    spec : FmuSpec
        What to build.
    out_dir : path-like
        Target folder (created if missing).
    wrapper : {"pythonfmu", "native"}, optional
        FMI wrapper (see the module docstring); default ``$DRILLCOSIM_FMU_WRAPPER``
        or "native".

    Returns
    -------
    pathlib.Path
        ``out_dir / f"{spec.name}.fmu"``.

    Raises
    ------
    WrapperUnavailableError
        ``wrapper="native"`` without a C compiler or a shared libpython (one line,
        naming the ``pythonfmu`` fallback).
    RuntimeError
        If the build subprocess fails (its output is included).
    """
    wrapper = _wrapper(wrapper)
    if wrapper == "native":
        _check_native_prerequisites()
    out_dir = Path(out_dir).resolve()
    out_dir.mkdir(parents=True, exist_ok=True)
    target = out_dir / f"{spec.name}.fmu"
    workdir = Path(tempfile.mkdtemp(prefix=f".{spec.name}-", dir=out_dir))
    try:
        env = dict(os.environ)
        env["PYTHONDONTWRITEBYTECODE"] = "1"
        cmd = [sys.executable, "-m", "drillcosim.fmu_src.build", "--worker-spec",
               json.dumps(asdict(spec)), "--workdir", str(workdir), "--wrapper", wrapper]
        # a fresh interpreter in an empty folder: nothing of the calling process (its
        # sys.modules, a shadowing pythonfmu, the working directory) reaches the build
        proc = subprocess.run(cmd, cwd=workdir, env=env, capture_output=True, text=True)
        if proc.returncode != 0:
            raise RuntimeError(f"building {spec.name} failed (exit {proc.returncode}):\n"
                               f"{proc.stdout}\n{proc.stderr}")
        os.replace(workdir / "out" / f"{spec.name}.fmu", target)
    finally:
        shutil.rmtree(workdir, ignore_errors=True)
    return target


def build_all(out_dir: Path | str = DEFAULT_OUT,
              specs: Sequence[FmuSpec] = REGISTRY, wrapper: str | None = None) -> list[Path]:
    """Build every FMU of ``specs`` whose adapter script exists.

    Parameters
    ----------
    out_dir : path-like
        Target folder, default ``build/fmus/`` in the repository.
    specs : sequence of FmuSpec
        Default :data:`REGISTRY`.
    wrapper : {"pythonfmu", "native"}, optional
        FMI wrapper, see :func:`build_one`.

    Returns
    -------
    list of pathlib.Path
        The FMUs written (skipped entries are not listed).
    """
    built = []
    for spec in specs:
        if not spec.script_path.is_file():
            print(f"note: skipping {spec.name}: adapter {spec.script} does not exist yet")
            continue
        built.append(build_one(spec, out_dir, wrapper))
        print(f"built {built[-1]}")
    return built


def _spec_from_json(text: str) -> FmuSpec:
    raw = json.loads(text)
    return FmuSpec(
        name=raw["name"], script=raw["script"],
        vendored=tuple(tuple(v) for v in raw["vendored"]),
        extra_files=tuple(raw["extra_files"]),
        options=tuple(tuple(o) for o in raw["options"]),
    )


def main(argv: Sequence[str] | None = None) -> int:
    """Command-line entry point; returns the exit status."""
    parser = argparse.ArgumentParser(prog="python -m drillcosim.fmu_src.build", description=__doc__
                                     .split("\n")[0])
    parser.add_argument("--out", type=Path, default=DEFAULT_OUT,
                        help=f"output folder (default {DEFAULT_OUT})")
    parser.add_argument("--only", action="append", default=None, metavar="NAME",
                        help="build only this FMU (repeatable)")
    parser.add_argument("--wrapper", choices=WRAPPERS, default=None,
                        help="FMI wrapper: native (default, or $DRILLCOSIM_FMU_WRAPPER; "
                             "our C wrapper, fmi2Error for errors, needs a C compiler) or "
                             "pythonfmu (fallback: errors reported as fmi2Discard)")
    parser.add_argument("--worker-spec", help=argparse.SUPPRESS)
    parser.add_argument("--workdir", type=Path, help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.worker_spec is not None:
        _build_in_this_process(_spec_from_json(args.worker_spec), args.workdir,
                               _wrapper(args.wrapper))
        return 0
    specs = REGISTRY
    if args.only:
        unknown = set(args.only) - {s.name for s in REGISTRY}
        if unknown:
            parser.error(f"unknown FMU(s) {sorted(unknown)}; registered: "
                         f"{[s.name for s in REGISTRY]}")
        specs = tuple(s for s in REGISTRY if s.name in args.only)
    try:
        build_all(args.out, specs, args.wrapper)
    except WrapperUnavailableError as exc:
        print(f"python -m drillcosim.fmu_src.build: {exc}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
