"""The plant's port table: every plant output, plant input and parameter, and the wiring names.

The one place the plant side spells a signal name. Everything else asks this module: the
kernels fill their output vector in the order of :func:`plant_outputs`, the plant FMU registers
its variables from :class:`Port` rows (:func:`io_ports`, :func:`plant.scene.parameter_table`),
the co-simulation wires them by name (``"<instance>.<name>"``, :func:`ref`) and the studies,
plots and summaries read recorded columns by them. A name is never parsed back: whoever needs a
site or a body number builds the candidate names and looks them up (:func:`sites_in`,
:func:`bodies_in`). The controllers spell their side in ``controller/ports.py`` (the same
names: the two connect by name, as any two FMUs do; each package is vendored alone, so the
row type :class:`Port` is declared in both, a test keeps them the same).

Names
-----
Per contact body ``b`` (3D model; :data:`CONTACT_QUANTITIES`):
``body<b>_X``, ``body<b>_Y`` [m], ``body<b>_radial_deflection`` [m],
``body<b>_contact_force`` [N] (and, extended, ``body<b>_whirl_speed``, ``_whirl_direction``).
Per actuator site ``s`` (1-based, top to bottom) and gauge axis ``a`` in :data:`AXES`:
``strain<s>_<a>`` [1] (plant output, controller input), ``actuator<s>_force_<a>`` [N]
(controller output, plant input), ``actuator<s>_power`` [W] (plant output).
Top drive: ``top_rotary_speed`` [rad/s], ``top_torque`` [N m] (plant outputs),
``top_drive_torque`` [N m] / ``top_drive_speed_command`` [rad/s] (plant inputs).
Instances of a drillstring system: :data:`PLANT`, :data:`CONTROLLER`, :data:`TOP_DRIVE`.
"""

from __future__ import annotations

from collections.abc import Collection, Iterable, Sequence
from typing import Any, NamedTuple

__all__ = ["AXES", "CONTACT_QUANTITIES", "CONTROLLER", "EXTENDED_SCALAR_OUTPUTS",
           "FIELD_SCALAR_OUTPUTS", "INSTANCES", "PLANT", "SCALAR_OUTPUTS", "TOP_DRIVE",
           "TOP_DRIVE_SPEED_COMMAND", "TOP_DRIVE_TORQUE", "WHIRL_MIN_RADIUS", "Port",
           "actuator_force", "actuator_input_rows", "actuator_inputs", "actuator_power",
           "bodies_in", "body_signal", "fmi_unit", "io_ports", "parameter_name",
           "plant_outputs", "ref", "site_channels", "site_signals", "sites_in", "strain"]

PLANT = "plant"                       #: instance name of the plant
CONTROLLER = "controller"             #: instance name of the strain controller
TOP_DRIVE = "top_drive_controller"    #: instance name of the top-drive speed controller
INSTANCES = (PLANT, CONTROLLER, TOP_DRIVE)

AXES = ("C", "E")                     #: gauge axes of a site: C bends about body y, E about x
CONTACT_QUANTITIES = ("X", "Y", "radial_deflection", "contact_force")

TOP_DRIVE_TORQUE = "top_drive_torque"                #: plant input, top_drive.mode "torque"
TOP_DRIVE_SPEED_COMMAND = "top_drive_speed_command"  #: plant input, top_drive.mode "speed"
#: Whirl below this radius [m] is not defined (the centre sits on the well axis): speed 0.
WHIRL_MIN_RADIUS = 1e-6

