"""The plant's parameter tree: frozen dataclasses in SI units, validated on construction.

Every field carries its unit and a one-line description in ``metadata`` so that the scene schema
(``docs/scenes.md``) and the FMU's variable table are generated from one place. A bad value raises
``ValueError`` naming the parameter, the value and the allowed range.

Conventions (see ``plant/model.py``): inertial Z points down the well from the top drive, body 1
is the top segment and body ``n`` the bit segment (1-based in every user-facing parameter).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, fields
from typing import Any

__all__ = [
    "BIT_MODELS",
    "TOP_DRIVE_MODES",
    "PipeParams",
    "DampingParams",
    "TopDriveParams",
    "BitParams",
    "StabilizerParams",
    "ContactParams",
    "UnbalanceParams",
    "ActuatorParams",
    "LoadParams",
    "SECTION_KINDS",
    "SectionParams",
    "TrajectoryParams",
    "FluidParams",
    "PlantParams",
    "describe",
]


#: Top-drive boundary conditions (``top_drive.mode``), in the order of the kernels' integer code.
TOP_DRIVE_MODES = ("prescribed", "speed", "torque")
#: Bit-rock laws (``bit.model``), in the order of the kernels' integer code.
BIT_MODELS = ("prescribed", "cutting")


def _f(default: Any, unit: str, doc: str, **kw: Any) -> Any:
    return field(default=default, metadata={"unit": unit, "doc": doc, **kw})


def _check_finite(owner: str, name: str, value: Any, *, allow_inf: bool = False) -> None:
    if isinstance(value, bool):
        return
    if isinstance(value, (int, float)):
        if math.isnan(value) or (math.isinf(value) and not allow_inf):
            raise ValueError(f"{owner}.{name} = {value!r} is not allowed: must be a finite number")


def _check_range(
    owner: str,
    name: str,
    value: float,
    lo: float | None = None,
    hi: float | None = None,
    *,
    lo_open: bool = False,
    hi_open: bool = False,
    unit: str = "",
    allow_inf: bool = False,
) -> None:
    """Raise a one-line ValueError unless lo <= value <= hi (inf only where ``allow_inf``)."""
    _check_finite(owner, name, value, allow_inf=allow_inf)
    if hi is None and not allow_inf and isinstance(value, (int, float)) and math.isinf(value):
        bad = True
    else:
        bad = (lo is not None and (value < lo or (lo_open and value == lo))) or (
            hi is not None and (value > hi or (hi_open and value == hi))
        )
    if bad:
        left = "(" if lo_open else "["
        right = ")" if hi_open or (hi is None and not allow_inf) else "]"
        lo_s = "-inf" if lo is None else f"{lo:g}"
        hi_s = "inf" if hi is None else f"{hi:g}"
        u = f" {unit}" if unit else ""
        raise ValueError(
            f"{owner}.{name} = {value!r} is out of range: allowed {left}{lo_s}, {hi_s}{right}{u}"
        )


def _validate_types(obj: Any) -> None:
    """Reject values whose type does not match the field's default (bool vs number vs tuple)."""
    owner = type(obj).OWNER
    for f in fields(obj):
        v = getattr(obj, f.name)
        d = f.default
        if isinstance(d, bool):
            if not isinstance(v, bool):
                raise ValueError(f"{owner}.{f.name} = {v!r} is not allowed: must be true or false")
        elif isinstance(d, (int, float)) and not isinstance(d, bool):
            if isinstance(v, bool) or not isinstance(v, (int, float)):
                raise ValueError(f"{owner}.{f.name} = {v!r} is not allowed: must be a number")
            if isinstance(d, int) and not isinstance(d, bool) and f.metadata.get("integer"):
                if not float(v).is_integer():
                    raise ValueError(
                        f"{owner}.{f.name} = {v!r} is not allowed: must be an integer"
                    )
                object.__setattr__(obj, f.name, int(v))
        elif isinstance(d, tuple):
            if isinstance(v, list):
                v = tuple(v)
                object.__setattr__(obj, f.name, v)
            if not isinstance(v, tuple):
                raise ValueError(f"{owner}.{f.name} = {v!r} is not allowed: must be a list")


class _Tube:
    """Section properties of a hollow circular steel tube (fields ``outer_diameter``,
    ``inner_diameter``, ``youngs_modulus``, ``shear_modulus``, ``density``,
    ``shear_coefficient``), shared by :class:`PipeParams` and :class:`SectionParams`."""

    @property
    def area(self) -> float:
        """Cross-section area A [m^2]."""
        return math.pi / 4.0 * (self.outer_diameter**2 - self.inner_diameter**2)

    @property
    def second_moment(self) -> float:
        """Area moment of inertia I [m^4] (about a diameter)."""
        return math.pi / 64.0 * (self.outer_diameter**4 - self.inner_diameter**4)

    @property
    def polar_moment(self) -> float:
        """Polar moment of area J = 2 I [m^4]."""
        return 2.0 * self.second_moment

    @property
    def poisson_ratio(self) -> float:
        """nu = E / (2 G) - 1 [1]."""
        return self.youngs_modulus / (2.0 * self.shear_modulus) - 1.0

    @property
    def kappa(self) -> float:
        """Shear coefficient: the given one, or Cowper's (1966) for a hollow circle [1]."""
        if self.shear_coefficient > 0.0:
            return self.shear_coefficient
        nu = self.poisson_ratio
        m2 = (self.inner_diameter / self.outer_diameter) ** 2
        a = (1.0 + m2) ** 2
        return 6.0 * (1.0 + nu) * a / ((7.0 + 6.0 * nu) * a + (20.0 + 12.0 * nu) * m2)

    @property
    def axial_wave_speed(self) -> float:
        """c = sqrt(E / rho) [m/s]."""
        return math.sqrt(self.youngs_modulus / self.density)

    @property
    def torsional_wave_speed(self) -> float:
        """c_t = sqrt(G / rho) [m/s]."""
        return math.sqrt(self.shear_modulus / self.density)


