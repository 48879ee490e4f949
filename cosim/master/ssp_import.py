"""Import an SSP 1.0 system (``.ssp`` archive, or an unpacked folder / ``.ssd`` file) to run it.

:func:`read_ssp` turns what another tool wrote (libcosim, Ecos, an SSP editor, or
:func:`cosim.master.ssp.export_ssp`) into a :class:`~cosim.master.system.SystemSpec`. Namespaces
are resolved by URI (any prefix works).

Supported (SSP 1.0)
-------------------
* one flat ``ssd:System`` whose ``ssd:Elements`` are ``ssd:Component`` s of type
  ``application/x-fmu-sharedlibrary`` (the default) with a relative ``source`` inside the
  package, ``implementation`` ``any`` or ``CoSimulation``;
* ``ssd:Connectors`` (kind, type ``ssc:Real|Integer|Boolean|String``, optional ``unit``);
* ``ssd:Connections`` from an ``output`` connector to an ``input`` connector (Real, the
  master exchanges Reals);
* ``ssd:ParameterBindings`` on components and on the system, with the parameter set inline
  (``ssd:ParameterValues / ssv:ParameterSet``) or in an SSV file (``source``, relative to the
  SSD), optional ``prefix``; ``ssv:Real`` (optional ``unit``), ``ssv:Integer``,
  ``ssv:Boolean``, ``ssv:String``. As SSP 1.0 specifies, all bindings apply, later ones over
  earlier ones and system bindings over component bindings; a name that matches no variable
  is ignored (and listed in :attr:`SspSystem.notes`);
* ``ssd:DefaultExperiment`` ``startTime`` / ``stopTime`` [s], the OSP annotations
  ``osp:FixedStepAlgorithm baseStepSize`` [s] (the base step) and, per component,
  ``osp:StepSizeHint`` [s] (a multiple of the base step: that component's period).

SSP 1.0 has no standard step size: without the OSP annotation a step must be given.
Geometry, graphical elements, enumerations, unit definitions and annotations of other
types carry no simulation semantics here and are skipped.

Refused, in one line naming the element (:class:`SspError`, a ``ValueError``)
--------------------------------------------------------------------------------
nested systems and components referencing SSD/SSP files, connectors of the system itself,
signal dictionaries, connection transformations (linear, mappings), connections that need
a unit conversion, parameter mappings, ``sourceBase="component"``, ``ssv:Enumeration`` and
``ssv:Binary`` values, ModelExchange components, non-Real connections, a component period
that is not a multiple of the base step, and any element SSP 1.0 does not define.

All components step with the same base step in Jacobi fashion with a zero-order hold
(the libcosim/Ecos fixed-step algorithm), without delays.
"""

from __future__ import annotations

import math
import shutil
import tempfile
import zipfile
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path, PurePosixPath
from typing import Any
from urllib.parse import unquote, urlparse
from xml.etree import ElementTree as ET

from .errors import UserError
from .interface import FmuInterface, check_system, read_interface
from .ssp import NS
from .system import Connection, FmuSpec, ParameterValue, SystemSpec
from .timegrid import integer_multiple

__all__ = ["SspError", "SspSystem", "read_ssp"]

_URI = {uri: prefix for prefix, uri in NS.items()}
_FMU_TYPE = "application/x-fmu-sharedlibrary"
_PARAMETER_SET_TYPE = "application/x-ssp-parameter-set"
_OSP = "com.opensimulationplatform"

# children with no simulation semantics, skipped wherever they occur
_SKIP = {"ssd:ElementGeometry", "ssd:ConnectorGeometry", "ssd:ConnectionGeometry",
         "ssd:SystemGeometry", "ssd:GraphicalElements", "ssd:Enumerations", "ssd:Units",
         "ssv:Units", "ssv:Enumerations", "ssc:Annotations", "ssd:Annotations"}
