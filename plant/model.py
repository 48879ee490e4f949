"""The drillstring model: parameters -> kernel arrays, state layout, initial state, outputs.

:class:`DrillstringModel` is the pure-physics object every other layer uses (the FMU adapter, the
modal analysis, the benchmarks). It builds the cheapest model a scene needs
(``"full3d"`` or ``"axial_torsional"``), fills the flat arrays of the compiled kernels once, and
owns preallocated scratch space so that stepping allocates nothing.

Frames: inertial Z points down the well from the top drive (at the origin); body z lies along
the pipe. Body k (1-based) spans depth [(k-1) dx, k dx] in the undeformed state.
"""

from __future__ import annotations

import hashlib
import math
from dataclasses import dataclass
from functools import cached_property, lru_cache

import numpy as np

try:  # optional: the plant FMU must also run in a host Python without it
    from threadpoolctl import threadpool_limits
except ImportError:  # pragma: no cover
    from contextlib import nullcontext

    def threadpool_limits(limits: int):  # noqa: D103 - same call shape, no effect
        return nullcontext()

from . import kernels as kern
from . import layout as lay
from .beam_fe import pinned_beam_frequencies
from .integrators import (
    KERNEL_ERK,
    KERNEL_ETD2,
    KERNEL_EXPEULER,
    KERNEL_RK4,
    KERNEL_VERLET,
    METHODS,
    advance_dopri5,
    advance_erk,
    advance_etd2,
    advance_expeuler,
    advance_rk4,
    advance_rk4_span,
    advance_verlet,
    block_split,
    exponential_matrices,
    polynomial_input_responses,
    stable_step,
)
from .observables import outputs3d, outputs_at
from .params import BIT_MODELS, TOP_DRIVE_MODES, PlantParams
from .sections import (
    BodyTable,
    body_fluid,
    body_table,
    chain_first_frequency,
    joint_dampers,
    local_frequencies,
    max_joint_frequency,
)
from .signals import (
    TOP_DRIVE_SPEED_COMMAND,
    TOP_DRIVE_TORQUE,
    actuator_force,
    actuator_inputs,
    plant_outputs,
    site_channels,
)
from .trajectory import StringLay, WellPath, lay_string

__all__ = ["DrillstringModel", "FIXED_STEP_METHODS", "ModelKind", "extensions", "field_outputs",
           "needs_lateral", "series"]

ModelKind = str  # "full3d" | "axial_torsional"
# exponential-integrator matrices kept per step size (each costs one expm, ~10 ms at n = 30)
_EXPM_CACHE_SIZE = 8
MODEL_KINDS = ("full3d", "axial_torsional")
# Fixed-step methods of :meth:`DrillstringModel.advance` and their stability radius |lambda dt|
# (None: no stability limit; exponential integrators treat the linear part exactly; 0: none
# automatic). The table itself: :data:`plant.integrators.METHODS`.
FIXED_STEP_METHODS = {name: m.radius for name, m in METHODS.items()}
#: Spectral radius [1/s] (with margins) of every (parameters, model kind) built in this process,
#: by :func:`spectral_key`: it costs a Jacobian (2 n_state right-hand sides) and an eigenvalue
#: problem (~50 ms for 30 bodies) that another model of the same parameters (a second FMU
#: instance, a sweep point, a re-run) need not repeat. A pure function of the key, so results
#: are unchanged; a caller may fill it from a store of its own (the plant FMU keeps one beside
#: its stable copy, per numpy version).
SPECTRAL_RADII: dict[str, float] = {}


def spectral_key(params: PlantParams, kind: str) -> str:
    """Key of :data:`SPECTRAL_RADII`: SHA-256 (hex) of ``repr((params, kind))`` (the frozen
    parameter tree's repr is complete: floats round-trip, strings are quoted)."""
    return hashlib.sha256(repr((params, kind)).encode()).hexdigest()


def series(k_boundary: float, k_half: float) -> float:
    """Stiffness [N/m or N m/rad] of a boundary spring in series with a half segment.

    ``inf`` means a rigid boundary (only the half segment remains), 0 a free end.
    """
    if k_boundary <= 0.0:
        return 0.0
    if math.isinf(k_boundary):
        return k_half
    return 1.0 / (1.0 / k_boundary + 1.0 / k_half)


def extensions(params: PlantParams) -> list[str]:
    """The extensions beyond the paper a parameter set uses (``docs/physics.md``); [] for the
    paper's model."""
    out = []
    if params.top_drive.mode != "prescribed":
        out.append(f"top_drive.mode = {params.top_drive.mode!r}")
    if params.contact.enabled and params.contact.friction_coefficient > 0.0:
        out.append("wellbore friction")
    if params.contact.whirl_outputs:
        out.append("whirl outputs")
    if params.bit.model != "prescribed":
        out.append(f"bit.model = {params.bit.model!r}")
    if params.sections:
        out.append("string sections")
    if params.trajectory is not None:
        out.append("well trajectory")
    if params.fluid.enabled:
        out.append("drilling fluid")
    if params.top_drive.hoisting_speed != 0.0:
        out.append("top-drive hoisting")
    return out


def needs_lateral(params: PlantParams) -> list[str]:
    """Reasons why a parameter set needs the lateral DOFs (empty list: axial-torsional suffices)."""
    why = []
    if params.unbalance.enabled and params.unbalance.moment > 0.0:
        why.append("unbalance")
    if any(ld.is_lateral for ld in params.loads):
        why.append("lateral loads")
    if framed(params):
        why.append("a deviated well")
    return why


def field_outputs(params: PlantParams) -> bool:
    """Do the outputs include the field summary (a string of sections or a trajectory)?"""
    return not params.uniform or params.trajectory is not None


def framed(params: PlantParams) -> bool:
    """Does the 3D model use per-body reference frames (a curved or inclined hole)?"""
    return params.trajectory is not None and not params.trajectory.vertical


@dataclass(frozen=True)
class Derived:
    """Derived per-segment quantities (SI)."""

    dx: float  # [m]
    mass: float  # [kg]
    j_transverse: float  # [kg m^2]
    j_polar: float  # [kg m^2]
    k_axial: float  # [N/m]
    k_shear: float  # [N/m]
    k_bend: float  # [N m/rad]
    k_tors: float  # [N m/rad]
    beta_axial: float  # [s]
    beta_tors: float  # [s]
    beta_bend: float  # [s] bending joint dampers
    alpha_lateral: float  # [1/s] lateral drag
    w_axial_ref: float  # [rad/s] first fixed-free axial rod frequency
    w_tors_ref: float  # [rad/s]
    w_lateral_ref: float  # [rad/s]