def _check_tube(obj: Any) -> None:
    """Range checks of the fields every tube has (see :class:`_Tube`)."""
    o = obj.OWNER
    _check_range(o, "length", obj.length, 0.0, None, lo_open=True, unit="m")
    _check_range(o, "outer_diameter", obj.outer_diameter, 0.0, 5.0, lo_open=True, unit="m")
    _check_range(
        o, "inner_diameter", obj.inner_diameter, 0.0, obj.outer_diameter, hi_open=True, unit="m",
    )
    _check_range(o, "youngs_modulus", obj.youngs_modulus, 0.0, 1e13, lo_open=True, unit="Pa")
    _check_range(o, "shear_modulus", obj.shear_modulus, 0.0, 1e13, lo_open=True, unit="Pa")
    _check_range(o, "density", obj.density, 0.0, 1e5, lo_open=True, unit="kg/m^3")
    _check_range(o, "shear_coefficient", obj.shear_coefficient, 0.0, 1.0)


@dataclass(frozen=True)
class PipeParams(_Tube):
    """Geometry and material of the collar section (hollow circular steel pipe)."""

    OWNER = "pipe"
    length: float = _f(80.0, "m", "length of the modelled collar section")
    n_segments: int = _f(30, "1", "number of rigid segments (bodies)", integer=True)
    outer_diameter: float = _f(0.110, "m", "outer diameter")
    inner_diameter: float = _f(0.045, "m", "inner diameter (0 for a solid bar)")
    youngs_modulus: float = _f(208e9, "Pa", "Young's modulus E")
    shear_modulus: float = _f(81e9, "Pa", "shear modulus G")
    density: float = _f(7850.0, "kg/m^3", "density rho")
    shear_coefficient: float = _f(
        0.0, "1", "Timoshenko shear coefficient kappa; 0 = Cowper's value for a hollow circle"
    )

    def __post_init__(self) -> None:
        _validate_types(self)
        _check_range(self.OWNER, "n_segments", self.n_segments, 2, 2000)
        _check_tube(self)

    @property
    def segment_length(self) -> float:
        """dx = L / n [m]."""
        return self.length / self.n_segments


@dataclass(frozen=True)
class DampingParams:
    """Material and lateral damping, set from target damping ratios.

    Joint dampers are stiffness-proportional (c = beta k): ``beta_axial = 2 zeta_a / w_a`` with
    ``w_a`` the first fixed-free axial rod frequency, likewise torsion; shear joints use
    ``beta_axial``. The first lateral mode gets ``lateral_ratio`` at ``w_l``, the first frequency
    of the pinned multi-span Euler-Bernoulli beam over the top pin and the stabilizers (or
    ``lateral_reference_frequency`` if > 0), in one of two ways (``lateral_model``):
    ``"drag"`` (default): viscous drag on each body's lateral velocity, ``alpha = 2 zeta_l w_l``
    (mass proportional, external damping), bending joints keep ``beta_axial``. ``"joint"``
    (like joint R elements): bending dampers with ``beta_lateral = 2 zeta_l / w_l``. Joint dampers
    rotate with the pipe: above the first critical speed (20 rad/s >> 0.68 rad/s here) internal
    damping drives forward whirl unstable (Kimball-Newkirk), which this model reproduces.
    """

    OWNER = "damping"
    axial_ratio: float = _f(0.015, "1", "damping ratio of the first axial mode (Table 1: 1.5 %)")
    torsional_ratio: float = _f(
        0.034, "1", "damping ratio of the first torsional mode (Table 1: 3.4 %)"
    )
    lateral_ratio: float = _f(0.40, "1", "damping ratio of the first lateral mode (Table 1: 40 %)")
    lateral_reference_frequency: float = _f(
        0.0, "rad/s", "frequency at which lateral_ratio is met; 0 = first pinned multi-span beam mode"
    )
    lateral_model: str = _f(
        "drag", "-",
        "'drag': viscous drag on lateral velocity c = alpha m (external, fluid-like); 'joint': "
        "bending dampers c = beta_l k_bend (internal: destabilizes whirl above the first critical speed)",
    )
    max_joint_rate: float = _f(
        math.inf, "1/s",
        "cap of each joint damper: c <= k * max_joint_rate / w_j^2 with w_j = 2 sqrt(k / m) the "
        "joint's highest local frequency, so that no overdamped joint mode decays faster than "
        "max_joint_rate (short stiff segments otherwise set the time step); inf = no cap (the "
        "paper's model), 0 = the string's highest undamped joint frequency",
    )

    def __post_init__(self) -> None:
        _validate_types(self)
        o = self.OWNER
        _check_range(o, "axial_ratio", self.axial_ratio, 0.0, 1.0)
        _check_range(o, "torsional_ratio", self.torsional_ratio, 0.0, 1.0)
        _check_range(o, "lateral_ratio", self.lateral_ratio, 0.0, 2.0)
        _check_range(
            o, "lateral_reference_frequency", self.lateral_reference_frequency, 0.0, 1e4,
            unit="rad/s",
        )
        _check_range(o, "max_joint_rate", self.max_joint_rate, 0.0, None, unit="1/s",
                     allow_inf=True)
        if self.lateral_model not in ("joint", "drag"):
            raise ValueError(
                f"damping.lateral_model = {self.lateral_model!r} is not allowed: 'joint' or 'drag'"
            )