_WHY = {
    "ssd:System": "nested systems are not supported (a flat system only)",
    "ssd:SignalDictionaries": "signal dictionaries are not supported",
    "ssd:SignalDictionaryReference": "signal dictionaries are not supported",
    "ssc:LinearTransformation": "connection transformations are not supported",
    "ssc:BooleanMappingTransformation": "connection transformations are not supported",
    "ssc:IntegerMappingTransformation": "connection transformations are not supported",
    "ssc:EnumerationMappingTransformation": "connection transformations are not supported",
    "ssd:ParameterMapping": "parameter mappings are not supported",
    "ssv:Enumeration": "Enumeration parameter values are not supported",
    "ssv:Binary": "Binary parameter values are not supported",
    "ssc:Enumeration": "only Real connections are supported",
    "ssc:Binary": "only Real connections are supported",
}


class SspError(UserError):
    """An SSP file that cannot be run: one line naming the file and the element."""


@dataclass
class SspSystem:
    """An imported SSP, ready to run; a context manager that removes its extracted files.

    Attributes
    ----------
    system : SystemSpec
        FMU paths point into :attr:`directory` (or beside the SSD).
    outputs : tuple of str
        ``'instance.variable'`` of every Real output of every component.
    name : str
        The system's name.
    source : Path
        The file read.
    notes : tuple of str
        Things applied differently than written, one line each (e.g. ignored parameters).
    directory : Path or None
        Temporary folder the archive was extracted to (None for an unpacked SSP).
    """

    system: SystemSpec
    outputs: tuple[str, ...]
    name: str
    source: Path
    notes: tuple[str, ...] = ()
    directory: Path | None = None

    def close(self) -> None:
        """Delete the extracted files (the system's FMU paths become invalid)."""
        if self.directory is not None:
            shutil.rmtree(self.directory, ignore_errors=True)
            self.directory = None

    def __enter__(self) -> SspSystem:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def _tag(el: ET.Element) -> str:
    """``ssd:Component`` for ``{uri}Component`` (the standard prefixes; the URI otherwise)."""
    if el.tag.startswith("{"):
        uri, local = el.tag[1:].split("}", 1)
        return f"{_URI.get(uri, uri)}:{local}"
    return el.tag