#: Scalars at the end of every output vector (both models), after the per-body/per-site blocks.
SCALAR_OUTPUTS = (
    ("bit_axial_force", "N", "compressive force between bit and rock (weight on bit)"),
    ("bit_torque", "N m", "resisting torque at the bit"),
    ("top_torque", "N m", "torque applied by the top drive"),
    ("hook_load", "N", "axial tension in the top spring"),
    ("top_rotary_speed", "rad/s", "rotary speed of the top drive"),
    ("bit_rotary_speed", "rad/s", "spin rate of the bit segment"),
    ("bit_axial_displacement", "m", "axial displacement of the bit end from its initial position"),
    ("bit_twist", "rad", "bit rotation angle minus top-drive angle"),
    ("total_energy", "J", "kinetic + elastic + gravity potential energy of the string"),
)
#: Scalars of the extensions (after :data:`SCALAR_OUTPUTS` when the outputs are extended).
EXTENDED_SCALAR_OUTPUTS = (
    ("rate_of_penetration", "m/s", "rate at which the hole bottom deepens (bit.model 'cutting')"),
    ("drilled_depth", "m", "hole drilled since the start (bit.model 'cutting')"),
    ("depth_of_cut", "m", "depth of cut per bit revolution d (bit.model 'cutting')"),
    ("bit_on_bottom", "1", "1 while the bit presses on the rock, 0 off bottom (bit bounce)"),
)
#: Summary of a field string (sections or a trajectory; 3D model), after the extensions'.
FIELD_SCALAR_OUTPUTS = (
    ("max_radial_deflection", "m",
     "largest lateral deflection of a contact point (any body, the bit) from the hole axis"),
    ("wall_contact_force", "N", "sum of the normal forces of the hole wall on the string"),
    ("bodies_in_contact", "1", "number of contact points touching the hole wall"),
)


class Port(NamedTuple):
    """One variable of the plant FMU (the row of ``controller/ports.py``, the same fields).

    Attributes
    ----------
    name : str
    causality : {"input", "output", "parameter"}
    variability : {"continuous", "fixed"}
    unit : str
        FMI unit name (``"N.m"``); ``""`` for none.
    description : str
    start : float, int, bool, str or None
        Start value; None for an output computed at initialization (``initial="calculated"``).
    range : (float, float) or None
        Declared ``[min, max]``.
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


def io_ports(inputs: Sequence[Sequence[str]], outputs: Sequence[Sequence[str]]
             ) -> tuple[Port, ...]:
    """The plant's input and output ports from ``(name, plant unit, description)`` rows (a
    model's, :func:`plant_outputs`): inputs start at 0, outputs are computed at
    initialization; units as FMI names (:func:`fmi_unit`, ``"1"`` for none)."""
    return (*(Port(n, "input", "continuous", fmi_unit(u) or "1", d) for n, u, d in inputs),
            *(Port(n, "output", "continuous", fmi_unit(u) or "1", d, None)
              for n, u, d in outputs))


def parameter_name(section: str, key: str) -> str:
    """The plant FMU's parameter of scene key ``key`` of table ``section``: its key path
    ``<section>.<key>`` (``key`` alone for a top-level key, ``section`` ``""``)."""
    return f"{section}.{key}" if section else key


def fmi_unit(unit: str) -> str | None:
    """The FMI unit name of a unit as the plant states it ("N m/rad" -> "N.m/rad", "m/s^2" ->
    "m/s2"); None for none ("-" or "")."""
    if unit in ("-", ""):
        return None
    return unit.replace("^", "").replace(" ", ".")


def ref(instance: str, name: str) -> str:
    """The wiring / recording name ``"<instance>.<name>"`` of a variable."""
    return f"{instance}.{name}"


def body_signal(body: int, quantity: str) -> str:
    """``body<b>_<quantity>``, e.g. ``body11_radial_deflection`` (quantity in
    :data:`CONTACT_QUANTITIES`, or ``whirl_speed`` / ``whirl_direction``)."""
    return f"body{body}_{quantity}"


def strain(site: int, axis: str) -> str:
    """``strain<s>_<axis>``: bending strain [1] at gauge ``axis`` of site ``s``."""
    return f"strain{site}_{axis}"


def actuator_force(site: int, axis: str) -> str:
    """``actuator<s>_force_<axis>``: actuator force [N] at gauge ``axis`` of site ``s``."""
    return f"actuator{site}_force_{axis}"


def actuator_power(site: int) -> str:
    """``actuator<s>_power``: power [W] the actuators of site ``s`` deliver."""
    return f"actuator{site}_power"


def site_channels(sites: Iterable[int]) -> list[tuple[int, str]]:
    """``(site, axis)`` channels in the order plant inputs and controller ports list them."""
    return [(s, a) for s in sites for a in AXES]


def actuator_input_rows(n_sites: int, site_names: dict[int, str] | None = None
                        ) -> list[tuple[str, str, str]]:
    """``(name, unit, description)`` of the actuator force inputs of ``n_sites`` sites
    (``site_names``: site -> words, default ``"site <s>"``)."""
    pair = {"C": "D", "E": "F"}
    return [(actuator_force(s, a), "N",
             f"Actuator force at {(site_names or {}).get(s, f'site {s}')}, axis {a}; > 0 "
             f"opposes positive strain (compressive at {pair[a]}, tensile at {a})")
            for s, a in site_channels(range(1, n_sites + 1))]


def actuator_inputs(n_sites: int) -> list[str]:
    """The plant's actuator force inputs, two per site (C, E), sites 1 .. ``n_sites``."""
    return [actuator_force(s, a) for s, a in site_channels(range(1, n_sites + 1))]