@dataclass(frozen=True)
class TopDriveParams:
    """Top boundary: stiff springs to a top drive that ramps its rotary speed."""

    OWNER = "top_drive"
    axial_stiffness: float = _f(1e9, "N/m", "axial spring to the top drive (inf = rigid, 0 = free)")
    lateral_stiffness: float = _f(1e9, "N/m", "lateral spring to the top drive (inf = rigid)")
    torsional_stiffness: float = _f(
        math.inf, "N m/rad", "torsional spring to the top drive (inf = rigid drive)"
    )
    rotary_speed: float = _f(20.0, "rad/s", "final rotary speed of the top drive (mode 'prescribed')")
    ramp_time: float = _f(1.0, "s", "duration of the linear speed ramp from 0 (mode 'prescribed')")
    mode: str = _f(
        "prescribed", "-",
        "'prescribed': the speed ramp above; 'speed': an ideal speed source driven by the input "
        "top_drive_speed_command [rad/s]; 'torque': a drive of rotor inertia `inertia` driven by "
        "the input top_drive_torque [N m] (the motor torque)",
    )
    inertia: float = _f(
        0.0, "kg m^2", "rotor inertia of the top drive (mode 'torque'; must then be > 0)"
    )
    hoisting_speed: float = _f(
        0.0, "m/s",
        "axial speed of the top drive along the well axis, > 0 lowering the string (tripping "
        "in), < 0 raising it (tripping out); ramped from 0 over ramp_time",
    )

    def __post_init__(self) -> None:
        _validate_types(self)
        o = self.OWNER
        for name in ("axial_stiffness", "lateral_stiffness", "torsional_stiffness"):
            _check_range(o, name, getattr(self, name), 0.0, None, unit="N/m or N m/rad",
                         allow_inf=True)
        _check_range(o, "rotary_speed", self.rotary_speed, -1e3, 1e3, unit="rad/s")
        _check_range(o, "ramp_time", self.ramp_time, 0.0, 1e6, unit="s")
        if self.mode not in TOP_DRIVE_MODES:
            raise ValueError(f"{o}.mode = {self.mode!r} is not allowed: one of "
                             + ", ".join(repr(m) for m in TOP_DRIVE_MODES))
        _check_range(o, "inertia", self.inertia, 0.0, 1e6, unit="kg m^2")
        _check_range(o, "hoisting_speed", self.hoisting_speed, -10.0, 10.0, unit="m/s")
        if self.mode == "torque" and self.inertia <= 0.0:
            raise ValueError(f"{o}.inertia = {self.inertia!r} is out of range for mode = "
                             "'torque': allowed (0, 1e+06] kg m^2")
        if self.mode != "prescribed" and self.torsional_stiffness == 0.0:
            raise ValueError(f"{o}.torsional_stiffness = 0 is not allowed with mode = "
                             f"{self.mode!r}: the drive must be connected to the string "
                             "(allowed (0, inf] N m/rad)")


@dataclass(frozen=True)
class BitParams:
    """Bit boundary: a spring to a prescribed rock displacement (the paper's) or a cutting bit.

    ``model = "prescribed"``: an axial spring to a rock surface moving as a sinusoid of the
    top-drive angle. ``model = "cutting"``: the Detournay & Defourny (2008) drag-bit law on a
    unilateral contact (the bit lifts off); see docs/physics.md.
    """

    OWNER = "bit"
    axial_stiffness: float = _f(
        1e9, "N/m", "axial spring between the bit and the rock (0 = axially free bit)"
    )
    displacement_amplitude: float = _f(
        0.003, "m", "amplitude of the sinusoidal bit displacement ('cutting': of the bottom-hole "
        "profile under the bit)"
    )
    lobes: float = _f(
        1.0, "1", "bit displacement frequency / rotary speed ('cutting': profile lobes per bit "
        "revolution)"
    )
    weight_on_bit: float = _f(0.0, "N", "static compressive bit force (sets the rock position)")
    torque: float = _f(0.0, "N m", "constant resisting bit torque (smoothed sign of the bit speed)")
    model: str = _f(
        "prescribed", "-",
        "'prescribed': spring to the prescribed displacement; 'cutting': cutting + wear-flat "
        "friction law on a unilateral contact, the hole bottom advancing as the bit cuts",
    )
    radius: float = _f(0.108, "m", "bit radius a ('cutting')")
    intrinsic_specific_energy: float = _f(
        60e6, "Pa", "intrinsic specific energy epsilon of the rock ('cutting')"
    )
    cutting_force_ratio: float = _f(
        0.6, "1", "zeta: ratio of the normal to the tangential cutting force ('cutting')"
    )
    wearflat_force: float = _f(
        20e3, "N", "W_f* = a l sigma: axial force carried by the wear flats at full contact "
        "('cutting')"
    )
    friction_coefficient: float = _f(
        0.6, "1", "mu gamma: wear-flat friction coefficient times the bit geometry factor "
        "('cutting')"
    )
    static_friction_ratio: float = _f(
        1.0, "1", "velocity weakening: friction at rest / friction at speed (1 = none)"
    )
    weakening_speed: float = _f(
        1.0, "rad/s", "bit speed over which the wear-flat friction decays to its dynamic value"
    )
    slip_speed: float = _f(
        0.1, "rad/s", "speed scale of the smoothed sign of the bit torque: tanh(omega/slip_speed)"
    )
    inertia: float = _f(
        0.0, "kg m^2", "polar inertia added to the bit body (bit and bottom-hole assembly below "
        "the modelled section)"
    )

    def __post_init__(self) -> None:
        _validate_types(self)
        o = self.OWNER
        _check_range(o, "axial_stiffness", self.axial_stiffness, 0.0, 1e13, unit="N/m")
        _check_range(o, "displacement_amplitude", self.displacement_amplitude, 0.0, 1.0, unit="m")
        _check_range(o, "lobes", self.lobes, 0.0, 100.0)
        _check_range(o, "weight_on_bit", self.weight_on_bit, -1e8, 1e8, unit="N")
        _check_range(o, "torque", self.torque, 0.0, 1e7, unit="N m")
        if self.model not in BIT_MODELS:
            raise ValueError(f"{o}.model = {self.model!r} is not allowed: one of "
                             + ", ".join(repr(m) for m in BIT_MODELS))
        _check_range(o, "radius", self.radius, 0.0, 2.0, lo_open=True, unit="m")
        _check_range(o, "intrinsic_specific_energy", self.intrinsic_specific_energy, 0.0, 1e11,
                     lo_open=True, unit="Pa")
        _check_range(o, "cutting_force_ratio", self.cutting_force_ratio, 0.0, 10.0, lo_open=True)
        _check_range(o, "wearflat_force", self.wearflat_force, 0.0, 1e8, unit="N")
        _check_range(o, "friction_coefficient", self.friction_coefficient, 0.0, 5.0)
        _check_range(o, "static_friction_ratio", self.static_friction_ratio, 1.0, 100.0)
        _check_range(o, "weakening_speed", self.weakening_speed, 0.0, 1e3, lo_open=True,
                     unit="rad/s")
        _check_range(o, "slip_speed", self.slip_speed, 0.0, 100.0, lo_open=True, unit="rad/s")
        _check_range(o, "inertia", self.inertia, 0.0, 1e7, unit="kg m^2")
        if self.model == "cutting" and self.axial_stiffness == 0.0:
            raise ValueError(f"{o}.axial_stiffness = 0 is not allowed with model = 'cutting': "
                             "the bit-rock contact needs a stiffness (allowed (0, 1e+13] N/m)")