class _Reader:
    """Parser state: the file name for messages and the folder the SSD lives in."""

    def __init__(self, source: Path, base: Path):
        self.source = source
        self.base = base

    def fail(self, where: str, text: str) -> SspError:
        return SspError(f"{self.source.name}: {where}: {text}")

    def children(self, el: ET.Element, where: str, allowed: set[str]) -> Iterator[ET.Element]:
        """Children of ``el`` whose tag is in ``allowed``; skip geometry/annotations; refuse others."""
        for child in el:
            tag = _tag(child)
            if tag in allowed:
                yield child
            elif tag in _SKIP:
                continue
            elif tag in _WHY:
                raise self.fail(f"<{tag}> in {where}", _WHY[tag])
            else:
                raise self.fail(f"<{tag}> in {where}", "not an SSP 1.0 element this importer "
                                "supports")

    def file(self, uri: str, where: str) -> Path:
        """A relative URI resolved against the SSD's folder, staying inside it."""
        parsed = urlparse(uri)
        if parsed.scheme not in ("", "file") or parsed.netloc or not parsed.path:
            raise self.fail(where, f"source {uri!r} is not a relative URI inside the package")
        rel = PurePosixPath(unquote(parsed.path))
        if rel.is_absolute() or ".." in rel.parts:
            raise self.fail(where, f"source {uri!r} must stay inside the package (no absolute "
                            "path, no '..')")
        path = self.base.joinpath(*rel.parts)
        if not path.is_file():
            raise self.fail(where, f"source {uri!r}: no such file in the package")
        return path

    # -------------------------------------------------------------- parameters
    def parameter_set(self, binding: ET.Element, where: str) -> list[tuple[str, Any, str | None]]:
        """``(name, value, unit)`` of one ``ssd:ParameterBinding`` (prefix applied)."""
        kind = binding.get("type", _PARAMETER_SET_TYPE)
        if kind != _PARAMETER_SET_TYPE:
            raise self.fail(where, f"parameter source type {kind!r} is not supported (only "
                            f"{_PARAMETER_SET_TYPE})")
        if binding.get("sourceBase", "SSD") != "SSD":
            raise self.fail(where, "sourceBase='component' is not supported")
        inline = list(self.children(binding, where, {"ssd:ParameterValues"}))
        if binding.get("source"):
            if inline:
                raise self.fail(where, "has both a source and inline ParameterValues")
            path = self.file(binding.get("source"), where)
            try:
                root = ET.parse(path).getroot()
            except ET.ParseError as exc:
                raise self.fail(where, f"{path.name} is not well-formed XML: {exc}") from None
            sets = [root]
        elif inline:
            sets = list(self.children(inline[0], f"{where}/ssd:ParameterValues",
                                      {"ssv:ParameterSet"}))
        else:
            raise self.fail(where, "has neither a source nor inline ParameterValues")
        out = []
        prefix = binding.get("prefix", "")
        for pset in sets:
            if _tag(pset) != "ssv:ParameterSet":
                raise self.fail(where, f"expected an ssv:ParameterSet, found <{_tag(pset)}>")
            for params in self.children(pset, f"{where}/ssv:ParameterSet", {"ssv:Parameters"}):
                for p in self.children(params, f"{where}/ssv:Parameters", {"ssv:Parameter"}):
                    out.append(self.parameter(p, prefix, where))
        return out

    def parameter(self, p: ET.Element, prefix: str, where: str) -> tuple[str, Any, str | None]:
        name = p.get("name")
        here = f"{where}/ssv:Parameter name={name!r}"
        values = list(self.children(p, here, {"ssv:Real", "ssv:Integer", "ssv:Boolean",
                                              "ssv:String"}))
        if len(values) != 1 or not name:
            raise self.fail(here, "needs a name and exactly one value element")
        v, tag = values[0], _tag(values[0])
        text = v.get("value")
        if text is None:
            raise self.fail(here, f"<{tag}> has no value")
        try:
            value: ParameterValue
            if tag == "ssv:Real":
                value = float(text)
            elif tag == "ssv:Integer":
                value = int(text)
            elif tag == "ssv:Boolean":
                if text not in ("true", "false", "1", "0"):
                    raise ValueError(text)
                value = text in ("true", "1")
            else:
                value = text
        except ValueError:
            raise self.fail(here, f"<{tag} value={text!r}> is not a valid {tag[4:]}") from None
        return prefix + name, value, v.get("unit")

    # -------------------------------------------------------------- components
    def component(self, el: ET.Element) -> dict[str, Any]:
        name = el.get("name") or ""
        where = f"<ssd:Component name={name!r}>"
        if not name or "." in name:
            raise self.fail(where, "needs a name without '.'")
        kind = el.get("type", _FMU_TYPE)
        if kind != _FMU_TYPE:
            raise self.fail(where, f"type {kind!r}: nested systems are not supported (a flat "
                            "system of FMUs only)")
        if el.get("implementation", "any") not in ("any", "CoSimulation"):
            raise self.fail(where, f"implementation {el.get('implementation')!r}: only "
                            "co-simulation FMUs are run")
        path = self.file(el.get("source") or "", where)
        connectors: dict[str, tuple[str, str, str | None]] = {}
        bindings: list[tuple[str, Any, str | None]] = []
        for child in self.children(el, where, {"ssd:Connectors", "ssd:ParameterBindings"}):
            if _tag(child) == "ssd:Connectors":
                for c in self.children(child, where, {"ssd:Connector"}):
                    connectors[c.get("name") or ""] = self.connector(c, where)
            else:
                for b in self.children(child, where, {"ssd:ParameterBinding"}):
                    bindings += self.parameter_set(b, f"{where}/ssd:ParameterBinding")
        return {"name": name, "path": path, "connectors": connectors, "bindings": bindings,
                "hint": _osp_value(el, "StepSizeHint", "value"), "where": where}

    def connector(self, c: ET.Element, where: str) -> tuple[str, str, str | None]:
        here = f"{where}/ssd:Connector name={c.get('name')!r}"
        types = list(self.children(c, here, {"ssc:Real", "ssc:Integer", "ssc:Boolean",
                                             "ssc:String"}))
        if len(types) > 1:
            raise self.fail(here, "more than one type element")
        vtype = _tag(types[0])[4:] if types else ""
        unit = types[0].get("unit") if types else None
        return c.get("kind", ""), vtype, unit