def derive(params: PlantParams) -> Derived:
    """Compute segment masses, inertias, joint stiffnesses and damping factors."""
    pipe = params.pipe
    dx = pipe.segment_length
    A = pipe.area
    I = pipe.second_moment
    rho = pipe.density
    ro = pipe.outer_diameter / 2.0
    ri = pipe.inner_diameter / 2.0
    mass = rho * A * dx
    j_polar = 0.5 * mass * (ro**2 + ri**2)
    j_trans = mass * (3.0 * (ro**2 + ri**2) + dx**2) / 12.0
    E = pipe.youngs_modulus
    G = pipe.shear_modulus
    w_ax = math.pi * pipe.axial_wave_speed / (2.0 * pipe.length)
    w_to = math.pi * pipe.torsional_wave_speed / (2.0 * pipe.length)
    d = params.damping
    if d.lateral_reference_frequency > 0.0:
        w_lat = d.lateral_reference_frequency
    else:
        w_lat = lateral_reference_frequency(params)
    return Derived(
        dx=dx,
        mass=mass,
        j_transverse=j_trans,
        j_polar=j_polar,
        k_axial=E * A / dx,
        k_shear=pipe.kappa * G * A / dx,
        k_bend=E * I / dx,
        k_tors=G * pipe.polar_moment / dx,
        beta_axial=2.0 * d.axial_ratio / w_ax,
        beta_tors=2.0 * d.torsional_ratio / w_to,
        beta_bend=(2.0 * d.lateral_ratio / w_lat if d.lateral_model == "joint"
                   else 2.0 * d.axial_ratio / w_ax),
        alpha_lateral=2.0 * d.lateral_ratio * w_lat if d.lateral_model == "drag" else 0.0,
        w_axial_ref=w_ax,
        w_tors_ref=w_to,
        w_lateral_ref=w_lat,
    )


@lru_cache(maxsize=64)
def lateral_reference_frequency(params: PlantParams) -> float:
    """First bending frequency [rad/s] of the pinned multi-span Euler-Bernoulli beam.

    Supports: the top (when its lateral spring is > 0) and every stabilizer. With fewer than two
    supports the string has no pinned span; the first fixed-free axial frequency is returned as a
    harmless placeholder (the lateral damping then acts at that rate).
    """
    pipe = params.pipe
    Lp = pipe.length
    sup = sorted({Lp - h for h in params.stabilizers.heights})
    if params.top_drive.lateral_stiffness > 0.0:
        sup = sorted({0.0, *sup})
    if len(sup) < 2 or params.stabilizers.stiffness == 0.0:
        return math.pi * pipe.axial_wave_speed / (2.0 * Lp)
    ei = pipe.youngs_modulus * pipe.second_moment
    rho_a = pipe.density * pipe.area
    with threadpool_limits(1):  # small dense problems: one BLAS thread is fastest
        return float(pinned_beam_frequencies(Lp, sup, ei, rho_a, n_elements=48, count=1)[0])