@dataclass(frozen=True)
class StabilizerParams:
    """Stabilizers: stiff lateral springs at given heights above the bit."""

    OWNER = "stabilizers"
    heights: tuple = _f((0.0, 26.67), "m", "heights of the stabilizers above the bit")
    stiffness: float = _f(1e9, "N/m", "lateral stiffness of each stabilizer")
    damping: float = _f(
        -1.0, "N s/m", "lateral damping of each stabilizer; -1 = material (beta_axial * stiffness)"
    )

    def __post_init__(self) -> None:
        _validate_types(self)
        o = self.OWNER
        for h in self.heights:
            if isinstance(h, bool) or not isinstance(h, (int, float)):
                raise ValueError(f"{o}.heights: {h!r} is not allowed: must be numbers (m)")
            _check_range(o, "heights", float(h), 0.0, None, unit="m")
        _check_range(o, "stiffness", self.stiffness, 0.0, 1e13, unit="N/m")
        if self.damping != -1.0:
            _check_range(o, "damping", self.damping, 0.0, 1e12, unit="N s/m")


@dataclass(frozen=True)
class ContactParams:
    """Wellbore contact (eq. 14-17): radial spring beyond the clearance at given bodies."""

    OWNER = "contact"
    enabled: bool = _f(True, "-", "wellbore contact on/off")
    bodies: tuple = _f(
        (), "1", "bodies (1 = top) checked for contact; [] = the body at each span's middle"
    )
    clearance: float = _f(0.02, "m", "radial clearance between collar and wellbore (0: touching)")
    stiffness: float = _f(1e7, "N/m", "wellbore contact stiffness k_w")
    damping: float = _f(0.0, "N s/m", "contact damping (acts only while in contact)")
    friction_coefficient: float = _f(
        0.0, "1", "Coulomb friction coefficient mu at the wall (0 = frictionless, the paper's)"
    )
    friction_velocity: float = _f(
        0.01, "m/s",
        "slip speed of the regularized friction: F = mu N v / sqrt(v^2 + v_eps^2)",
    )
    whirl_outputs: bool = _f(
        False, "-",
        "add the outputs body<b>_whirl_speed [rad/s] and body<b>_whirl_direction per contact "
        "body (always there when friction_coefficient > 0)",
    )

    def __post_init__(self) -> None:
        _validate_types(self)
        o = self.OWNER
        for b in self.bodies:
            if isinstance(b, bool) or not isinstance(b, int):
                raise ValueError(f"{o}.bodies: {b!r} is not allowed: must be integers >= 1")
        _check_range(o, "clearance", self.clearance, 0.0, 10.0, unit="m")
        _check_range(o, "stiffness", self.stiffness, 0.0, 1e13, unit="N/m")
        _check_range(o, "damping", self.damping, 0.0, 1e12, unit="N s/m")
        _check_range(o, "friction_coefficient", self.friction_coefficient, 0.0, 2.0)
        _check_range(o, "friction_velocity", self.friction_velocity, 0.0, 10.0, lo_open=True,
                     unit="m/s")


@dataclass(frozen=True)
class UnbalanceParams:
    """Mass unbalance: a rotating centrifugal force m e w^2 fixed in the body frame."""

    OWNER = "unbalance"
    enabled: bool = _f(True, "-", "unbalance on/off")
    body: int = _f(0, "1", "body carrying the unbalance (1 = top); 0 = the bit body", integer=True)
    moment: float = _f(0.1, "kg m", "unbalance m e")

    def __post_init__(self) -> None:
        _validate_types(self)
        _check_range(self.OWNER, "body", self.body, 0, None)
        _check_range(self.OWNER, "moment", self.moment, 0.0, 1e4, unit="kg m")