def _osp_value(el: ET.Element, local: str, attribute: str) -> str | None:
    """``attribute`` of the first ``osp:<local>`` inside an OSP annotation of ``el``."""
    for holder in el:
        if _tag(holder) not in ("ssd:Annotations", "ssc:Annotations"):
            continue
        for ann in holder:
            if _tag(ann) == "ssc:Annotation" and ann.get("type") == _OSP:
                for node in ann.iter(f"{{{NS['osp']}}}{local}"):
                    return node.get(attribute)
    return None


def _number(reader: _Reader, text: str | None, where: str) -> float | None:
    if text is None:
        return None
    try:
        value = float(text)
    except ValueError:
        raise reader.fail(where, f"{text!r} is not a number") from None
    if not math.isfinite(value):
        raise reader.fail(where, f"{text!r} must be finite")
    return value


def _locate(path: Path) -> tuple[Path, Path | None]:
    """The SSD file to read and the temporary folder an archive was extracted to (or None)."""
    if path.is_dir():
        return path / "SystemStructure.ssd", None
    if path.suffix.lower() == ".ssd":
        return path, None
    try:
        zf = zipfile.ZipFile(path)
    except (zipfile.BadZipFile, OSError) as exc:
        raise SspError(f"{path}: not an SSP archive (a zip file): {exc}") from None
    tmp = Path(tempfile.mkdtemp(prefix="drillcosim-ssp-"))
    try:
        with zf:
            for info in zf.infolist():
                parts = PurePosixPath(info.filename).parts
                if info.filename.startswith("/") or ".." in parts:
                    raise SspError(f"{path.name}: archive member {info.filename!r} points "
                                   "outside the package")
            zf.extractall(tmp)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    return tmp / "SystemStructure.ssd", tmp


def read_ssp(path: str | Path, *, step: float | None = None,
             stop_time: float | None = None) -> SspSystem:
    """Read an SSP 1.0 system (see the module docstring for what is supported).

    Parameters
    ----------
    path : path-like
        ``.ssp`` archive, an unpacked SSP folder, or its ``.ssd`` file.
    step : float, optional
        Base step [s]; overrides the ``osp:FixedStepAlgorithm baseStepSize`` annotation and
        is required without it.
    stop_time : float, optional
        [s]; overrides ``DefaultExperiment stopTime``.

    Returns
    -------
    SspSystem
        Close it (or use ``with``) to remove the extracted files.

    Raises
    ------
    SspError
        Unsupported or invalid content, one line naming the file and the element.
    FileNotFoundError
        No such file.
    """
    path = Path(path)
    if not path.exists():
        raise FileNotFoundError(f"{path}: no such SSP file")
    ssd, tmp = _locate(path)
    try:
        result = _read(path, ssd, step, stop_time)
    except BaseException:
        if tmp is not None:
            shutil.rmtree(tmp, ignore_errors=True)
        raise
    result.directory = tmp
    return result


