"""Export a :class:`~cosim.master.system.SystemSpec` as an SSP 1.0 archive (``.ssp``).

The archive holds ``SystemStructure.ssd`` and the FMUs under ``resources/``. It
is written for what libcosim's SSP loader (``CosimExecution.from_ssp_file`` in
libcosimpy) reads:

* ``ssd:Component`` elements (``source="resources/<file>.fmu"``) with their
  ``ssd:Connectors`` (kind ``input`` / ``output`` / ``parameter``; type
  ``ssc:Real``, ``ssc:Integer``, ``ssc:Boolean`` or ``ssc:String``);
* parameter start values as an inline ``ssd:ParameterBindings /
  ssd:ParameterBinding / ssd:ParameterValues / ssv:ParameterSet`` (``Real``,
  ``Integer``, ``Boolean``, ``String``); every component's set carries the same
  name, the system name (libcosim applies each component's first set; Ecos applies
  the sets of one name, ``ecos simulate --parameterSet <system name>``);
* a multirate FMU's period as the OSP annotation ``osp:StepSizeHint`` [s]
  (libcosim rounds it to a multiple of the base step);
* ``ssd:Connections`` without transformations;
* ``ssd:DefaultExperiment`` (``startTime``, ``stopTime`` [s]) with the OSP
  annotation ``osp:FixedStepAlgorithm baseStepSize`` [s].

libcosim only accepts the literal prefixes ``ssd:``, ``ssc:``, ``ssv:`` and
``osp:`` (it does not resolve namespaces), so they are written exactly so.

Not representable in SSP 1.0 (nor in libcosim): transport delays on
connections, linear-extrapolation coupling and Gauss-Seidel stepping (libcosim's
fixed-step algorithm is Jacobi-like with a zero-order hold). :func:`export_ssp`
refuses such systems unless ``strict=False``, in which case the archive holds
the system without them and the omissions are returned (and listed in the
``ssd:System`` description).
"""

from __future__ import annotations

import zipfile
from dataclasses import dataclass
from pathlib import Path
from xml.sax.saxutils import quoteattr

from fmpy import read_model_description

from .files import AtomicFile
from .system import SystemSpec, split_variable

__all__ = ["SspExport", "export_ssp", "ssd_xml", "unsupported_features"]

NS = {
    "ssd": "http://ssp-standard.org/SSP1/SystemStructureDescription",
    "ssc": "http://ssp-standard.org/SSP1/SystemStructureCommon",
    "ssv": "http://ssp-standard.org/SSP1/SystemStructureParameterValues",
    "osp": "http://opensimulationplatform.com/SSP/OSPAnnotations",
}
_SSC_TYPES = {"Real": "Real", "Integer": "Integer", "Enumeration": "Integer",
              "Boolean": "Boolean", "String": "String"}


@dataclass(frozen=True)
class SspExport:
    """Result of :func:`export_ssp`.

    Attributes
    ----------
    path : Path
        The ``.ssp`` file.
    omitted : tuple of str
        Features of the system the archive does not represent (empty if exact).
    """

    path: Path
    omitted: tuple[str, ...]


def unsupported_features(system: SystemSpec) -> list[str]:
    """Features of ``system`` an SSP 1.0 archive (as libcosim reads it) cannot express."""
    out = []
    if system.algorithm != "jacobi":
        out.append(f"algorithm '{system.algorithm}' (SSP/libcosim: Jacobi-like fixed step)")
    for c in system.connections:
        if c.delay > 0:
            out.append(f"delay {c.delay:g} s on {c.source} -> {c.target}")
        if c.coupling != "zoh":
            out.append(f"coupling '{c.coupling}' on {c.source} -> {c.target}")
    return out


def _fmt_value(vtype: str, value) -> str:
    if vtype == "Real":
        return repr(float(value))
    if vtype == "Integer":
        return str(int(value))
    if vtype == "Boolean":
        return "true" if value else "false"
    return str(value)


def _resource_names(system: SystemSpec) -> dict[Path, str]:
    names: dict[Path, str] = {}
    used: set[str] = set()
    for spec in system.fmus:
        path = Path(spec.path).resolve()
        if path in names:
            continue
        stem, name, i = path.stem, path.name, 1
        while name in used:
            i += 1
            name = f"{stem}_{i}.fmu"
        used.add(name)
        names[path] = name
    return names