class DrillstringModel:
    """A drillstring ready to integrate: kernel arrays, state layout, initial state, outputs.

    Parameters
    ----------
    params : PlantParams
        The validated parameter tree.
    kind : {"full3d", "axial_torsional"}
        Which model to build. ``axial_torsional`` is refused when the parameters need lateral
        DOFs (see :func:`needs_lateral`).
    extended_outputs : bool, optional
        List the outputs of the extensions beyond the paper (whirl speed and direction per
        contact body, ...; :func:`plant.signals.plant_outputs`). Default: when one of them
        is active (:func:`extensions`), so that the paper's scenes keep the paper's interface.
    """

    def __init__(self, params: PlantParams, kind: ModelKind = "full3d",
                 extended_outputs: bool | None = None) -> None:
        if kind not in MODEL_KINDS:
            raise ValueError(f"model = {kind!r} is not allowed: one of {', '.join(MODEL_KINDS)}")
        if kind == "axial_torsional":
            why = needs_lateral(params)
            if why:
                raise ValueError(
                    "model = 'axial_torsional' cannot represent " + " and ".join(why)
                    + ": use 'full3d' (or 'auto')"
                )
        self.params = params
        self.kind = kind
        self.extended_outputs = (bool(extensions(params)) if extended_outputs is None
                                 else bool(extended_outputs))
        self.model_id = kern.MODEL_FULL3D if kind == "full3d" else kern.MODEL_AXIAL_TORSIONAL
        #: per-segment quantities of the uniform pipe (None for a string of sections)
        self.derived = derive(params) if params.uniform else None
        #: per-body masses, inertias and per-joint springs (:mod:`plant.sections`)
        self.bodies: BodyTable = body_table(params)
        self.n = params.n_bodies
        #: per-body reference frames along a curved hole (None: positions are inertial)
        self.lay: StringLay | None = None
        #: length of the bodies' block of the state (12 n or 4 n); auxiliary states follow it
        self.n_body_state = (12 if kind == "full3d" else 4) * self.n
        self.aux_names, aux_units = self._aux_layout()
        #: unit of every auxiliary state, by name
        self.aux_units = dict(zip(self.aux_names, aux_units))
        self.n_state = self.n_body_state + len(self.aux_names)
        self._build_arrays()
        n = self.n
        self.wR = np.zeros((n + 2, 3, 3))
        self.wF = np.zeros((n, 3))
        self.wM = np.zeros((n, 3))
        #: integrator scratch, shape (5, n_state): stages k1..k4 and a trial state
        self.work = np.zeros((5, self.n_state))
        self._scratch = list(self.work)
        self.verlet_lambda = 1.0  # velocity predictor of the Verlet damping forces (0.5 .. 1)
        names = plant_outputs(kind == "full3d", list(self.contact_bodies), self.n_sites,
                              extended=self.extended_outputs, field=self.field_outputs)
        self.input_names, self.input_units, self.input_docs = self._input_layout()
        self.n_inputs = len(self.input_names)
        #: the inputs that act on this model, in input order: the actuator forces only in the
        #: 3D model (the axial-torsional chain has no bending: it ignores them), then the
        #: top-drive input (what an FMU of this model needs to declare)
        self.acting_inputs = [nm for nm in self.input_names
                              if kind == "full3d" or nm not in self._actuator_inputs()]
        self.u = np.zeros(self.n_inputs)
        self.output_names = [r[0] for r in names]
        self.output_units = {r[0]: r[1] for r in names}
        self.output_docs = {r[0]: r[2] for r in names}
        self._out = np.zeros(len(names))
        self._zbit_ref = 0.0
        y0 = self.initial_state()
        self._zbit_ref = self._bit_end_z(y0)

    # ------------------------------------------------------------------ layout of extensions
    def _aux_layout(self) -> tuple[list[str], list[str]]:
        """Names and units of the auxiliary states after the bodies' block (see kernels)."""
        names, units = [], []
        mode = self.params.top_drive.mode
        if mode in ("speed", "torque"):
            names.append("top_drive.angle")
            units.append("rad")
        if mode == "torque":
            names.append("top_drive.speed")
            units.append("rad/s")
        if self.params.bit.model == "cutting":
            names.append("bit.hole_bottom")
            units.append("m")
        return names, units

    def _actuator_inputs(self) -> list[str]:
        """Names of the actuator force inputs, two per site (C, E)."""
        return actuator_inputs(self.n_sites)

    def _input_layout(self) -> tuple[list[str], dict[str, str], dict[str, str]]:
        """Names, units and descriptions of the entries of the input vector ``u``.

        Two actuator forces [N] per site (C, E), then the top-drive input of modes "speed"
        (``top_drive_speed_command`` [rad/s]) and "torque" (``top_drive_torque`` [N m]).
        """
        names, units, docs = [], {}, {}
        for s, a in site_channels(range(1, self.n_sites + 1)):
            nm = actuator_force(s, a)
            names.append(nm)
            units[nm] = "N"
            docs[nm] = (f"actuator force at {a} of site {s}, > 0 opposing a positive strain "
                        f"(a bending couple of arm {self.p[lay.ACT_ARM]:g} m)")
        mode = self.params.top_drive.mode
        if mode == "speed":
            names.append(TOP_DRIVE_SPEED_COMMAND)
            units[TOP_DRIVE_SPEED_COMMAND] = "rad/s"
            docs[TOP_DRIVE_SPEED_COMMAND] = ("rotary speed of the top drive (an ideal speed "
                                               "source; replaces the prescribed ramp)")
        elif mode == "torque":
            names.append(TOP_DRIVE_TORQUE)
            units[TOP_DRIVE_TORQUE] = "N m"
            docs[TOP_DRIVE_TORQUE] = ("motor torque on the top-drive rotor (inertia "
                                        f"{self.params.top_drive.inertia:g} kg m^2)")
        return names, units, docs

    # ------------------------------------------------------------------ arrays for kernels
    def _damping_rates(self) -> tuple[float, float, float, float, float]:
        """(beta_axial, beta_tors, beta_bend [s], alpha_lateral [1/s], max_joint_rate [1/s]).

        The uniform pipe: :func:`derive`'s values. Sections: ``beta = 2 zeta / w_1`` with ``w_1``
        the first mode of the lumped axial / torsional chain (fixed at the top drive, free at
        the bit); lateral drag or bending dampers only at a given
        ``damping.lateral_reference_frequency`` (the mud's drag damps a field string laterally).
        """
        prm = self.params
        dmp = prm.damping
        tab = self.bodies
        rate = dmp.max_joint_rate
        if rate == 0.0:
            rate = max_joint_frequency(tab)
        if prm.uniform:
            d = self.derived
            return d.beta_axial, d.beta_tors, d.beta_bend, d.alpha_lateral, rate
        seg_ax = self._segment_stiffness("axial")
        seg_to = self._segment_stiffness("tors")
        jp = tab.j_polar.copy()
        jp[-1] += prm.bit.inertia
        w_ax = chain_first_frequency(tab.mass, tab.k_axial, 2.0 * seg_ax[0])
        w_to = chain_first_frequency(jp, tab.k_tors, 2.0 * seg_to[0])
        b_ax = 2.0 * dmp.axial_ratio / w_ax
        b_to = 2.0 * dmp.torsional_ratio / w_to
        w_lat = dmp.lateral_reference_frequency
        if w_lat > 0.0 and dmp.lateral_model == "joint":
            return b_ax, b_to, 2.0 * dmp.lateral_ratio / w_lat, 0.0, rate
        alpha = 2.0 * dmp.lateral_ratio * w_lat if w_lat > 0.0 else 0.0
        return b_ax, b_to, b_ax, alpha, rate

    def _segment_stiffness(self, kind: str) -> np.ndarray:
        """Per body: the spring of its whole segment [N/m or N m/rad]: ``EA / dx`` (axial),
        ``kappa G A / dx`` (shear) or ``G J / dx`` (tors)."""
        from .sections import string_sections

        secs = string_sections(self.params)
        tab = self.bodies
        out = np.empty(tab.n)
        for k in range(tab.n):
            s = secs[tab.section[k]]
            if kind == "axial":
                out[k] = s.youngs_modulus * s.area / tab.length[k]
            elif kind == "shear":
                out[k] = s.kappa * s.shear_modulus * s.area / tab.length[k]
            else:
                out[k] = s.shear_modulus * s.polar_moment / tab.length[k]
        return out

    def _hole_diameters(self, md: np.ndarray) -> np.ndarray:
        """Hole diameter [m] at each measured depth (nan without a trajectory)."""
        traj = self.params.trajectory
        if traj is None:
            return np.full(md.size, np.nan)
        return np.array([traj.hole_diameter(float(x)) for x in md])

    def _build_arrays(self) -> None:
        prm = self.params
        tab = self.bodies
        n = self.n
        uniform = prm.uniform
        beta_ax, beta_to, beta_be, alpha_lat, max_rate = self._damping_rates()
        if uniform:  # the springs of a body's own segment (the top and bit joints' halves)
            d = self.derived
            k_ax0, k_sh0, k_to0 = (np.full(n, d.k_axial), np.full(n, d.k_shear),
                                   np.full(n, d.k_tors))
        else:
            k_ax0, k_sh0, k_to0 = (self._segment_stiffness(s) for s in ("axial", "shear", "tors"))
        p = np.zeros(lay.NP + lay.NB * n)
        # scalars of the uniform model (the top body's values for a string of sections: what
        # code written for a uniform string reads)
        p[lay.DX] = tab.length[0]
        p[lay.HALF] = tab.half[0]
        p[lay.MASS] = tab.mass[0]
        p[lay.JT] = tab.j_transverse[0]
        p[lay.JP] = tab.j_polar[0]
        p[lay.GRAV] = prm.gravity
        if n > 1:
            p[lay.K_AX] = tab.k_axial[0]
            p[lay.K_SH] = tab.k_shear[0]
            p[lay.K_BE] = tab.k_bend[0]
            p[lay.K_TO] = tab.k_tors[0]
            p[lay.C_AX] = beta_ax * tab.k_axial[0]
            p[lay.C_SH] = beta_ax * tab.k_shear[0]
            p[lay.C_BE] = beta_be * tab.k_bend[0]
            p[lay.C_TO] = beta_to * tab.k_tors[0]
            p[lay.G1] = tab.k_tors[0]
            p[lay.G3] = 2.0 * tab.k_bend[0] - tab.k_tors[0]
        td = prm.top_drive
        p[lay.KT_AX] = series(td.axial_stiffness, 2.0 * k_ax0[0])
        p[lay.KT_LAT] = series(td.lateral_stiffness, 2.0 * k_sh0[0])
        p[lay.KT_TO] = series(td.torsional_stiffness, 2.0 * k_to0[0])
        def end_damper(beta: float, k: float, inertia: float) -> float:
            return float(joint_dampers(beta, np.array([k]), np.array([4.0 * k / inertia]),
                                       max_rate)[0])

        h0 = tab.half[0]
        rot0 = max(1.0 / tab.mass[0], h0 * h0 / tab.j_transverse[0])
        p[lay.CT_AX] = end_damper(beta_ax, p[lay.KT_AX], tab.mass[0])
        p[lay.CT_LAT] = end_damper(beta_ax, p[lay.KT_LAT], 1.0 / rot0)
        p[lay.CT_TO] = end_damper(beta_to, p[lay.KT_TO], tab.j_polar[0])
        p[lay.OMEGA0] = td.rotary_speed
        p[lay.T_RAMP] = td.ramp_time
        p[lay.TD_INERTIA] = td.inertia
        p[lay.HOIST] = td.hoisting_speed
        p[lay.TD_R: lay.TD_R + 9] = np.eye(3).ravel()
        bit = prm.bit
        p[lay.KB_AX] = series(bit.axial_stiffness, 2.0 * k_ax0[-1])
        p[lay.CB_AX] = end_damper(beta_ax, p[lay.KB_AX], tab.mass[-1])
        p[lay.BIT_AMP] = bit.displacement_amplitude if bit.axial_stiffness > 0.0 else 0.0
        p[lay.BIT_LOBES] = bit.lobes
        p[lay.BIT_TORQUE] = bit.torque
        p[lay.BIT_EPS] = bit.slip_speed
        p[lay.BIT_A] = bit.radius
        p[lay.BIT_EPSI] = bit.intrinsic_specific_energy
        p[lay.BIT_ZETA] = bit.cutting_force_ratio
        p[lay.BIT_WF] = bit.wearflat_force
        p[lay.BIT_MU] = bit.friction_coefficient
        p[lay.BIT_WEAK] = bit.static_friction_ratio - 1.0
        p[lay.BIT_WSPD] = bit.weakening_speed
        p[lay.BIT_JX] = bit.inertia
        st = prm.stabilizers
        p[lay.K_STAB] = st.stiffness
        p[lay.C_STAB] = beta_ax * st.stiffness if st.damping < 0.0 else st.damping
        ct = prm.contact
        p[lay.K_CONT] = ct.stiffness if ct.enabled else 0.0
        p[lay.C_CONT] = ct.damping if ct.enabled else 0.0
        p[lay.CLEAR] = ct.clearance
        p[lay.MU_WALL] = ct.friction_coefficient if ct.enabled else 0.0
        p[lay.V_SLIP] = ct.friction_velocity
        ro = tab.outer_radius
        p[lay.R_OUT] = ro[0]
        ub = prm.unbalance
        p[lay.UNB] = ub.moment if ub.enabled else 0.0
        p[lay.ALPHA_LAT] = alpha_lat
        act = prm.actuators
        p[lay.ACT_ARM] = 2.0 * (act.radius or ro[0])
        p[lay.GAUGE_R] = act.gauge_radius or ro[0]
        self.p = p
        self.framed = framed(prm) and self.kind == "full3d"
        #: the outputs include the field summary (a string of sections or a trajectory)
        self.field_outputs = field_outputs(prm)

        # per-body records
        g = prm.gravity
        mass = tab.mass
        buoy = body_fluid(prm, tab, np.full(n, np.nan))[0]
        weight = np.where(buoy == 1.0, mass * g, mass * g * buoy)
        body_md = tab.top + tab.half
        if self.framed:
            self.lay = self._lay_string(weight)
            body_md = self.lay.md
        hole = self._hole_diameters(body_md)
        buoy, madd, clin, cq = body_fluid(prm, tab, hole)
        w2 = local_frequencies(tab)
        c_ax = joint_dampers(beta_ax, tab.k_axial, w2["axial"], max_rate)
        c_sh = joint_dampers(beta_ax, tab.k_shear, w2["shear"], max_rate)
        c_be = joint_dampers(beta_be, tab.k_bend, w2["bend"], max_rate)
        c_to = joint_dampers(beta_to, tab.k_tors, w2["tors"], max_rate)
        if prm.trajectory is None:
            clear = np.full(n, ct.clearance)
            rcon = np.full(n, p[lay.R_OUT]) if uniform else tab.contact_radius
        else:
            rcon = tab.contact_radius
            clear = 0.5 * hole - rcon
            bad = np.flatnonzero(clear < 0.0)
            if bad.size:
                k = int(bad[0])
                raise ValueError(
                    f"sections: body {k + 1} (contact diameter {2 * rcon[k]:g} m) does not fit "
                    f"the hole (diameter {hole[k]:g} m at measured depth {body_md[k]:.1f} m): "
                    "check trajectory.hole and the sections' contact_diameter")
        for k in range(n):
            o = lay.NP + lay.NB * k
            m = mass[k]
            p[o + lay.B_M] = m
            p[o + lay.B_IM] = 1.0 / m
            p[o + lay.B_ML] = m + madd[k] if madd[k] > 0.0 else m
            # the mud's added mass also follows a segment's rotation: + m_a dx^2 / 12
            p[o + lay.B_JT] = (tab.j_transverse[k] if madd[k] == 0.0 else
                               tab.j_transverse[k] + madd[k] * tab.length[k] ** 2 / 12.0)
            p[o + lay.B_JP] = tab.j_polar[k]
            p[o + lay.B_IJP] = 1.0 / tab.j_polar[k]
            p[o + lay.B_H] = tab.half[k]
            p[o + lay.B_W] = weight[k]
            p[o + lay.B_CLIN] = alpha_lat * m if clin[k] == 0.0 else alpha_lat * m + clin[k]
            p[o + lay.B_CQ] = cq[k]
            p[o + lay.B_R: o + lay.B_R + 9] = np.eye(3).ravel()
            p[o + lay.B_CLR] = clear[k]
            p[o + lay.B_RC] = rcon[k]
            if k < n - 1:
                p[o + lay.J_KAX] = tab.k_axial[k]
                p[o + lay.J_KSH] = tab.k_shear[k]
                p[o + lay.J_G1] = tab.k_tors[k]
                p[o + lay.J_G3] = 2.0 * tab.k_bend[k] - tab.k_tors[k]
                p[o + lay.J_CAX] = c_ax[k]
                p[o + lay.J_CSH] = c_sh[k]
                p[o + lay.J_CBE] = c_be[k]
                p[o + lay.J_CTO] = c_to[k]
                p[o + lay.J_LEN] = tab.joint_length[k]
                p[o + lay.J_RG] = act.gauge_radius or ro[k]
                p[o + lay.J_ARM] = 2.0 * (act.radius or ro[k])
                # the divergence guard's strain per radian: outer radius (the thinner body's)
                # over the joint's length (the uniform pipe: the pipe's radius / dx)
                p[o + lay.J_SF] = (0.5 * prm.pipe.outer_diameter / self.derived.dx if uniform
                                   else min(ro[k], ro[k + 1]) / tab.joint_length[k])
        if self.lay is not None:
            lz = self.lay
            p[lay.TD_R: lay.TD_R + 9] = lz.top_frame.ravel()
            for k in range(n):
                o = lay.NP + lay.NB * k
                F = lz.frame[k]
                p[o + lay.B_P: o + lay.B_P + 3] = lz.centre[k]
                p[o + lay.B_R: o + lay.B_R + 9] = F.ravel()
                kap = F.T @ lz.curvature[k]
                p[o + lay.B_K1] = kap[0]
                p[o + lay.B_K2] = kap[1]

        # stabilizers at material points: arc length s from the top
        L = prm.string_length
        tops = tab.top
        stab_body, stab_z = [], []
        for hgt in st.heights:
            s = L - hgt
            if uniform:
                dx = tab.length[0]
                k = min(int(math.floor(s / dx + 1e-9)), n - 1)
                stab_body.append(k)
                stab_z.append(s - (k + 0.5) * dx)
            else:
                k = min(int(np.searchsorted(tops, s + 1e-9, side="right")) - 1, n - 1)
                stab_body.append(k)
                stab_z.append(s - (tops[k] + tab.half[k]))
        if st.stiffness == 0.0:
            stab_body, stab_z = [], []
        self.contact_bodies = prm.contact_bodies
        self.sites = prm.actuator_joints
        self.n_sites = len(self.sites)
        # contact points: the monitored bodies (no trajectory), or every body and the bit's
        # gauge (a trajectory: a radial check against the local hole axis everywhere)
        if prm.trajectory is None:
            cps = [(b - 1, 0.0, ct.clearance, p[lay.R_OUT]) for b in self.contact_bodies]
        else:
            cps = [(k, 0.0, clear[k], rcon[k]) for k in range(n)]
            cps += self._stabilizer_points(hole)
            e = n - 1
            hole_bit = hole[e]
            cps.append((e, tab.half[e], max(0.0, 0.5 * hole_bit - bit.radius), bit.radius))
        unb = prm.unbalance_body - 1 if (ub.enabled and ub.moment > 0.0) else -1
        aux = {name: self.n_body_state + i for i, name in enumerate(self.aux_names)}
        ip = [n, len(stab_body), len(self.contact_bodies), self.n_sites, unb, len(prm.loads),
              TOP_DRIVE_MODES.index(td.mode), aux.get("top_drive.angle", -1),
              BIT_MODELS.index(prm.bit.model), aux.get("bit.hole_bottom", -1),
              int(self.extended_outputs), len(cps), int(self.framed), int(self.field_outputs)]
        assert len(ip) == kern.IP_HDR
        ip += stab_body + [b - 1 for b in self.contact_bodies] + [j - 1 for j in self.sites]
        self.ip = np.array(ip, dtype=np.int64)
        rows = []
        for ld in prm.loads:
            rows.append(
                [0.0 if ld.kind == "force" else 1.0, ld.body - 1, "xyz".index(ld.direction),
                 ld.magnitude, ld.start, ld.start + ld.duration, 0.0]
            )
        self.fp = np.concatenate([np.array(stab_z, dtype=float),
                                  np.array(rows, dtype=float).ravel(),
                                  np.array(cps, dtype=float).ravel()])
        # times [s] where an input of the model jumps (loads) or kinks (end of the speed ramp):
        # integrators step exactly to them (see integrators.next_breakpoint)
        bps = [t for ld in prm.loads for t in (ld.start, ld.start + ld.duration)]
        if td.ramp_time > 0.0 and (
                (td.mode == "prescribed" and td.rotary_speed != 0.0) or td.hoisting_speed != 0.0):
            bps.append(td.ramp_time)
        self.breakpoints = np.unique(np.array([t for t in bps if math.isfinite(t) and t > 0.0],
                                              dtype=float))

    def _stabilizer_points(self, hole: np.ndarray) -> list[tuple[int, float, float, float]]:
        """Contact points (body, offset from its centre [m], clearance [m], radius [m]) of the
        sections' stabilizer blades; ``hole`` [m] the hole diameter at every body."""
        from .sections import string_sections

        tab = self.bodies
        out = []
        top = 0.0
        for i, sec in enumerate(string_sections(self.params)):
            ks = np.flatnonzero(tab.section == i)
            for z in sec.stabilizers:
                s = top + z  # from the top of the string
                k = int(ks[min(np.searchsorted(tab.top[ks], s + 1e-9, side="right") - 1,
                               ks.size - 1)])
                r = 0.5 * sec.stabilizer_diameter
                clr = 0.5 * hole[k] - r
                if clr < 0.0:
                    raise ValueError(
                        f"sections ({sec.kind}): stabilizer_diameter {sec.stabilizer_diameter:g}"
                        f" m does not fit the hole (diameter {hole[k]:g} m)")
                out.append((k, s - (tab.top[k] + tab.half[k]), clr, r))
            top += sec.length
        return out

    def static_tensions(self, axis: np.ndarray, weight: np.ndarray) -> np.ndarray:
        """Static effective tension [N] in the top spring and each joint (shape (n,): entry k is
        the spring above body k), without wall friction, for body axes ``axis`` (n, 3).

        From the bit up: ``T_k = T_{k+1} (a_{k+1} . a_k) + W_k a_k,Z + F_k . a_k`` with ``W`` the
        (buoyed) weight [N] (``weight``, per body), ``F`` the axial loads acting for good from
        t = 0 and ``T_n`` minus the weight on bit: the joint forces act along the lower body's
        axis (the joints start without shear), so that the laid string is in exact axial
        balance. Once released the joints shear slightly and the hook load settles at the soft
        string's (~1 % higher in a 60 deg build).
        """
        n = self.n
        f = np.zeros((n, 3))
        f[:, 2] = weight
        for ld in self.params.loads:
            if ld.kind == "force" and ld.start <= 0.0 and math.isinf(ld.duration):
                f[ld.body - 1, "xyz".index(ld.direction)] += ld.magnitude
        T = np.zeros(n)
        below = -self.params.bit.weight_on_bit
        for k in range(n - 1, -1, -1):
            c = float(np.dot(axis[k + 1], axis[k])) if k < n - 1 else 1.0
            T[k] = below * c + float(np.dot(f[k], axis[k]))
            below = T[k]
        return T

    def _lay_string(self, weight: np.ndarray) -> StringLay:
        """The string along the hole at its static (frictionless) axial stretch."""
        prm = self.params
        tab = self.bodies
        path = WellPath(prm.trajectory.survey)
        n = self.n
        k_spring = np.concatenate([[self.p[lay.KT_AX]], tab.k_axial])
        gaps = np.zeros(n)
        lz = lay_string(path, tab.length, gaps)
        for _ in range(2):  # the stretch barely turns the axes: two passes settle it
            T = self.static_tensions(lz.axis, weight)
            gaps = np.where(k_spring > 0.0, T / np.where(k_spring > 0.0, k_spring, 1.0), 0.0)
            lz = lay_string(path, tab.length, gaps)
        return lz

    # ------------------------------------------------------------------ state layout
    def _bit_end_z(self, y: np.ndarray) -> float:
        """Depth [m] of the bit end along the hole (local to the bit body when framed)."""
        h = self.bodies.half[-1]
        if self.kind == "full3d":
            n = self.n
            ang = y[3 * n + 3 * (n - 1): 3 * n + 3 * n]
            # R[2, 2] of kern.cardan (the same libm calls, the same bits), without a numba
            # dispatch: a model built only to declare an FMU's layout sets no numba up
            r22 = math.cos(float(ang[1])) * math.cos(float(ang[2]))
            return float(y[3 * (n - 1) + 2] + h * r22)
        return float(y[self.n - 1] + h)

    def static_axial_displacement(self) -> np.ndarray:
        """Static axial displacements [m] of the bodies under gravity and weight on bit.

        Solves the linear axial chain (top spring, joints; the bit force is the prescribed weight
        on bit; axial step loads acting from t = 0 are included). Returns shape (n,).
        """
        n = self.n
        p = self.p
        f = p[lay.NP + lay.B_W: lay.NP + lay.NB * n: lay.NB].copy()  # weights [N]
        f[-1] -= self.params.bit.weight_on_bit
        for ld in self.params.loads:  # axial forces acting from t = 0 on, for good
            if ld.kind == "force" and ld.direction == "z" and ld.start <= 0.0 \
                    and math.isinf(ld.duration):
                f[ld.body - 1] += ld.magnitude
        if not np.any(f):
            return np.zeros(n)
        kt = p[lay.KT_AX]
        if kt == 0.0:
            if abs(f.sum()) > 1e-9 * max(1.0, np.abs(f).max()):
                raise ValueError(
                    "top_drive.axial_stiffness = 0 with a net axial load: the weight "
                    f"{math.fsum(f) + self.params.bit.weight_on_bit:.6g} N (with the axial "
                    "loads) must equal bit.weight_on_bit"
                )
        kj = self.bodies.k_axial
        Kd = np.zeros((n, n))
        for a in range(n - 1):
            ka = kj[a]
            Kd[a, a] += ka
            Kd[a + 1, a + 1] += ka
            Kd[a, a + 1] -= ka
            Kd[a + 1, a] -= ka
        Kd[0, 0] += kt
        if kt == 0.0:
            Kd[0, 0] += kj[0] * 1e-12  # fix the floating chain's mean; the shape is what matters
        return np.linalg.solve(Kd, f)

    def initial_state(self) -> np.ndarray:
        """The string at rest along the hole axis in static axial equilibrium (without wall
        friction); shape (n_state,).

        A vertical hole: body positions are inertial (depths of the mass centres). A curved
        hole (``framed``): each body sits at its reference frame's origin (local position 0;
        the stretched string laid along the hole, :func:`plant.trajectory.lay_string`), and the
        string settles onto the low side once released.
        """
        n = self.n
        y = np.zeros(self.n_state)
        if self.framed:
            z = np.zeros(n)
        else:
            if self.params.uniform:
                z = (np.arange(n) + 0.5) * self.derived.dx + self.static_axial_displacement()
            else:
                tab = self.bodies
                z = tab.top + tab.half + self.static_axial_displacement()
            if self.kind == "full3d":
                y[2:3 * n:3] = z
            else:
                y[:n] = z
        if self.params.bit.axial_stiffness > 0.0:
            zb = z[-1] + self.bodies.half[-1]
            kb = self.p[lay.KB_AX]
            self.p[lay.ZBIT0] = zb - self.params.bit.weight_on_bit / kb
            if self.params.bit.model == "cutting":  # the hole bottom under the pressed bit
                self.p[lay.BIT_ZH0] = self.p[lay.ZBIT0]
                y[self.aux_names.index("bit.hole_bottom") + self.n_body_state] = self.p[lay.ZBIT0]
        return y

    # ------------------------------------------------------------------ evaluation
    def rhs(self, t: float, y: np.ndarray, u: np.ndarray | None = None) -> np.ndarray:
        """Time derivative of the state (allocates the result; for scipy and tests).

        Parameters
        ----------
        t : float
            Time [s].
        y : numpy.ndarray, shape (n_state,)
        u : numpy.ndarray, shape (n_inputs,), optional
            Inputs in the order of :attr:`input_names` (actuator forces [N], C and E per site,
            then the top-drive input if any); defaults to the model's held inputs.
        """
        dy = np.empty(self.n_state)
        kern.set_load_modes(self.ip, self.fp, float(t))
        kern.rhs(self.model_id, float(t), np.ascontiguousarray(y, dtype=float), dy, self.p, self.ip,
              self.fp, self.u if u is None else np.asarray(u, dtype=float), self.wR, self.wF,
              self.wM)
        return dy

    def outputs(self, t: float, y: np.ndarray, u: np.ndarray | None = None) -> np.ndarray:
        """Output vector in the order of :attr:`output_names` (a view reused between calls)."""
        fn = outputs3d if self.kind == "full3d" else outputs_at
        fn(float(t), y, self.p, self.ip, self.fp, self.u if u is None else u, self.wR,
           self._zbit_ref, self._out)
        return self._out

    def output_dict(self, t: float, y: np.ndarray) -> dict[str, float]:
        """Outputs as a name -> value dict (convenience; allocates)."""
        return dict(zip(self.output_names, self.outputs(t, y).tolist()))

    def energy(self, t: float, y: np.ndarray) -> float:
        """Total mechanical energy [J] of the string (kinetic + elastic + gravity potential)."""
        return float(self.outputs(t, y)[self._energy_index])

    @cached_property
    def _energy_index(self) -> int:
        return self.output_names.index("total_energy")

    # ------------------------------------------------------------------ integration
    def jacobian(self, t: float, y: np.ndarray, rel_step: float = 1e-7) -> np.ndarray:
        """Central finite-difference Jacobian of :meth:`rhs`; shape (n_state, n_state)."""
        N = self.n_state
        J = np.empty((N, N))
        yp = y.copy()
        for i in range(N):
            h = rel_step * max(1.0, abs(y[i]))
            yp[i] = y[i] + h
            fp = self.rhs(t, yp)
            yp[i] = y[i] - h
            fm = self.rhs(t, yp)
            yp[i] = y[i]
            J[:, i] = (fp - fm) / (2.0 * h)
        return J

    @cached_property
    def initial_jacobian(self) -> np.ndarray:
        """Jacobian of the rhs at t = 0 and the initial (static equilibrium) state [1/s].

        Shape (n_state, n_state); the step choice and the exponential integrators share it.
        """
        return self.jacobian(0.0, self.initial_state())

    @cached_property
    def max_eigenvalue(self) -> float:
        """Spectral radius [1/s] of the Jacobian at the initial state, plus active-contact margin.

        Contact adds at most k_w/m to the squared frequency of one body; that margin is added so
        that the step stays stable when the pipe touches the wellbore. Computed once per
        parameter set and model kind in a process.
        """
        key = spectral_key(self.params, self.kind)
        if key not in SPECTRAL_RADII:
            SPECTRAL_RADII[key] = self.spectral_radius_with_margins(self.initial_jacobian)
        return SPECTRAL_RADII[key]

    def spectral_radius_with_margins(self, J: np.ndarray) -> float:
        """Spectral radius [1/s] of ``J`` (a Jacobian of this model, possibly augmented) plus
        the margins of :attr:`max_eigenvalue` for effects the initial state does not show."""
        with threadpool_limits(1):  # 6x faster than multithreaded BLAS on a loaded machine
            lam = float(np.max(np.abs(np.linalg.eigvals(J))))
        touching = self.ip[kern.IP_NCP] > 0 and self.kind == "full3d"
        kc = self.p[lay.K_CONT] if touching else 0.0
        cc = self.p[lay.C_CONT] if touching else 0.0
        m = float(self.bodies.mass[self._contact_point_bodies()].min()) if touching else 1.0
        return math.sqrt(lam**2 + kc / m) + cc / m

    def _contact_point_bodies(self) -> np.ndarray:
        """0-based body of every contact point (rows of the contact-point table)."""
        ncp = int(self.ip[kern.IP_NCP])
        o = self.ip[kern.IP_NS] + lay.NLD * self.ip[kern.IP_NL]
        return self.fp[o + lay.CP_BODY: o + lay.NCP * ncp: lay.NCP].astype(np.int64)

    def stable_step(self) -> float:
        """Largest stable RK4 step [s] for this model (from :attr:`max_eigenvalue`)."""
        return stable_step(self.max_eigenvalue)

    def advance(self, t0: float, y: np.ndarray, n_steps: int, dt: float,
                u: np.ndarray | None = None, method: str = "rk4") -> int:
        """Integrate ``y`` in place over ``n_steps`` fixed steps of ``dt`` [s] from ``t0`` [s].

        ``method``: a fixed-step method of :data:`plant.integrators.METHODS`: ``"rk4"``
        (default), explicit Runge-Kutta methods of fewer stages (``"kutta3"``, ...),
        ``"verlet"`` (velocity Verlet, 1 rhs a step), ``"expeuler"`` / ``"etd2"``
        (exponential integrators about the equilibrium Jacobian, axial-torsional model only).
        Returns the number of completed steps before a non-finite state (``n_steps`` if
        none). Step loads switch once a step (at its midpoint): a step that straddles a
        switch time sees one value; :meth:`advance_span` and ``PlantSimulator`` split the steps
        at :attr:`breakpoints`.
        """
        k1, k2, k3, k4, yt = self._scratch
        uu = self.u if u is None else u
        a = (self.model_id, float(t0), y, int(n_steps), float(dt))
        w = (self.p, self.ip, self.fp, uu, self.wR, self.wF, self.wM)
        spec = METHODS.get(method)
        kernel = spec.kernel if spec is not None else -1
        if kernel == KERNEL_RK4:
            return int(advance_rk4(*a, *w, k1, k2, k3, k4, yt))
        if kernel == KERNEL_ERK:
            A, b, c = spec.tableau
            return int(advance_erk(*a, A, b, c, self.work[:4], yt, *w))
        if kernel == KERNEL_VERLET:
            if self.n_state != self.n_body_state:
                raise ValueError(f"method = 'verlet' needs a state of positions and velocities; "
                                 f"this model has the first-order states {self.aux_names}: use "
                                 "'rk4'")
            H = self.n_state // 2
            return int(advance_verlet(*a, self.verlet_lambda, *w, k1, k2, k3[:H], k4[:H]))
        if kernel in (KERNEL_EXPEULER, KERNEL_ETD2):
            if kernel == KERNEL_EXPEULER:
                return int(advance_expeuler(*a, *self.expeuler_operator(float(dt)), *w, k1, k2))
            P1, P2, Q = self.exponential_matrices(float(dt))
            return int(advance_etd2(*a, P1, P2, Q, *w, k1, k2, k3))
        raise ValueError(f"method = {method!r} is not allowed: one of "
                         f"{', '.join(FIXED_STEP_METHODS)}")

    def advance_span(self, t0: float, t1: float, max_dt: float, y: np.ndarray,
                     u: np.ndarray | None = None) -> float:
        """RK4 from ``t0`` to ``t1`` [s], steps <= ``max_dt`` [s], split at :attr:`breakpoints`.

        ``y`` (shape (n_state,)) is advanced in place; returns the time [s] reached (``t1``
        unless the state stopped being finite).
        """
        k1, k2, k3, k4, yt = self._scratch
        return float(advance_rk4_span(
            self.model_id, float(t0), float(t1), float(max_dt), self.breakpoints, y, self.p,
            self.ip, self.fp, self.u if u is None else u, self.wR, self.wF, self.wM, k1, k2, k3,
            k4, yt))

    def exponential_matrices(self, dt: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(P1, P2, Q)`` of the exponential integrators for step ``dt`` [s] (cached per dt).

        Built from the Jacobian at the initial (static equilibrium) state; only for the
        axial-torsional model, which is linear up to the small-twist ``sin`` and the bit torque.
        """
        if self.kind != "axial_torsional":
            raise ValueError("exponential integrators need the axial-torsional model (the full "
                             "3D model is far from linear under spin): use 'rk4' or 'verlet'")
        cache = self.__dict__.setdefault("_expm_cache", {})
        if dt not in cache:
            if len(cache) >= _EXPM_CACHE_SIZE:
                cache.pop(next(iter(cache)))
            cache[dt] = exponential_matrices(self.initial_jacobian, dt)
        return cache[dt]

    def expeuler_operator(self, dt: float) -> tuple[np.ndarray, ...]:
        """Exponential Euler's operator for step ``dt`` [s]: ``P1 = dt phi1(dt A)`` in the block
        form of ``block_split``, then the top drive's ramp vectors (3, n_state), or (0,
        n_state) when no drive moves (:func:`plant.integrators.add_drive_ramp`)."""
        cache = self.__dict__.setdefault("_p1_blocks", {})
        if dt not in cache:
            if len(cache) >= _EXPM_CACHE_SIZE:  # variable steps: keep the newest few
                cache.pop(next(iter(cache)))
            cache[dt] = (*block_split(self.exponential_matrices(dt)[0]), self._drive_ramp(dt))
        return cache[dt]

    def _drive_ramp(self, dt: float) -> np.ndarray:
        """The ramp vectors of :func:`plant.integrators.add_drive_ramp` for step ``dt`` [s].

        The drives that move: hoisting (the top spring and damper on body 1's axial motion)
        and a prescribed rotation (the torsional ones on its rotation). Each enters ``f`` as
        ``(K x(t) + C x'(t)) g``, ``g`` the unit vector of body 1's acceleration over its mass
        (polar inertia), ``x`` the drive's travel [m or rad]; in the equilibrium Jacobian
        ``A`` the torsional spring's ``sin`` is linear. Rows, summed over the drives times
        their speed: ``C P1 g``, ``K dt^2 phi2 g``, ``C dt^2 phi2 g + K dt^3 phi3 g``.
        """
        p = self.p
        n = self.n
        drives = []  # (speed, state index, 1 / inertia, K, C)
        if p[lay.HOIST] != 0.0:
            drives.append((p[lay.HOIST], 2 * n, p[lay.NP + lay.B_IM], p[lay.KT_AX],
                           p[lay.CT_AX]))
        if self.params.top_drive.mode == "prescribed" and p[lay.OMEGA0] != 0.0 \
                and p[lay.KT_TO] > 0.0:
            drives.append((p[lay.OMEGA0], 3 * n, p[lay.NP + lay.B_IJP], p[lay.KT_TO],
                           p[lay.CT_TO]))
        if not drives:
            return np.zeros((0, self.n_state))
        G = np.zeros((self.n_state, len(drives)))
        for j, (_speed, i, inv, _k, _c) in enumerate(drives):
            G[i, j] = inv
        W = polynomial_input_responses(self.initial_jacobian, G, dt)
        ramp = np.zeros((3, self.n_state))
        for j, (speed, _i, _inv, k, c) in enumerate(drives):
            ramp[0] += speed * c * W[0][:, j]
            ramp[1] += speed * k * W[1][:, j]
            ramp[2] += speed * (c * W[1][:, j] + k * W[2][:, j])
        return ramp

    @property
    def exponential_exclusions(self) -> list[str]:
        """Why the exact exponential step does not fit this model ([] when it does).

        It fits the axial-torsional chain, linear up to the small-twist ``sin``, with inputs
        it integrates exactly whatever the step: inputs held over a step (a top-drive speed
        command or motor torque), step loads (steps split at their switch times), and the top
        drive's prescribed hoisting and rotation (piecewise polynomial in time:
        :func:`plant.integrators.add_drive_ramp`). It does not fit the full 3D model (far
        from linear under spin) or the bit's nonlinear or oscillating inputs: the cutting bit
        (a unilateral contact and friction law), a bit torque (``tanh`` of the bit speed) and
        the prescribed bit displacement (a sine of the top-drive angle: exponential Euler
        would hold it over a step, a first-order error).
        """
        p = self.p
        out = []
        if self.kind != "axial_torsional":
            out.append(f"model = {self.kind!r} (not linear: the exact step needs "
                       "'axial_torsional')")
        if self.params.bit.model == "cutting":
            out.append("bit.model = 'cutting' (a nonlinear contact and friction law)")
        if p[lay.BIT_AMP] != 0.0 and p[lay.KB_AX] != 0.0:
            out.append("bit.displacement_amplitude > 0 (a sine of the top-drive angle, not "
                       "polynomial in time)")
        if p[lay.BIT_TORQUE] != 0.0:
            out.append("bit.torque > 0 (tanh of the bit speed: nonlinear)")
        return out

    @property
    def default_method(self) -> str:
        """The fastest accurate integrator for this model when the step size is not known:
        :meth:`method_for_step` with ``h = None``."""
        return self.method_for_step(None)

    def method_for_step(self, h: float | None) -> str:
        """The fastest accurate fixed-step method for communication steps of ``h`` [s].

        Exponential Euler (exact for the linear chain, one step a communication step) unless
        :attr:`exponential_exclusions` names a reason: the axial-torsional chain whose inputs
        are held over a step, step loads, or the top drive's prescribed hoisting and rotation
        (ramps: integrated exactly through ``phi`` functions). Else, among the methods of
        :data:`plant.integrators.METHODS` marked ``automatic`` for this model kind (they met
        the accuracy bar of ``BENCHMARKS.md`` at their automatic step; explicit Runge-Kutta
        methods that evaluate the prescribed motions at their stage times, so a hoisting or
        rotation ramp is integrated to their order, its end a breakpoint), the fewest
        right-hand side evaluations per communication step, ``stages * ceil(h / stable
        step)`` (per unit time, ``stages / stable step``, for ``h = None``); ties go to fewer
        internal steps (less work besides the right-hand sides), then to the higher order.
        For the paper's 3D string at 0.25 ms (the closed loop) one step of Kutta's 3rd-order
        method beats one RK4 step; at 1 ms three RK4 steps tie with four 3-stage steps and
        RK4 is kept.
        """
        if not self.exponential_exclusions:
            return "expeuler"
        best: tuple[tuple[float, float, int], str] | None = None
        for spec in METHODS.values():
            if self.kind not in spec.automatic or not spec.radius:
                continue
            dt = stable_step(self.max_eigenvalue, spec.radius)
            if h is None:
                key = (spec.stages / dt, 1.0 / dt, -spec.order)
            else:
                n_sub = max(1, math.ceil(h / dt - 1e-9))
                key = (float(spec.stages * n_sub), float(n_sub), -spec.order)
            if best is None or key < best[0]:
                best = (key, spec.name)
        assert best is not None, "no automatic method in the table"
        return best[1]

    def advance_adaptive(self, t0: float, t1: float, y: np.ndarray, hstate: np.ndarray,
                         rtol: float = 1e-6, atol: float = 1e-9, u: np.ndarray | None = None,
                         max_steps: int = 1_000_000, stats: np.ndarray | None = None) -> int:
        """Adaptive Dormand-Prince 5(4) from ``t0`` to exactly ``t1`` [s], ``y`` in place.

        ``hstate`` (shape (1,)) carries the step proposal [s] between calls (<= 0: automatic).
        Returns 0 on success, a negative code on failure (see ``integrators.DP5_*``).
        """
        K = self.__dict__.get("_dp5_K")
        if K is None:
            K = self.__dict__.setdefault("_dp5_K", np.zeros((7, self.n_state)))
        st = np.zeros(3, dtype=np.int64) if stats is None else stats
        k1, k2 = self._scratch[:2]
        return int(
            advance_dopri5(self.model_id, float(t0), float(t1), y, hstate, st, float(rtol),
                           float(atol), int(max_steps), self.p, self.ip, self.fp,
                           self.u if u is None else u, self.wR, self.wF, self.wM, K, k1, k2)
        )