def _read(source: Path, ssd: Path, step: float | None, stop_time: float | None) -> SspSystem:
    reader = _Reader(source, ssd.parent)
    if not ssd.is_file():
        raise SspError(f"{source.name}: no SystemStructure.ssd in the package")
    try:
        root = ET.parse(ssd).getroot()
    except ET.ParseError as exc:
        raise SspError(f"{source.name}: {ssd.name} is not well-formed XML: {exc}") from None
    if _tag(root) != "ssd:SystemStructureDescription":
        raise reader.fail(f"<{_tag(root)}>", "not an SSP 1.0 SystemStructureDescription "
                          f"(namespace {NS['ssd']})")
    version = root.get("version", "")
    if version.split(".")[:2] != ["1", "0"]:
        raise reader.fail("<ssd:SystemStructureDescription>", f"version {version!r}: only SSP "
                          "1.0 is supported")
    systems = list(reader.children(root, "the SSD", {"ssd:System", "ssd:DefaultExperiment"}))
    system_els = [s for s in systems if _tag(s) == "ssd:System"]
    if len(system_els) != 1:
        raise reader.fail("the SSD", f"needs exactly one <ssd:System>, found {len(system_els)}")
    system_el = system_els[0]
    sys_name = system_el.get("name") or root.get("name") or source.stem
    comps: list[dict[str, Any]] = []
    conn_els: list[ET.Element] = []
    sys_bindings: list[tuple[str, Any, str | None]] = []
    where_sys = f"<ssd:System name={sys_name!r}>"
    for child in reader.children(system_el, where_sys, {
            "ssd:Elements", "ssd:Connections", "ssd:ParameterBindings", "ssd:Connectors"}):
        tag = _tag(child)
        if tag == "ssd:Elements":
            comps += [reader.component(c) for c in
                      reader.children(child, where_sys, {"ssd:Component"})]
        elif tag == "ssd:Connections":
            conn_els += list(reader.children(child, where_sys, {"ssd:Connection"}))
        elif tag == "ssd:ParameterBindings":
            for b in reader.children(child, where_sys, {"ssd:ParameterBinding"}):
                sys_bindings += reader.parameter_set(b, f"{where_sys}/ssd:ParameterBinding")
        elif len(child):
            raise reader.fail(f"<ssd:Connectors> of {where_sys}", "connectors of the system "
                              "itself are not supported (a flat, closed system only)")
    if not comps:
        raise reader.fail(where_sys, "has no components")
    names = [c["name"] for c in comps]
    dup = sorted({n for n in names if names.count(n) > 1})
    if dup:
        raise reader.fail(where_sys, f"component names must be unique, repeated: {dup}")
    by_name = {c["name"]: c for c in comps}
    faces = {c["name"]: read_interface(c["name"], c["path"]) for c in comps}

    # experiment: base step, start/stop
    exp = next((s for s in systems if _tag(s) == "ssd:DefaultExperiment"), None)
    start = 0.0
    stop = stop_time
    base = step
    if exp is not None:
        start = _number(reader, exp.get("startTime"), "<ssd:DefaultExperiment startTime>") or 0.0
        if stop is None:
            stop = _number(reader, exp.get("stopTime"), "<ssd:DefaultExperiment stopTime>")
        if base is None:
            base = _number(reader, _osp_value(exp, "FixedStepAlgorithm", "baseStepSize"),
                           "<osp:FixedStepAlgorithm baseStepSize>")
    if base is None:
        raise SspError(f"{source.name}: no step size (SSP 1.0 has none; no "
                       "osp:FixedStepAlgorithm baseStepSize annotation): give one (--step H)")
    if not base > 0:
        raise reader.fail("base step", f"{base!r} must be > 0 [s]")

    notes: list[str] = []
    params: dict[str, dict[str, ParameterValue]] = {n: {} for n in names}
    # component bindings first, then the system's (they take precedence), later over earlier
    bound = [(c["name"], n, v, u, c["where"]) for c in comps for n, v, u in c["bindings"]]
    for full, v, u in sys_bindings:
        inst, _, var = full.partition(".")
        if inst not in by_name or not var:
            notes.append(f"system parameter {full!r} names no component variable: ignored")
            continue
        bound.append((inst, var, v, u, where_sys))
    for inst, var, value, unit, where in bound:
        port = faces[inst].ports.get(var)
        if port is None:
            notes.append(f"{faces[inst].label}: parameter {var!r} of {where} names no "
                         "variable of the FMU: ignored (SSP 1.0)")
            continue
        if unit and port.unit and unit != port.unit:
            raise reader.fail(f"{where}/ssv:Parameter name={var!r}", f"unit {unit!r} differs "
                              f"from the FMU's {port.unit!r}: unit conversions are not "
                              "supported")
        params[inst][var] = float(value) if port.type == "Real" and \
            isinstance(value, int) and not isinstance(value, bool) else value

    connections = []
    for el in conn_els:
        connections.append(_connection(reader, el, by_name, faces))
    fmus = []
    for c in comps:
        ticks = 1
        hint = _number(reader, c["hint"], f"{c['where']}/osp:StepSizeHint")
        if hint is not None:
            n = integer_multiple(hint, base)
            if n is None:
                raise reader.fail(f"{c['where']}/osp:StepSizeHint value={c['hint']}",
                                  f"not a positive integer multiple of the base step {base!r} s")
            ticks = n
        fmus.append(FmuSpec(c["name"], c["path"], params[c["name"]], ticks))
    report = check_system(fmus, connections, faces)
    if report.problems:
        raise SspError(f"{source.name}: " + "; ".join(report.problems))
    try:
        spec = SystemSpec(fmus, connections, base, "jacobi", (), start, stop)
    except ValueError as exc:
        raise SspError(f"{source.name}: {exc}") from None
    outputs = tuple(f"{n}.{p.name}" for n in names for p in faces[n].ports.values()
                    if p.causality == "output" and p.type == "Real")
    return SspSystem(spec, outputs, sys_name, source, tuple(notes))


