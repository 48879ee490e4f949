"""The drillstring model: which model a scene needs, its state and input layout, outputs.

:class:`DrillstringModel` is the pure-physics object every other layer uses (the FMU adapter, the
analysis, the benchmarks). It builds the cheapest model a scene needs (``"full3d"`` or
``"axial_torsional"``), lays out its state and inputs, evaluates the right-hand side and the
outputs, and owns preallocated scratch space so that stepping allocates nothing. Its other jobs
are a module each, joined as its bases: the kernel arrays (:mod:`plant.assembly`), the statics
and the initial state (:mod:`plant.statics`), stepping and the method choice
(:mod:`plant.stepping`).

Frames: inertial Z points down the well from the top drive (at the origin); body z lies along
the pipe. Body k (1-based) spans depth [(k-1) dx, k dx] in the undeformed state.
"""

from __future__ import annotations

from functools import cached_property

import numpy as np

from . import kernels as kern
from . import layout as lay
from .assembly import ArrayAssembly, derive, field_outputs, framed, series
from .observables import outputs3d, outputs_at
from .params import PlantParams
from .sections import BodyTable, body_table
from .signals import (
    TOP_DRIVE_SPEED_COMMAND,
    TOP_DRIVE_TORQUE,
    actuator_force,
    actuator_inputs,
    plant_outputs,
    site_channels,
)
from .statics import StaticState
from .stepping import FIXED_STEP_METHODS, SPECTRAL_RADII, Stepping, spectral_key
from .trajectory import StringLay

__all__ = ["DrillstringModel", "FIXED_STEP_METHODS", "MODEL_KINDS", "SPECTRAL_RADII", "ModelKind",
           "extensions", "field_outputs", "framed", "needs_lateral", "series", "spectral_key"]

ModelKind = str  # "full3d" | "axial_torsional"
MODEL_KINDS = ("full3d", "axial_torsional")


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


class DrillstringModel(ArrayAssembly, StaticState, Stepping):
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
