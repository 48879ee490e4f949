"""Interface check of a system before its first step: do the connected variables fit?

Works on any FMI 2.0 FMUs (nothing here knows the drillstring). For every connection
``source -> target`` of a system it checks, from the modelDescriptions alone:

* both variables exist, the source is an ``output`` and the target an ``input``;
* their types agree and are ``Real`` (the master exchanges Reals only);
* their units agree (a variable without a unit, directly or through its declared type,
  matches any unit: FMI 2.0 makes units optional);
* no input is the target of more than one connection, and no FMU declares a name twice;

and for every start value a system sets (:attr:`FmuSpec.parameters`) that the variable
exists, may be set (causality ``parameter`` or ``input``), has a matching type and lies in the
range the variable declares (``min`` / ``max``). Inputs
that no connection feeds are listed (they keep their start value); whether that is
acceptable is the caller's decision.

Every problem is one line naming both FMUs (instance and file) and the variable. Names
are paired by :func:`pair_by_name` when two FMUs are meant to connect by name (a plant and
a controller): every input of one is fed by the variable of the same name of the other.
"""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path

from fmpy import read_model_description

from .errors import UserError
from .system import Connection, FmuSpec, _did_you_mean, split_variable

__all__ = ["FmuInterface", "InterfaceError", "InterfaceReport", "Port", "check_system",
           "pair_by_name", "read_interface"]

_SETTABLE = ("parameter", "input")
_PY_TYPES = {"Real": (float, int), "Integer": (int,), "Enumeration": (int,),
             "Boolean": (bool,), "String": (str,)}


@dataclass(frozen=True)
class Port:
    """One variable of an FMU as the check sees it.

    Attributes
    ----------
    name : str
    causality : str
        FMI 2.0 causality (``input``, ``output``, ``parameter``, ...).
    type : str
        ``Real``, ``Integer``, ``Enumeration``, ``Boolean`` or ``String``.
    unit : str or None
        The unit, directly or from its declared type; None if it has none.
    low, high : float or None
        The declared ``min`` / ``max`` (directly or from its declared type); None: none.
    """

    name: str
    causality: str
    type: str
    unit: str | None
    low: float | None = None
    high: float | None = None


@dataclass(frozen=True)
class FmuInterface:
    """The variables of one FMU instance.

    Attributes
    ----------
    instance : str
        Instance name in the system.
    path : Path
        The ``.fmu`` file.
    ports : dict[str, Port]
        By variable name (the first declaration of a name).
    duplicates : tuple of str
        Names the modelDescription declares more than once.
    """

    instance: str
    path: Path
    ports: dict[str, Port]
    duplicates: tuple[str, ...] = ()

    @property
    def label(self) -> str:
        """``instance (file.fmu)``, how messages name the FMU."""
        return f"{self.instance} ({self.path.name})"

    def inputs(self) -> list[str]:
        """Names of the ``input`` variables, in declaration order."""
        return [p.name for p in self.ports.values() if p.causality == "input"]

    def outputs(self) -> list[str]:
        """Names of the ``output`` variables, in declaration order."""
        return [p.name for p in self.ports.values() if p.causality == "output"]


