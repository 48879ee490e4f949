"""A plant FMU and its controller FMUs: wiring by name and the interface check before the
first step.

Any plant FMU and any controller FMUs can be paired (``[plant] fmu`` / ``[controller] fmu``
in a scene, ``drillcosim run --plant-fmu P --controller-fmu C``). They connect by name:
every input of one is fed by the variable of the same name of the other (the strains
``strain<s>_<C|E>`` plant -> strain controller, the forces ``actuator<s>_force_<C|E>``
controller -> plant; ``top_rotary_speed`` / ``top_torque`` plant -> top-drive controller,
``top_drive_torque`` back). Controllers are not connected to each other. Before the first step
:func:`wire_system` checks the system with :func:`cosim.master.interface.check_system`
(causality, type, unit, nothing connected twice, start values) and reports every problem, one
line each naming both FMUs and the variable.

Unfed inputs
------------
An input no other FMU feeds is a problem, with two exceptions: the inputs of a plant that runs
alone (the open loop: they keep their start value; a warning names the inputs other than the
actuator forces, e.g. a top-drive torque), and the inputs of a whole *site* the other FMU
does not serve. A site ``s`` is the number in ``actuator<s>_...``
(plant inputs) and ``strain<s>_...`` (controller inputs). If the controller has no
variable ``actuator<s>_...`` at all (it serves fewer sites than the plant has), the plant's
``actuator<s>_...`` inputs keep their start value (0 N for the project's plant: no
actuation at that site), and one :class:`InterfaceWarning` names them. The same holds for a
controller serving more sites than the plant has (its ``strain<s>_...`` inputs keep their
start value; its extra forces go nowhere). A site served in part (``actuator1_force_C`` fed,
``actuator1_force_E`` not) is a problem.
"""

from __future__ import annotations

import warnings
from collections.abc import Sequence
from dataclasses import dataclass

from drillcosim.cosim.master.interface import (
    FmuInterface,
    InterfaceError,
    check_system,
    pair_by_name,
)
from drillcosim.cosim.master.system import FmuSpec
from drillcosim.plant.signals import AXES, actuator_force, actuator_power, sites_in, strain

__all__ = ["InterfaceWarning", "PairWiring", "wire_system"]


class InterfaceWarning(UserWarning):
    """A pair that runs but not as a whole: e.g. a plant site no controller output feeds."""


def _site_names(kind: str, site: int) -> tuple[str, ...]:
    """The names of site ``site`` of one kind: ``"actuator"`` (forces and power) or ``"strain"``."""
    if kind == "strain":
        return tuple(strain(site, a) for a in AXES)
    return (*(actuator_force(site, a) for a in AXES), actuator_power(site))


def _sites(face: FmuInterface, kind: str) -> dict[str, int]:
    """``{name: site}`` of the face's ``kind`` names (built from the site numbers it has)."""
    return {n: s for s in sites_in(face.ports) for n in _site_names(kind, s) if n in face.ports}


def _serves(face: FmuInterface, kind: str, site: int) -> bool:
    return any(n in face.ports for n in _site_names(kind, site))


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


def wire_system(plant: FmuInterface, controllers: Sequence[FmuInterface],
                fmus: Sequence[FmuSpec], extra_problems: Sequence[str] = ()) -> PairWiring:
    """Connect ``plant`` with each of ``controllers`` by name and check the system.

    Parameters
    ----------
    plant : FmuInterface
    controllers : sequence of FmuInterface
        Possibly none (the plant runs alone).
    fmus : sequence of FmuSpec
        The instances with the start values the system will set (checked too).
    extra_problems : sequence of str
        Problems the caller found (e.g. a scene key a controller FMU cannot take),
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
        Inputs of whole sites the other FMU does not serve, or plant inputs other than the
        actuator forces that nothing feeds (they keep their start value).
    """
    pairs = [pair for c in controllers for pair in pair_by_name(plant, c)]
    faces = {plant.instance: plant, **{c.instance: c for c in controllers}}
    report = check_system(fmus, pairs, faces)
    problems = list(report.problems)
    unserved, idle = [], []
    others = " nor ".join(c.label for c in controllers)
    actuator_site = _sites(plant, "actuator")
    for name in report.unconnected.get(plant.instance, []):
        site = actuator_site.get(name)
        if site is not None and not any(_serves(c, "actuator", site) for c in controllers):
            if controllers:
                unserved.append(f"{plant.instance}.{name}")
        elif not controllers:
            idle.append(f"{plant.instance}.{name}")
        else:
            problems.append(f"{plant.label} input '{name}' is not fed: {others} has no "
                            f"variable '{name}'")
    for c in controllers:
        strain_site = _sites(c, "strain")
        for name in report.unconnected.get(c.instance, []):
            site = strain_site.get(name)
            if site is not None and not _serves(plant, "strain", site):
                unserved.append(f"{c.instance}.{name}")
            else:
                problems.append(f"{c.label} input '{name}' is not fed: {plant.label} has no "
                                f"variable '{name}'")
    problems += list(extra_problems)
    if problems:
        label = " and ".join([plant.label, *(c.label for c in controllers)])
        header = f"{label} do not fit" if controllers else f"{label} cannot take the scene's settings"
        raise InterfaceError(header, problems)
    if unserved:
        warnings.warn(InterfaceWarning(
            f"{' and '.join([plant.label, *(c.label for c in controllers)])}: inputs of sites "
            f"the other FMU does not serve keep their start value: {', '.join(unserved)}"),
            stacklevel=3)
    if idle:
        warnings.warn(InterfaceWarning(
            f"{plant.label} runs without a controller: its inputs {', '.join(idle)} keep their "
            f"start value"), stacklevel=3)
    return PairWiring(tuple(pairs), tuple(unserved))