def site_signals(site: int) -> tuple[str, ...]:
    """Every name of site ``s``: its strains, actuator forces and power."""
    return (*(strain(site, a) for a in AXES), *(actuator_force(site, a) for a in AXES),
            actuator_power(site))


def sites_in(names: Collection[str], signal=None) -> list[int]:
    """Site numbers that have a name among ``names`` (any of :func:`site_signals`, or only
    ``signal(site, axis)``, e.g. :func:`strain`), found by building names, not parsing them.

    Sites are numbered from 1 without gaps in the project's FMUs; a foreign FMU may leave gaps,
    so every number up to ``len(names)`` is tried.
    """
    have = set(names)

    def named(s: int) -> tuple[str, ...]:
        return site_signals(s) if signal is None else tuple(signal(s, a) for a in AXES)

    return [s for s in range(1, len(have) + 1) if have.intersection(named(s))]


def bodies_in(names: Collection[str], quantity: str = "radial_deflection",
              instance: str | None = None, most: int = 10000) -> list[int]:
    """Bodies ``b`` with ``body<b>_<quantity>`` among ``names`` (recorded names
    ``"<instance>.body<b>_<quantity>"`` with ``instance``), found by building the names, not
    parsing them; bodies 1 .. ``most``."""
    have = set(names)
    return [b for b in range(1, most + 1)
            if (ref(instance, body_signal(b, quantity)) if instance else
                body_signal(b, quantity)) in have]


def plant_outputs(full3d: bool, contact_bodies: Iterable[int], n_sites: int,
                  extended: bool = False, field: bool = False) -> list[tuple[str, str, str]]:
    """(name, unit, description) of each output of a plant model, in the kernels' order.

    Parameters
    ----------
    full3d : bool
        True for the 3D model (contact and strain outputs exist), False for axial-torsional.
    contact_bodies : iterable of int
        1-based contact bodies.
    n_sites : int
        Number of actuator sites.
    extended : bool
        Include the outputs of the extensions beyond the paper (``docs/physics.md``: whirl speed
        and direction per contact body). The kernels always fill the extended list
        (:class:`plant.model.DrillstringModel` uses it); ``False`` gives the paper's interface
        (the default plant FMU's outputs), a subset of it.
    field : bool
        Include the field summary (:data:`FIELD_SCALAR_OUTPUTS`; 3D model only): a string of
        sections or in a trajectory, whose contact is checked at every body.
    """
    rows: list[tuple[str, str, str]] = []
    if full3d:
        for b in contact_bodies:
            rows += [
                (body_signal(b, "X"), "m", f"inertial X of the mass centre of body {b}"),
                (body_signal(b, "Y"), "m", f"inertial Y of the mass centre of body {b}"),
                (body_signal(b, "radial_deflection"), "m", f"radial deflection of body {b}"),
                (body_signal(b, "contact_force"), "N", f"wellbore contact force on body {b}"),
            ]
            if extended:
                rows += [
                    (body_signal(b, "whirl_speed"), "rad/s",
                     f"angular velocity of the mass centre of body {b} about the well axis "
                     f"(> 0 in the top drive's positive sense; 0 within "
                     f"{WHIRL_MIN_RADIUS:g} m of the axis)"),
                    (body_signal(b, "whirl_direction"), "1",
                     f"+1 forward whirl (with the spin of body {b}), -1 backward, 0 none"),
                ]
        for s in range(1, n_sites + 1):
            rows += [
                (strain(s, "C"), "1", f"bending strain at gauge C of site {s}"),
                (strain(s, "E"), "1", f"bending strain at gauge E of site {s}"),
                (actuator_power(s), "W", f"power delivered by the actuators of site {s}"),
            ]
    rows += list(SCALAR_OUTPUTS)
    if extended:
        rows += list(EXTENDED_SCALAR_OUTPUTS)
    if field and full3d:
        rows += list(FIELD_SCALAR_OUTPUTS)
    return rows
