"""Port tables of the controller laws: every variable of a law as data.

A law's table (``Law.ports(layout)``) lists its inputs, outputs and parameters in the order of
its arrays (inputs and outputs: the order of the law's input and output vectors; parameters:
the order its FMU declares them), each a :class:`Port`: name, causality, variability, unit,
description, start, declared range and FMI type. The FMU adapter registers its variables from
it, the in-process slave takes its inputs and outputs from it, the scene's start values, the
scene schema and the generated interface docs read it. So a variable is described once.

This module is also the one place the controller side spells a variable name that has a number
in it (:func:`strain`, :func:`actuator_force`, :func:`gain_matrix_entry`, :func:`limit`); a name
is never parsed back: whoever needs a site builds the candidate names and looks them up. The
plant spells the same signal names on its side (``plant/signals.py``): the two connect by name,
as any two FMUs do.

Only the standard library is imported (the package is vendored into the FMUs).
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from typing import Any, NamedTuple

__all__ = ["AXES", "CAUSALITIES", "TYPES", "VARIABILITIES", "Port", "actuator_force",
           "by_name", "gain_matrix_entry", "inputs", "limit", "outputs", "parameter",
           "parameters", "real_input", "real_output", "site_channels", "strain",
           "strain_site_ports"]

CAUSALITIES = ("input", "output", "parameter")
VARIABILITIES = ("continuous", "tunable", "fixed")
TYPES = ("Real", "Integer", "Boolean", "String")
#: Gauge axes of an actuator site, in channel order: C bends about body y, E about body x.
AXES: tuple[str, ...] = ("C", "E")
#: The actuator pair at a gauge: a force > 0 is compressive at the pair point, tensile at the
#: gauge point (paper section 3.3).
_PAIR = {"C": "D", "E": "F"}


class Port(NamedTuple):
    """One variable of a law (an FMU variable of its FMU).

    Attributes
    ----------
    name : str
        Variable name.
    causality : {"input", "output", "parameter"}
    variability : {"continuous", "tunable", "fixed"}
        Inputs and outputs are continuous; a tunable parameter may change between steps.
    unit : str
        FMI unit name (``"N.m"``, ``"rad/s"``, ``"1"``); ``""`` for none (Integer, Boolean).
    description : str
    start : float, int, bool, str or None
        Start value (inputs and outputs: 0).
    range : (float, float) or None
        Declared ``[min, max]`` of a parameter (FMI ``min`` / ``max``); None: unbounded.
    type : {"Real", "Integer", "Boolean", "String"}
    """

    name: str
    causality: str
    variability: str
    unit: str
    description: str
    start: Any = 0.0
    range: tuple[float, float] | None = None
    type: str = "Real"


def real_input(name: str, unit: str, description: str) -> Port:
    """A Real input (continuous, start 0)."""
    return Port(name, "input", "continuous", unit, description)


def real_output(name: str, unit: str, description: str) -> Port:
    """A Real output (continuous, start 0: no output before the first step)."""
    return Port(name, "output", "continuous", unit, description)


def parameter(name: str, unit: str, description: str, start: Any, *,
              range: tuple[float, float] | None = None, tunable: bool = True,
              type: str = "Real") -> Port:
    """A parameter (tunable unless ``tunable=False``)."""
    return Port(name, "parameter", "tunable" if tunable else "fixed", unit, description, start,
                range, type)


def inputs(ports: Iterable[Port]) -> tuple[Port, ...]:
    """The inputs of a table, in order."""
    return tuple(p for p in ports if p.causality == "input")


def outputs(ports: Iterable[Port]) -> tuple[Port, ...]:
    """The outputs of a table, in order."""
    return tuple(p for p in ports if p.causality == "output")


def parameters(ports: Iterable[Port]) -> tuple[Port, ...]:
    """The parameters of a table, in order."""
    return tuple(p for p in ports if p.causality == "parameter")


def by_name(ports: Iterable[Port]) -> dict[str, Port]:
    """``{name: port}`` of a table."""
    return {p.name: p for p in ports}


# ------------------------------------------------------------------------ names with numbers
def strain(site: int, axis: str) -> str:
    """``strain<s>_<axis>``: the bending strain [1] at gauge ``axis`` of site ``s`` (a strain
    law's input, the plant's output)."""
    return f"strain{site}_{axis}"


def actuator_force(site: int, axis: str) -> str:
    """``actuator<s>_force_<axis>``: the actuator force [N] at gauge ``axis`` of site ``s`` (a
    strain law's output, the plant's input)."""
    return f"actuator{site}_force_{axis}"


def gain_matrix_entry(row: int, column: int) -> str:
    """``gain_matrix_<i>_<j>``: the relative gain [1] from the strain of site ``j`` to the
    force of site ``i`` (1-based)."""
    return f"gain_matrix_{row}_{column}"


def limit(side: str, output: str) -> str:
    """``<side>_limit_<output>``: the saturation limit (``side`` ``"lower"`` or ``"upper"``) of
    an output."""
    return f"{side}_limit_{output}"


def site_channels(n_sites: int) -> list[tuple[int, str]]:
    """``(site, axis)`` of the channels of ``n_sites`` sites, in channel order."""
    return [(s, a) for s in range(1, n_sites + 1) for a in AXES]


def strain_site_ports(n_sites: int, site_names: Mapping[int, str] | None = None,
                      ) -> tuple[Port, ...]:
    """The inputs and outputs of a strain law of ``n_sites`` sites: the strains, then the
    actuator forces, two channels (C, E) per site in channel order.

    ``site_names`` (site -> text, e.g. ``"site 1 (long span)"``) words the descriptions;
    default ``"site <s>"``.
    """
    def where(s: int) -> str:
        return (site_names or {}).get(s, f"site {s}")

    channels = site_channels(n_sites)
    return (
        *(real_input(strain(s, a), "1", f"Surface strain at gauge {a}, {where(s)}; tensile > 0")
          for s, a in channels),
        *(real_output(actuator_force(s, a), "N",
                      f"Actuator force at {where(s)}, axis {a}; > 0 = compressive at "
                      f"{_PAIR[a]} / tensile at {a} (couple opposing positive strain)")
          for s, a in channels),
    )


def names(ports: Sequence[Port]) -> tuple[str, ...]:
    """The names of ``ports``, in order."""
    return tuple(p.name for p in ports)