@dataclass(frozen=True)
class ActuatorParams:
    """Strain gauges and bending actuators at joints (Fig. 6-8)."""

    OWNER = "actuators"
    joints: tuple = _f(
        (), "1", "site k sits at the joint below body joints[k]; [] = below each span's middle body"
    )
    radius: float = _f(0.0, "m", "radius of the actuator points C, D, E, F; 0 = outer radius")
    gauge_radius: float = _f(0.0, "m", "radius of the strain gauges; 0 = outer radius")

    def __post_init__(self) -> None:
        _validate_types(self)
        o = self.OWNER
        for j in self.joints:
            if isinstance(j, bool) or not isinstance(j, int):
                raise ValueError(f"{o}.joints: {j!r} is not allowed: must be integers >= 1")
        _check_range(o, "radius", self.radius, 0.0, 5.0, unit="m")
        _check_range(o, "gauge_radius", self.gauge_radius, 0.0, 5.0, unit="m")


#: Kinds of string sections (``[[sections]] kind``); a "stabilizer" is a lateral support (a contact
#: point of its blades' gauge diameter) for the span logic; the others are labels.
SECTION_KINDS = ("drill_pipe", "heavy_weight", "collar", "stabilizer", "mwd", "motor", "sub")


@dataclass(frozen=True)
class SectionParams(_Tube):
    """One section of a multi-section string (``[[sections]]``, listed from the top drive down).

    A section is cut into ``round(length / segment_length)`` equal rigid bodies (at least one;
    ``segment_length = 0``: one rigid body, e.g. an MWD tool, a motor or a stabilizer).
    """

    OWNER = "sections"
    kind: str = _f("drill_pipe", "-", "drill_pipe, heavy_weight, collar, stabilizer, mwd, motor "
                   "or sub (a stabilizer is a lateral support of the spans)")
    length: float = _f(0.0, "m", "length of the section along the string (> 0)")
    outer_diameter: float = _f(0.127, "m", "outer diameter of the tube body")
    inner_diameter: float = _f(0.1086, "m", "inner diameter (0 for a solid bar)")
    youngs_modulus: float = _f(208e9, "Pa", "Young's modulus E")
    shear_modulus: float = _f(81e9, "Pa", "shear modulus G")
    density: float = _f(7850.0, "kg/m^3", "density of the steel rho")
    shear_coefficient: float = _f(
        0.0, "1", "Timoshenko shear coefficient kappa; 0 = Cowper's value for a hollow circle"
    )
    linear_mass: float = _f(
        0.0, "kg/m", "mass per length including tool joints and upsets; 0 = density x area"
    )
    contact_diameter: float = _f(
        0.0, "m", "diameter that touches the hole wall (tool joints of drill pipe, blade gauge of "
        "a stabilizer); 0 = outer diameter"
    )
    segment_length: float = _f(
        0.0, "m", "target length of the rigid segments (fine in the BHA, ~9-30 m in drill pipe); "
        "0 = one rigid body for the whole section"
    )
    stabilizers: tuple = _f(
        (), "m", "positions of stabilizer blades along the section, from its top (contact points "
        "of stabilizer_diameter on the section's bodies; a trajectory is needed)"
    )
    stabilizer_diameter: float = _f(
        0.0, "m", "gauge diameter of the blades at the positions in stabilizers"
    )
    added_mass_coefficient: float = _f(
        -1.0, "1", "lateral added-mass coefficient C_a of the displaced mud ([fluid] on); -1 = "
        "the potential-flow value for a cylinder in the concentric hole, (D_h^2 + D_o^2) / "
        "(D_h^2 - D_o^2) (Chen, Wambsganss and Jendrzejczyk 1976), 1 = unconfined"
    )

    def __post_init__(self) -> None:
        _validate_types(self)
        o = self.OWNER
        if self.kind not in SECTION_KINDS:
            raise ValueError(f"{o}.kind = {self.kind!r} is not allowed: one of "
                             + ", ".join(SECTION_KINDS))
        _check_tube(self)
        _check_range(o, "linear_mass", self.linear_mass, 0.0, 1e5, unit="kg/m")
        _check_range(o, "contact_diameter", self.contact_diameter, 0.0, 5.0, unit="m")
        if 0.0 < self.contact_diameter < self.outer_diameter:
            raise ValueError(f"{o}.contact_diameter = {self.contact_diameter!r} is out of range: "
                             f"allowed 0 or [{self.outer_diameter:g}, 5] m (not below the outer "
                             "diameter)")
        _check_range(o, "segment_length", self.segment_length, 0.0, 1e4, unit="m")
        for z in self.stabilizers:
            if isinstance(z, bool) or not isinstance(z, (int, float)):
                raise ValueError(f"{o}.stabilizers: {z!r} is not allowed: must be numbers (m)")
            _check_range(o, "stabilizers", float(z), 0.0, self.length, unit="m")
        _check_range(o, "stabilizer_diameter", self.stabilizer_diameter, 0.0, 5.0, unit="m")
        if self.stabilizers and self.stabilizer_diameter < self.outer_diameter:
            raise ValueError(f"{o}.stabilizer_diameter = {self.stabilizer_diameter!r} is out of "
                             f"range with stabilizers given: allowed [{self.outer_diameter:g}, 5] m")
        if self.added_mass_coefficient != -1.0:
            _check_range(o, "added_mass_coefficient", self.added_mass_coefficient, 0.0, 100.0)

    @property
    def mass_per_length(self) -> float:
        """Mass per length [kg/m]: ``linear_mass`` or density x area."""
        return self.linear_mass or self.density * self.area

    @property
    def n_bodies(self) -> int:
        """Number of rigid bodies of the section [1]."""
        if self.segment_length <= 0.0:
            return 1
        return max(1, int(round(self.length / self.segment_length)))

    @property
    def contact_radius(self) -> float:
        """Radius [m] at which the section touches the wall."""
        return 0.5 * (self.contact_diameter or self.outer_diameter)


