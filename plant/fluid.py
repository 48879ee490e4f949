"""Drilling fluid: buoyancy, lateral added mass and hydrodynamic drag of a string section.

All three act only when ``[fluid] enabled = true``.

Buoyancy (string open at both ends, mud inside and out): the pressure field of the mud acts on
the steel like a body force ``-rho_mud g V_steel`` (Archimedes), i.e. the weight is multiplied by
the buoyancy factor ``1 - rho_mud / rho_steel``; the axial force in the joints is then the
effective tension of Lubinski. ``V_steel`` = mass / steel density, so tool joints (a
``linear_mass`` above density x area) displace their own volume.

Lateral added mass per length (potential flow, no viscosity): the mud inside the pipe moves with
it, ``rho_mud pi r_i^2``; the mud displaced outside adds ``C_a rho_mud pi r_o^2`` with
``C_a = (D_h^2 + D_o^2) / (D_h^2 - D_o^2)`` for a cylinder moving inside a concentric rigid
cylinder of diameter ``D_h`` (Chen, Wambsganss and Jendrzejczyk 1976, J. Appl. Mech. 43; Fritz
1972, J. Eng. Ind. 94): 1 in open water, rising fast as the annulus narrows (5-in pipe in an
8.5-in hole: 2.06; 6.75-in collars: 4.4). Axial and torsional motion carry no added mass here.

Hydrodynamic drag per length on the lateral velocity ``v``: quadratic (Morison, O'Brien, Johnson
and Schaaf 1950) ``1/2 rho_mud C_d D_o |v| v`` and linear ``c_lin v``.
"""

from __future__ import annotations

import math

from .params import FluidParams, SectionParams

__all__ = ["buoyancy_factor", "added_mass_coefficient", "lateral_added_mass", "drag_coefficients"]


def buoyancy_factor(fluid: FluidParams, steel_density: float) -> float:
    """Weight in mud / weight in air [1] (1 with the fluid off)."""
    return 1.0 - fluid.density / steel_density if fluid.enabled else 1.0


def added_mass_coefficient(section: SectionParams, hole_diameter: float) -> float:
    """C_a [1] of ``section`` in a hole of ``hole_diameter`` [m] (``nan``: no hole, unconfined)."""
    if section.added_mass_coefficient >= 0.0:
        return section.added_mass_coefficient
    if not math.isfinite(hole_diameter):
        return 1.0
    dh2 = hole_diameter**2
    do2 = section.outer_diameter**2
    if dh2 <= do2:
        raise ValueError(f"sections ({section.kind}): outer diameter {section.outer_diameter:g} m"
                         f" does not fit the hole diameter {hole_diameter:g} m")
    return (dh2 + do2) / (dh2 - do2)


def lateral_added_mass(fluid: FluidParams, section: SectionParams, length: float,
                       hole_diameter: float) -> float:
    """Lateral added mass [kg] of a body of ``length`` [m]: inner mud + displaced mud x C_a."""
    if not fluid.enabled:
        return 0.0
    ri2 = (0.5 * section.inner_diameter) ** 2
    ro2 = (0.5 * section.outer_diameter) ** 2
    ca = added_mass_coefficient(section, hole_diameter)
    return fluid.density * math.pi * (ri2 + ca * ro2) * length


def drag_coefficients(fluid: FluidParams, section: SectionParams,
                      length: float) -> tuple[float, float]:
    """Lateral drag of a body of ``length`` [m]: (linear [N s/m], quadratic [N s^2/m^2])."""
    if not fluid.enabled:
        return 0.0, 0.0
    return (fluid.linear_drag * length,
            0.5 * fluid.density * fluid.drag_coefficient * section.outer_diameter * length)