def ssd_xml(system: SystemSpec, name: str = "drillcosim", description: str = "") -> str:
    """``SystemStructure.ssd`` of ``system`` (FMU sources ``resources/<file>.fmu``).

    Raises
    ------
    ValueError
        If a parameter or connected variable does not exist in its FMU.
    """
    resources = _resource_names(system)
    ports: dict[str, dict[str, str]] = {f.name: {} for f in system.fmus}
    for c in system.connections:
        for ref in (c.source, c.target):
            fmu, var = split_variable(ref, "connection")
            ports[fmu][var] = ""
    H = system.base_step
    lines = ['<?xml version="1.0" encoding="UTF-8"?>',
             f'<ssd:SystemStructureDescription name={quoteattr(name)} version="1.0"']
    lines += [f'    xmlns:{p}="{uri}"' for p, uri in NS.items()]
    lines[-1] += ">"
    desc = f" description={quoteattr(description)}" if description else ""
    lines.append(f"  <ssd:System name={quoteattr(name)}{desc}>")
    lines.append("    <ssd:Elements>")
    for spec in system.fmus:
        path = Path(spec.path).resolve()
        md = read_model_description(str(path))
        variables = {v.name: v for v in md.modelVariables}
        for key in list(ports[spec.name]) + list(spec.parameters):
            if key not in variables:
                raise ValueError(f"FMU '{spec.name}' ({path.name}) has no variable '{key}'")
        src = f"resources/{resources[path]}"
        lines.append(f"      <ssd:Component name={quoteattr(spec.name)} "
                     f'type="application/x-fmu-sharedlibrary" source={quoteattr(src)}>')
        lines.append("        <ssd:Connectors>")
        for var_name in dict.fromkeys([*ports[spec.name], *spec.parameters]):
            v = variables[var_name]
            kind = v.causality if v.causality in ("input", "output", "parameter") else "parameter"
            lines.append(f"          <ssd:Connector name={quoteattr(var_name)} kind=\"{kind}\">"
                         f"<ssc:{_SSC_TYPES.get(v.type, 'Real')}/></ssd:Connector>")
        lines.append("        </ssd:Connectors>")
        if spec.parameters:
            lines += ["        <ssd:ParameterBindings>", "          <ssd:ParameterBinding>",
                      "            <ssd:ParameterValues>",
                      f'              <ssv:ParameterSet version="1.0" '
                      f"name={quoteattr(name)}>",
                      "                <ssv:Parameters>"]
            for key, value in spec.parameters.items():
                vtype = _SSC_TYPES.get(variables[key].type, "Real")
                lines.append(f"                  <ssv:Parameter name={quoteattr(key)}>"
                             f"<ssv:{vtype} value={quoteattr(_fmt_value(vtype, value))}/>"
                             "</ssv:Parameter>")
            lines += ["                </ssv:Parameters>", "              </ssv:ParameterSet>",
                      "            </ssd:ParameterValues>", "          </ssd:ParameterBinding>",
                      "        </ssd:ParameterBindings>"]
        if spec.sample_period_ticks > 1:
            lines += ["        <ssd:Annotations>",
                      '          <ssc:Annotation type="com.opensimulationplatform">',
                      f'            <osp:StepSizeHint value="{spec.sample_period_ticks * H!r}"/>',
                      "          </ssc:Annotation>", "        </ssd:Annotations>"]
        lines.append("      </ssd:Component>")
    lines.append("    </ssd:Elements>")
    if system.connections:
        lines.append("    <ssd:Connections>")
        for c in system.connections:
            sf, sv = split_variable(c.source, "source")
            tf, tv = split_variable(c.target, "target")
            lines.append(f"      <ssd:Connection startElement={quoteattr(sf)} "
                         f"startConnector={quoteattr(sv)} endElement={quoteattr(tf)} "
                         f"endConnector={quoteattr(tv)}/>")
        lines.append("    </ssd:Connections>")
    lines.append("  </ssd:System>")
    stop = f' stopTime="{system.stop_time!r}"' if system.stop_time is not None else ""
    lines += [f'  <ssd:DefaultExperiment startTime="{system.start_time!r}"{stop}>',
              "    <ssd:Annotations>",
              '      <ssc:Annotation type="com.opensimulationplatform">',
              f'        <osp:Algorithm><osp:FixedStepAlgorithm baseStepSize="{H!r}"/>'
              "</osp:Algorithm>",
              "      </ssc:Annotation>", "    </ssd:Annotations>",
              "  </ssd:DefaultExperiment>", "</ssd:SystemStructureDescription>", ""]
    return "\n".join(lines)


def export_ssp(system: SystemSpec, path: str | Path, *, name: str = "drillcosim",
               strict: bool = True) -> SspExport:
    """Write ``system`` as an SSP archive (atomically, :class:`cosim.master.files.AtomicFile`).

    Parameters
    ----------
    system : SystemSpec
    path : path-like
        Target ``.ssp`` file.
    name : str
        System name in the SSD.
    strict : bool
        Refuse (``ValueError``) a system with delays, linear coupling or
        Gauss-Seidel stepping; with False, export without them.

    Returns
    -------
    SspExport

    Raises
    ------
    ValueError
        Unsupported features (strict), unknown variables, or a path not ending in ``.ssp``.
    """
    path = Path(path)
    if path.suffix != ".ssp":
        raise ValueError(f"SSP export: the file name must end in '.ssp' (libcosim unpacks "
                         f"only those), got '{path}'")
    omitted = unsupported_features(system)
    if omitted and strict:
        raise ValueError(f"SSP export: not representable in SSP 1.0/libcosim: {omitted[0]}"
                         + (f" (and {len(omitted) - 1} more)" if len(omitted) > 1 else "")
                         + "; use strict=False to export without them")
    desc = ("exported by drillcosim without: " + "; ".join(omitted)) if omitted else ""
    xml = ssd_xml(system, name, desc)
    path.parent.mkdir(parents=True, exist_ok=True)
    with AtomicFile(path, "wb") as fh, zipfile.ZipFile(fh, "w") as zf:
        zf.writestr("SystemStructure.ssd", xml, compress_type=zipfile.ZIP_DEFLATED)
        for src, res in _resource_names(system).items():
            zf.write(src, f"resources/{res}", compress_type=zipfile.ZIP_STORED)
    return SspExport(path, tuple(omitted))