def _connection(reader: _Reader, el: ET.Element, comps: dict[str, dict[str, Any]],
                faces: dict[str, FmuInterface]) -> Connection:
    se, sc = el.get("startElement"), el.get("startConnector") or ""
    ee, ec = el.get("endElement"), el.get("endConnector") or ""
    where = f"<ssd:Connection {se or '(system)'}.{sc} -> {ee or '(system)'}.{ec}>"
    list(reader.children(el, where, set()))  # refuses transformations
    if not se or not ee:
        raise reader.fail(where, "connects a connector of the system itself (a flat, closed "
                          "system only)")
    ends = []
    for elem, conn, role in ((se, sc, "start"), (ee, ec, "end")):
        comp = comps.get(elem)
        if comp is None:
            raise reader.fail(where, f"{role}Element {elem!r} is not a component of the system")
        if conn not in comp["connectors"]:
            raise reader.fail(where, f"{role}Connector {conn!r} is not a connector of "
                              f"{comp['where']}")
        kind, vtype, unit = comp["connectors"][conn]
        want = "output" if role == "start" else "input"
        if kind != want:
            raise reader.fail(where, f"the {role} connector is of kind {kind!r}, must be "
                              f"{want!r}")
        if vtype and vtype != "Real":
            raise reader.fail(where, f"connector type {vtype}: only Real connections are "
                              "supported")
        port = faces[elem].ports.get(conn)
        if unit and port is not None and port.unit and unit != port.unit:
            raise reader.fail(where, f"connector unit {unit!r} differs from the FMU's "
                              f"{port.unit!r}: unit conversions are not supported")
        ends.append(unit or (port.unit if port is not None else None))
    suppress = el.get("suppressUnitConversion", "false") in ("true", "1")
    if ends[0] and ends[1] and ends[0] != ends[1] and not suppress:
        raise reader.fail(where, f"units differ ({ends[0]!r} -> {ends[1]!r}): unit "
                          "conversions are not supported")
    return Connection(f"{se}.{sc}", f"{ee}.{ec}")