@dataclass(frozen=True)
class TrajectoryParams:
    """Well path and hole size: a survey interpolated by the minimum-curvature method.

    Inertial axes: X north, Y east, Z down (true vertical depth), origin at the top drive.
    """

    OWNER = "trajectory"
    survey: tuple = _f(
        (), "m, deg, deg", "survey stations [measured depth, inclination, azimuth], MD rising "
        "from 0; beyond the last station the hole goes on straight; [] = vertical"
    )
    hole: tuple = _f(
        (), "m, m", "hole sections [bottom measured depth, diameter] from the top (casing inner "
        "diameter, then open hole); the last one extends to any depth"
    )

    def __post_init__(self) -> None:
        _validate_types(self)
        o = self.OWNER
        rows = []
        for r in self.survey:
            if (not isinstance(r, (list, tuple)) or len(r) != 3
                    or any(isinstance(v, bool) or not isinstance(v, (int, float)) for v in r)):
                raise ValueError(f"{o}.survey: {r!r} is not allowed: each station is [measured "
                                 "depth m, inclination deg, azimuth deg]")
            md, inc, azi = (float(v) for v in r)
            _check_range(o, "survey measured depth", md, 0.0, 1e5, unit="m")
            _check_range(o, "survey inclination", inc, 0.0, 180.0, unit="deg")
            _check_range(o, "survey azimuth", azi, -360.0, 720.0, unit="deg")
            if rows and md <= rows[-1][0]:
                raise ValueError(f"{o}.survey: measured depth {md:g} m is not above the previous "
                                 f"station's {rows[-1][0]:g} m: stations must be in rising MD")
            rows.append((md, inc, azi))
        if rows and rows[0][0] != 0.0:
            raise ValueError(f"{o}.survey: the first station is at {rows[0][0]:g} m: it must be "
                             "at measured depth 0 (the top drive)")
        object.__setattr__(self, "survey", tuple(rows))
        holes = []
        for r in self.hole:
            if (not isinstance(r, (list, tuple)) or len(r) != 2
                    or any(isinstance(v, bool) or not isinstance(v, (int, float)) for v in r)):
                raise ValueError(f"{o}.hole: {r!r} is not allowed: each entry is [bottom measured "
                                 "depth m, diameter m]")
            md, dia = float(r[0]), float(r[1])
            _check_range(o, "hole measured depth", md, 0.0, 1e5, lo_open=True, unit="m",
                         allow_inf=True)
            _check_range(o, "hole diameter", dia, 0.0, 5.0, lo_open=True, unit="m")
            if holes and md <= holes[-1][0]:
                raise ValueError(f"{o}.hole: bottom depth {md:g} m is not below the previous "
                                 f"{holes[-1][0]:g} m")
            holes.append((md, dia))
        if not holes:
            raise ValueError(f"{o}.hole = [] is not allowed: give at least one [bottom measured "
                             "depth, diameter] (e.g. [[3000.0, 0.2159]])")
        object.__setattr__(self, "hole", tuple(holes))

    @property
    def vertical(self) -> bool:
        """True when every station has zero inclination (a vertical hole)."""
        return all(inc == 0.0 for _md, inc, _azi in self.survey)

    def hole_diameter(self, md: float) -> float:
        """Hole diameter [m] at measured depth ``md`` [m]."""
        for bottom, dia in self.hole:
            if md <= bottom:
                return dia
        return self.hole[-1][1]


@dataclass(frozen=True)
class FluidParams:
    """Drilling fluid (mud) in and around the string: buoyancy, lateral added mass and drag."""

    OWNER = "fluid"
    enabled: bool = _f(False, "-", "drilling fluid on/off (off: the string in air)")
    density: float = _f(1200.0, "kg/m^3", "mud density (1200 kg/m^3 = 10 ppg)")
    drag_coefficient: float = _f(
        1.0, "1", "quadratic lateral drag F = 1/2 rho C_d D |v| v per length (cylinder in cross "
        "flow, Re 1e3-2e5: C_d ~ 1.0-1.2, Morison et al. 1950)"
    )
    linear_drag: float = _f(
        0.0, "N s/m^2", "linear lateral drag per length and velocity (viscous; 0 = none)"
    )

    def __post_init__(self) -> None:
        _validate_types(self)
        o = self.OWNER
        _check_range(o, "density", self.density, 0.0, 3000.0, unit="kg/m^3")
        _check_range(o, "drag_coefficient", self.drag_coefficient, 0.0, 10.0)
        _check_range(o, "linear_drag", self.linear_drag, 0.0, 1e6, unit="N s/m^2")


@dataclass(frozen=True)
class LoadParams:
    """An external load on one body: a rectangular pulse (or a step when duration is inf)."""

    OWNER = "loads"
    kind: str = _f("force", "-", "'force' (inertial axis, at the mass centre) or 'torque' (body axis)")
    body: int = _f(1, "1", "loaded body (1 = top)", integer=True)
    direction: str = _f("z", "-", "axis: 'x', 'y' or 'z'")
    magnitude: float = _f(0.0, "N or N m", "load value")
    start: float = _f(0.0, "s", "start time")
    duration: float = _f(math.inf, "s", "duration (inf = step)")

    def __post_init__(self) -> None:
        _validate_types(self)
        o = self.OWNER
        if self.kind not in ("force", "torque"):
            raise ValueError(f"{o}.kind = {self.kind!r} is not allowed: 'force' or 'torque'")
        if self.direction not in ("x", "y", "z"):
            raise ValueError(f"{o}.direction = {self.direction!r} is not allowed: 'x', 'y' or 'z'")
        _check_range(o, "body", self.body, 1, None)
        _check_range(o, "magnitude", self.magnitude, -1e9, 1e9)
        _check_range(o, "start", self.start, 0.0, 1e9, unit="s")
        _check_range(o, "duration", self.duration, 0.0, None, lo_open=True, unit="s",
                     allow_inf=True)

    @property
    def is_lateral(self) -> bool:
        """True when the load excites lateral motion (x/y force or x/y torque)."""
        return self.direction in ("x", "y") and self.magnitude != 0.0


