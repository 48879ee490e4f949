"""Plant + controller FMU pair: wiring by name and the interface check before the first step.

Any plant FMU and any controller FMU can be paired (``[plant] fmu`` / ``[controller] fmu``
in a scene, ``drillcosim run --plant-fmu P --controller-fmu C``). They connect by name:
every input of one is fed by the variable of the same name of the other (the strains
``strain<s>_<C|E>`` plant -> controller, the forces ``actuator<s>_force_<C|E>`` controller ->
plant). Before the first step :func:`wire_pair` checks the pair with
:func:`cosim.master.interface.check_system` (causality, type, unit, nothing connected twice,
start values) and reports every problem, one line each naming both FMUs and the variable.

Unfed inputs
------------
An input the other FMU does not feed is a problem, with one exception: the inputs of a
whole *site* the other FMU does not serve. A site ``s`` is the number in ``actuator<s>_...``
(plant inputs) and ``strain<s>_...`` (controller inputs). If the controller has no
variable ``actuator<s>_...`` at all (it serves fewer sites than the plant has), the plant's
``actuator<s>_...`` inputs keep their start value (0 N for the project's plant: no
actuation at that site), and one :class:`InterfaceWarning` names them. The same holds for a
controller serving more sites than the plant has (its ``strain<s>_...`` inputs keep their
start value; its extra forces go nowhere). A site served in part (``actuator1_force_C`` fed,
``actuator1_force_E`` not) is a problem.
"""

from __future__ import annotations

import re
import warnings
from collections.abc import Sequence
from dataclasses import dataclass

from drillcosim.cosim.master.interface import (
    FmuInterface,
    InterfaceError,
    check_system,
    pair_by_name,
)
from drillcosim.cosim.master.system import Connection, FmuSpec

__all__ = ["InterfaceWarning", "PairWiring", "connections_of", "site_of", "wire_pair"]

_SITE = re.compile(r"^(actuator|strain)(\d+)_")


class InterfaceWarning(UserWarning):
    """A pair that runs but not as a whole: e.g. a plant site no controller output feeds."""


def site_of(name: str) -> tuple[str, int] | None:
    """``("actuator", 2)`` for ``actuator2_force_C``, ``("strain", 1)`` for ``strain1_E``, else None."""
    m = _SITE.match(name)
    return (m.group(1), int(m.group(2))) if m else None


def _serves(face: FmuInterface, kind: str, site: int) -> bool:
    return any(site_of(n) == (kind, site) for n in face.ports)


@dataclass(frozen=True)
class PairWiring:
    """Connections of a plant/controller pair and what stays unconnected.

    Attributes
    ----------
    connections : tuple of (str, str)
        ``('inst.var', 'inst.var')`` source -> target (controller inputs first).
    unserved : tuple of str
        ``'inst.var'`` inputs of whole sites the other FMU does not serve (keep their start).
    """

    connections: tuple[tuple[str, str], ...]
    unserved: tuple[str, ...]


def wire_pair(plant: FmuInterface, controller: FmuInterface, fmus: Sequence[FmuSpec],
              extra_problems: Sequence[str] = ()) -> PairWiring:
    """Connect ``plant`` and ``controller`` by name and check the pair.

    Parameters
    ----------
    plant, controller : FmuInterface
    fmus : sequence of FmuSpec
        The two instances with the start values the system will set (checked too).
    extra_problems : sequence of str
        Problems the caller found (e.g. a scene key the controller FMU cannot take),
        reported together with the others.

    Returns
    -------
    PairWiring

    Raises
    ------
    InterfaceError
        Every problem, one line each, naming both FMUs and the variable.

    Warns
    -----
    InterfaceWarning
        Inputs of whole sites the other FMU does not serve (they keep their start value).
    """
    pairs = pair_by_name(plant, controller)
    report = check_system(fmus, pairs, {plant.instance: plant, controller.instance: controller})
    problems = list(report.problems)
    unserved = []
    for face, other, kind in ((plant, controller, "actuator"), (controller, plant, "strain")):
        for name in report.unconnected.get(face.instance, []):
            site = site_of(name)
            if site is not None and site[0] == kind and not _serves(other, kind, site[1]):
                unserved.append(f"{face.instance}.{name}")
            else:
                problems.append(f"{face.label} input '{name}' is not fed: {other.label} has "
                                f"no variable '{name}'")
    problems += list(extra_problems)
    if problems:
        raise InterfaceError(f"{plant.label} and {controller.label} do not fit", problems)
    if unserved:
        warnings.warn(InterfaceWarning(
            f"{plant.label} and {controller.label}: inputs of sites the other FMU does not "
            f"serve keep their start value: {', '.join(unserved)}"), stacklevel=3)
    return PairWiring(tuple(pairs), tuple(unserved))


def connections_of(wiring: PairWiring, delays: dict[str, float], coupling: str) -> list[Connection]:
    """Master connections of a wiring; ``delays[instance]`` is the delay of what it receives [s]."""
    return [Connection(s, t, delays.get(t.split(".", 1)[0], 0.0), coupling)
            for s, t in wiring.connections]