def read_interface(instance: str, path: str | Path) -> FmuInterface:
    """The :class:`FmuInterface` of FMU file ``path`` used as ``instance``.

    Raises
    ------
    FileNotFoundError
        No such file.
    UserError
        The file is not an FMU with a readable modelDescription (one line; a ValueError).
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"FMU '{instance}': no file '{path}'")
    try:
        md = read_model_description(str(path), validate=False)
    except Exception as exc:  # noqa: BLE001 - zip, XML or schema errors: one line
        raise UserError(f"FMU '{instance}': cannot read the modelDescription of '{path}': "
                         f"{str(exc).splitlines()[0] if str(exc) else type(exc).__name__}"
                         ) from None
    ports: dict[str, Port] = {}
    for v in md.modelVariables:
        if v.name in ports:
            continue
        unit = v.unit or (getattr(v.declaredType, "unit", None) if v.declaredType else None)
        low, high = (_bound(v, side) for side in ("min", "max"))
        ports[v.name] = Port(v.name, v.causality, v.type, unit or None, low, high)
    counts = Counter(v.name for v in md.modelVariables)
    return FmuInterface(instance, path, ports, tuple(n for n, k in counts.items() if k > 1))


@dataclass
class InterfaceReport:
    """Outcome of :func:`check_system`.

    Attributes
    ----------
    problems : list of str
        One line each; empty if the system fits.
    unconnected : dict[str, list[str]]
        Per instance, the inputs no connection feeds (they keep their start value).
    """

    problems: list[str] = field(default_factory=list)
    unconnected: dict[str, list[str]] = field(default_factory=dict)


class InterfaceError(UserError):
    """FMUs that do not fit: the message is a header line, then one line per problem."""

    def __init__(self, header: str, problems: Sequence[str]):
        self.problems = list(problems)
        super().__init__("\n".join([f"{header}: {len(self.problems)} problem"
                                    f"{'s' if len(self.problems) != 1 else ''}",
                                    *(f"  {p}" for p in self.problems)]))


def pair_by_name(a: FmuInterface, b: FmuInterface) -> list[tuple[str, str]]:
    """Connections between two FMUs by name: each input of one is fed by the other's namesake.

    Returns
    -------
    list of (str, str)
        ``("inst.var", "inst.var")`` source -> target pairs: for every name both FMUs
        declare where one of them declares it an ``input``, from the other one (whatever
        its causality: :func:`check_system` reports a namesake that is not an output).
        A name both declare as ``input`` is paired both ways, so both inputs are
        reported. Inputs of ``b`` come first, then inputs of ``a``, each in declaration
        order.
    """
    pairs = []
    for dst, src in ((b, a), (a, b)):
        for name in dst.inputs():
            if name in src.ports:
                pairs.append((f"{src.instance}.{name}", f"{dst.instance}.{name}"))
    return pairs


def _bound(v, side: str) -> float | None:
    """A variable's declared ``min`` or ``max`` (its own, else its declared type's)."""
    value = getattr(v, side, None)
    if value is None and v.declaredType is not None:
        value = getattr(v.declaredType, side, None)
    try:
        return None if value is None else float(value)
    except (TypeError, ValueError):
        return None


def _outside(port: Port, value) -> str:
    """Why ``value`` lies outside the range ``port`` declares ("" if inside or none)."""
    if isinstance(value, bool) or not isinstance(value, (int, float)) or value != value:
        return ""
    if (port.low is not None and value < port.low) or (port.high is not None
                                                        and value > port.high):
        lo = "-inf" if port.low is None else f"{port.low:g}"
        hi = "inf" if port.high is None else f"{port.high:g}"
        return f"outside its declared range [{lo}, {hi}]"
    return ""


def _value_fits(port: Port, value) -> bool:
    if port.type == "Real" and isinstance(value, bool):
        return False
    if port.type in ("Integer", "Enumeration") and isinstance(value, bool):
        return False
    if port.type == "Real" and isinstance(value, float) and not math.isfinite(value):
        return True  # inf/nan reach the FMU, which judges them
    return isinstance(value, _PY_TYPES.get(port.type, ()))


def check_system(fmus: Sequence[FmuSpec], connections: Iterable[Connection | tuple[str, str]],
                 interfaces: Mapping[str, FmuInterface] | None = None) -> InterfaceReport:
    """Check connections and start values of a system against the FMUs' modelDescriptions.

    Parameters
    ----------
    fmus : sequence of FmuSpec
        The instances (their ``parameters`` are checked too).
    connections : iterable of Connection or (source, target)
        ``'inst.var'`` references.
    interfaces : mapping, optional
        Already read :class:`FmuInterface` per instance (read from the files otherwise).

    Returns
    -------
    InterfaceReport
        Problems (one line each) and unconnected inputs per instance.

    Raises
    ------
    FileNotFoundError, ValueError
        An FMU file is missing or unreadable.
    """
    faces = dict(interfaces or {})
    for spec in fmus:
        if spec.name not in faces:
            faces[spec.name] = read_interface(spec.name, spec.path)
    report = InterfaceReport()
    problems = report.problems
    for face in faces.values():
        for name in face.duplicates:
            problems.append(f"{face.label} declares variable '{name}' more than once")
    fed: dict[str, list[str]] = {}
    for c in connections:
        source, target = (c.source, c.target) if isinstance(c, Connection) else c
        sf, sv = split_variable(source, "connection source")
        tf, tv = split_variable(target, "connection target")
        s_face, t_face = faces.get(sf), faces.get(tf)
        if s_face is None or t_face is None:
            problems.append(f"connection {source} -> {target}: unknown instance "
                            f"'{sf if s_face is None else tf}'")
            continue
        where = f"{s_face.label} '{sv}' -> {t_face.label} '{tv}'"
        fed.setdefault(target, []).append(source)
        s_port, t_port = s_face.ports.get(sv), t_face.ports.get(tv)
        if s_port is None or t_port is None:
            missing = (s_face, sv) if s_port is None else (t_face, tv)
            problems.append(f"{where}: {missing[0].label} has no variable '{missing[1]}'")
            continue
        if s_port.causality != "output":
            problems.append(f"{where}: the source is declared '{s_port.causality}' in "
                            f"{s_face.label}, must be 'output'")
        if t_port.causality != "input":
            problems.append(f"{where}: the target is declared '{t_port.causality}' in "
                            f"{t_face.label}, must be 'input'")
        if s_port.type != t_port.type:
            problems.append(f"{where}: types differ ({s_port.type} -> {t_port.type})")
        elif s_port.type != "Real":
            problems.append(f"{where}: type {s_port.type}; the master connects Real "
                            f"variables only")
        if s_port.unit and t_port.unit and s_port.unit != t_port.unit:
            problems.append(f"{where}: units differ ('{s_port.unit}' -> '{t_port.unit}'); "
                            f"no unit conversion is done")
    for target, sources in fed.items():
        if len(sources) > 1:
            tf, tv = target.split(".", 1)
            problems.append(f"{faces[tf].label} input '{tv}' is connected {len(sources)} "
                            f"times (from {', '.join(sources)})")
    for spec in fmus:
        face = faces[spec.name]
        for key, value in spec.parameters.items():
            port = face.ports.get(key)
            if port is None:
                problems.append(f"{face.label} has no variable '{key}' to set (start value "
                                f"{value!r}){_did_you_mean(key, list(face.ports))}")
            elif port.causality not in _SETTABLE:
                problems.append(f"{face.label} '{key}' is declared '{port.causality}'; only "
                                f"parameters and inputs can be given start values")
            elif not _value_fits(port, value):
                problems.append(f"{face.label} '{key}' is {port.type}; got "
                                f"{type(value).__name__} {value!r}")
            elif why := _outside(port, value):
                problems.append(f"{face.label} '{key}' = {value!r} is {why}")
        missing = [n for n in face.inputs() if f"{spec.name}.{n}" not in fed]
        if missing:
            report.unconnected[spec.name] = missing
    return report