@dataclass(frozen=True)
class PlantParams:
    """The whole plant: one frozen tree in SI units, validated as a whole on construction.

    The string is either one uniform ``pipe`` (the paper's collar section, the default) or a
    list of ``sections`` from the top drive down (field strings: drill pipe, heavy-weight pipe,
    collars, stabilizers ...). With sections, the ``stabilizers`` springs act only where their
    heights are given (the default heights, the paper's, are dropped): field stabilizers are
    sections of kind "stabilizer", touching the wall with their gauge diameter. A
    ``trajectory`` (survey + hole sizes) curves the hole and puts a contact check at every body
    (then ``contact.bodies`` only lists the bodies whose outputs are wanted); ``fluid`` adds the
    mud's buoyancy, added mass and drag.
    """

    OWNER = "plant"
    pipe: PipeParams = field(default_factory=PipeParams)
    damping: DampingParams = field(default_factory=DampingParams)
    top_drive: TopDriveParams = field(default_factory=TopDriveParams)
    bit: BitParams = field(default_factory=BitParams)
    stabilizers: StabilizerParams | None = None  # None: the paper's (pipe), none (sections)
    contact: ContactParams = field(default_factory=ContactParams)
    unbalance: UnbalanceParams = field(default_factory=UnbalanceParams)
    actuators: ActuatorParams = field(default_factory=ActuatorParams)
    loads: tuple = field(default_factory=tuple)
    sections: tuple = field(default_factory=tuple)
    trajectory: TrajectoryParams | None = None
    fluid: FluidParams = field(default_factory=FluidParams)
    gravity: float = _f(0.0, "m/s^2", "gravity along inertial Z, the vertical (0 = off; 9.81 = on)")

    def __post_init__(self) -> None:
        sections = tuple(self.sections)
        for sec in sections:
            if not isinstance(sec, SectionParams):
                raise ValueError(f"sections: {sec!r} is not allowed: must be SectionParams")
        object.__setattr__(self, "sections", sections)
        if sections and self.pipe != PipeParams():
            raise ValueError("pipe and sections are both given: describe the string either as "
                             "one [pipe] or as [[sections]]")
        if self.stabilizers is None:
            object.__setattr__(self, "stabilizers", StabilizerParams(heights=()) if sections
                               else StabilizerParams())
        if self.trajectory is not None and not isinstance(self.trajectory, TrajectoryParams):
            raise ValueError(f"trajectory: {self.trajectory!r} is not allowed: must be "
                             "TrajectoryParams")
        n = self.n_bodies
        if n < 2:
            raise ValueError(f"sections: the string has {n} body; it needs at least 2 (a "
                             "segment_length below the length of a section)")
        if n > 2000:
            raise ValueError(f"sections: the string has {n} bodies; at most 2000 are allowed "
                             "(longer segment_length)")
        L = self.string_length
        if isinstance(self.gravity, bool) or not isinstance(self.gravity, (int, float)):
            raise ValueError(f"gravity = {self.gravity!r} is not allowed: must be a number (m/s^2)")
        _check_range("plant", "gravity", self.gravity, -100.0, 100.0, unit="m/s^2")
        for h in self.stabilizers.heights:
            if h > L:
                raise ValueError(
                    f"stabilizers.heights: {h!r} m is beyond the string: allowed [0, {L:g}] m"
                )
        if self.trajectory is None and any(s.stabilizers for s in sections):
            raise ValueError("sections.stabilizers need a [trajectory] (the hole the blades touch)")
        if self.trajectory is not None:
            self._check_gauges_fit_the_hole()
        for b in self.contact.bodies:
            if not 1 <= b <= n:
                raise ValueError(f"contact.bodies: {b} is out of range: allowed [1, {n}]")
        for j in self.actuators.joints:
            if not 1 <= j <= n - 1:
                raise ValueError(f"actuators.joints: {j} is out of range: allowed [1, {n - 1}]")
        if not self.span_middle_bodies() and self.trajectory is None:
            if self.contact.enabled and not self.contact.bodies:
                raise ValueError("contact.bodies = [] needs at least one span (two lateral "
                                 "supports); list the bodies explicitly")
        if self.unbalance.body > n:
            raise ValueError(f"unbalance.body = {self.unbalance.body} is out of range: [0, {n}]")
        loads = tuple(self.loads)
        for ld in loads:
            if not isinstance(ld, LoadParams):
                raise ValueError(f"loads: {ld!r} is not allowed: must be LoadParams")
            if ld.body > n:
                raise ValueError(f"loads.body = {ld.body} is out of range: allowed [1, {n}]")
        object.__setattr__(self, "loads", loads)
        if self.bit.axial_stiffness == 0.0 and self.bit.weight_on_bit != 0.0:
            raise ValueError(
                "bit.weight_on_bit must be 0 when bit.axial_stiffness = 0 (an axially free bit)"
            )

    def _check_gauges_fit_the_hole(self) -> None:
        """Refuse a bit (gauge 2 ``bit.radius``) or a stabilizer blade larger than the hole
        at its measured depth (the hole is what it drills or passes through: at most equal)."""
        traj = self.trajectory
        L = self.string_length
        hole = traj.hole_diameter(L)
        gauge = 2.0 * self.bit.radius
        if gauge > hole:
            raise ValueError(
                f"bit.radius = {self.bit.radius!r} m: the bit's gauge diameter {gauge:g} m is "
                f"larger than the hole diameter {hole:g} m at measured depth {L:g} m "
                f"(trajectory.hole): allowed bit.radius <= {0.5 * hole:g} m")
        top = 0.0
        for i, sec in enumerate(self.sections):
            for z in sec.stabilizers:
                hole = traj.hole_diameter(top + z)
                if sec.stabilizer_diameter > hole:
                    raise ValueError(
                        f"sections: section {i + 1} ({sec.kind}) has stabilizer_diameter = "
                        f"{sec.stabilizer_diameter!r} m, larger than the hole diameter "
                        f"{hole:g} m at its blade's measured depth {top + z:g} m "
                        "(trajectory.hole)")
            top += sec.length

    # --- the string's bodies --------------------------------------------------------------
    @property
    def uniform(self) -> bool:
        """True for the one-``pipe`` string (equal bodies; the paper's model)."""
        return not self.sections

    @property
    def n_bodies(self) -> int:
        """Number of rigid bodies of the whole string [1]."""
        if self.uniform:
            return self.pipe.n_segments
        return sum(s.n_bodies for s in self.sections)

    @property
    def string_length(self) -> float:
        """Length of the string from the top drive to the bit [m]."""
        if self.uniform:
            return self.pipe.length
        return math.fsum(s.length for s in self.sections)

    def body_sections(self) -> tuple[int, ...]:
        """Index of the section of each body (0 for the uniform pipe), top first."""
        if self.uniform:
            return (0,) * self.pipe.n_segments
        return tuple(i for i, s in enumerate(self.sections) for _ in range(s.n_bodies))

    def body_lengths(self) -> tuple[float, ...]:
        """Length [m] of each body, top first."""
        if self.uniform:
            return (self.pipe.segment_length,) * self.pipe.n_segments
        return tuple(s.length / s.n_bodies for s in self.sections for _ in range(s.n_bodies))

    def body_tops(self) -> tuple[float, ...]:
        """Distance [m] of each body's top end from the top of the string (undeformed)."""
        if self.uniform:
            dx = self.pipe.segment_length
            return tuple(k * dx for k in range(self.pipe.n_segments))
        out, z = [], 0.0
        for ln in self.body_lengths():
            out.append(z)
            z += ln
        return tuple(out)

    def spans(self) -> list[tuple[float, float]]:
        """Spans [m from the top] between lateral supports (top pin, stabilizers), top first.

        Supports: the top drive (lateral spring > 0), the ``stabilizers`` heights and, with
        sections, the middle of every stabilizer section, the sections' stabilizer blades and
        (with a trajectory: the bit touches the hole with its gauge) the bit.
        """
        L = self.string_length
        sup = sorted({L - h for h in self.stabilizers.heights}) if self.stabilizers.stiffness else []
        if not self.uniform:
            z = 0.0
            for s in self.sections:
                if s.kind == "stabilizer":
                    sup.append(z + 0.5 * s.length)
                sup += [z + x for x in s.stabilizers]
                z += s.length
            if self.trajectory is not None:
                sup.append(L)
            sup = sorted(set(sup))
        if self.top_drive.lateral_stiffness > 0.0:
            sup = sorted({0.0, *sup})
        return [(a, b) for a, b in zip(sup[:-1], sup[1:]) if b - a > 1e-9]

    def span_middle_bodies(self) -> tuple[int, ...]:
        """Per span, the 1-based body whose top end is nearest the span's middle (paper: 11, 26)."""
        n = self.n_bodies
        if self.uniform:
            dx = self.pipe.segment_length
            return tuple(min(max(int(round(0.5 * (a + b) / dx)) + 1, 1), n)
                         for a, b in self.spans())
        tops = self.body_tops()
        return tuple(min(range(n), key=lambda k: abs(tops[k] - 0.5 * (a + b))) + 1
                     for a, b in self.spans())

    @property
    def contact_bodies(self) -> tuple[int, ...]:
        """Monitored contact bodies (1-based): the given ones, or each span's middle body.

        They exist (with their X, Y, radial deflection outputs) even when contact is off; the
        contact force is then zero. With a trajectory every body is checked for contact, and
        only the given ones are monitored (no default: a field string has hundreds).
        """
        if self.trajectory is not None:
            return tuple(self.contact.bodies)
        return tuple(self.contact.bodies) or self.span_middle_bodies()

    @property
    def actuator_joints(self) -> tuple[int, ...]:
        """Actuator/gauge sites: joint below body k (1-based), given or (the uniform pipe) below
        each span's middle; a string of sections has sites only where they are given."""
        if self.actuators.joints:
            return tuple(self.actuators.joints)
        if not self.uniform:  # a field string: sites only where asked
            return ()
        n = self.n_bodies
        return tuple(min(b, n - 1) for b in self.span_middle_bodies())

    @property
    def unbalance_body(self) -> int:
        """1-based body index of the unbalance (0 in the parameters means the bit body)."""
        return self.unbalance.body or self.n_bodies


def describe(cls: type) -> list[tuple[str, Any, str, str]]:
    """Rows (name, default, unit, description) of a parameter dataclass, for docs and FMUs."""
    rows = []
    for f in fields(cls):
        if "unit" in f.metadata:
            rows.append((f.name, f.default, f.metadata["unit"], f.metadata["doc"]))
    return rows
