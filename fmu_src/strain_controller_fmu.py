"""pythonfmu adapter: the strain-feedback controller as an FMI 2.0 co-simulation FMU.

This file is the FMU's slave module. It holds no control law: ``do_step`` reads the
inputs, calls the vendored copy of the ``controller`` package and writes the
outputs. The build (``fmu_src/build.py``) ships ``controller/`` inside the FMU as
``resources/_dcs_controller_0_1_0/`` and imports it under that name, so the FMU
runs in a Python that has only numpy, and it never shadows (nor is shadowed by) a
``controller`` package imported by the host process. Where numba is installed the
package is imported from a stable per-user copy (``slave_support.vendored``), and where
numba is loaded in the process (by the plant FMU, in the main job) the law's compiled step
(``controller.compiled``) runs every doStep without entering Python
(``slave_support.LawSlave``); ``DRILLCOSIM_COMPILED_STEP=0`` switches it off.

Interface (value references follow the registration order below)
-----------------------------------------------------------------
inputs  (Real, unit "1", continuous, start 0):
    strain1_C, strain1_E, strain2_C, strain2_E
outputs (Real, unit "N", continuous, initial exact, start 0):
    actuator1_force_C, actuator1_force_E, actuator2_force_C, actuator2_force_E
    The force after ``doStep(t, h)`` is the actuator force at ``t + h``, computed
    from the strains set before the step (held over the step). There is no
    direct feedthrough: setting an input does not change an output until the
    next ``doStep``.
parameters:
    gain [N] (tunable), force_limit [N] (tunable), symmetric_force_limit [N]
    (tunable), switch_on_time [s] (tunable), mode (Integer, fixed: 0 =
    unrestricted, 1 = compressive_only), lag_time_constant [s] (fixed),
    enabled (Boolean, fixed).

``mode`` is an Integer rather than a String: every FMI 2.0 importer handles
Integer parameters (and SSP parameter sets), String parameters are often
unsupported, and pythonfmu cannot declare an Enumeration.

Built for a scene (a variant)
-----------------------------
``drillcosim build --scene SCENE`` builds this adapter for the scene's number of sites: a
generated subclass ``StrainController_<scene>`` (``fmu_src/build.py``, "Variants") whose
class attribute ``LAYOUT`` holds the number of sites and the scene's gain matrix. It has
``strain<s>_<C|E>`` inputs and ``actuator<s>_force_<C|E>`` outputs for every site s and,
besides the parameters above, the tunable relative gains ``gain_matrix_<i>_<j>`` [1] (start:
the scene's matrix, else the identity): per axis ``F = gain * M @ strain`` across the sites
(``controller/strain_feedback.py``); the identity is the SISO law.

Error handling (the wrapper's status protocol, see ``fmu_src/slave_support``)
------------------------------------------------------------------------------
* parameter out of range: fmi2ExitInitializationMode -> fmi2Error naming it; the instance
  stays in initialization mode (a doStep is refused): correct it and call it again;
* non-finite input or time, invalid tunable parameter, negative step -> fmi2Error
  from that doStep (state unchanged, the importer may correct the cause and retry);
  doStep before initialization -> fmi2Error (checked by the wrapper itself);
* unknown value reference, wrong type, setting an output or a fixed parameter after
  initialization, a state refused (``slave_support.state``) -> fmi2Error from that
  get/set/setFMUstate call itself (a get returns NaN / 0 / false for that reference;
  a refused set sets none of the call's values);
* an unexpected exception -> fmi2Error, the instance stays usable. Never fmi2Fatal.

The Real inputs and outputs live in the shared buffers ``self.inputs`` / ``self.outputs``:
in step mode the wrapper moves them without Python, and ``fmi2DoStep`` calls the law's
compiled step (or, without numba, is one Python call); both give the same bits.

FMU state (``fmi2Get/SetFMUstate``, serialisable; the rules of ``slave_support.state``):
the registered variables (the buffered inputs and outputs included) and the lag state of
the controller (``slave_support.LawSlave``; JSON-safe Python floats, so serialisation
round-trips bit for bit); after initialization a state's parameters are checked as at
initialization before any of it is applied.
"""

from __future__ import annotations

from typing import Any, ClassVar

from _dcs_pythonfmu_0_7_0 import (
    Boolean,
    DefaultExperiment,
    Fmi2Causality,
    Fmi2Initial,
    Fmi2Variability,
    Integer,
    Real,
)
from _dcs_pythonfmu_0_7_0.enums import Fmi2Status
from _dcs_slave_support_0_1_0 import LawSlave
from _dcs_slave_support_0_1_0.vendored import import_vendored

#: Name under which the build vendors ``controller/`` into this FMU's resources.
VENDORED_CONTROLLER = "_dcs_controller_0_1_0"
# from a stable copy where numba can compile the law's step (its cache needs a fixed path)
_CONTROLLER, _IMPORT_WARNING = import_vendored(VENDORED_CONTROLLER, __file__, only_with="numba")
from _dcs_controller_0_1_0 import (  # noqa: E402 - imported above from its stable copy
    MODES,
    ControllerParams,
)
from _dcs_controller_0_1_0 import StrainController as StrainLaw  # noqa: E402


def _io_names(n_sites: int) -> tuple[tuple[str, ...], tuple[str, ...]]:
    """(inputs, outputs): the strains and the actuator forces of ``n_sites`` sites."""
    channels = [(s, a) for s in range(1, n_sites + 1) for a in ("C", "E")]
    return (tuple(f"strain{s}_{a}" for s, a in channels),
            tuple(f"actuator{s}_force_{a}" for s, a in channels))


def _matrix_names(n_sites: int) -> tuple[str, ...]:
    """Parameter names of the relative gain matrix, row by row."""
    return tuple(f"gain_matrix_{i}_{j}" for i in range(1, n_sites + 1)
                 for j in range(1, n_sites + 1))


def _units(inputs: tuple[str, ...], outputs: tuple[str, ...], n_matrix: int) -> dict[str, str]:
    return {**dict.fromkeys(inputs, "1"), **dict.fromkeys(outputs, "N"),
            **dict.fromkeys(_matrix_names(n_matrix), "1"),
            "gain": "N", "force_limit": "N", "symmetric_force_limit": "N",
            "switch_on_time": "s", "lag_time_constant": "s"}


INPUTS, OUTPUTS = _io_names(2)
TUNABLE: tuple[str, ...] = ("gain", "force_limit", "symmetric_force_limit", "switch_on_time")
FIXED: tuple[str, ...] = ("mode", "lag_time_constant", "enabled")


class StrainController(LawSlave):
    """FMI 2.0 co-simulation adapter of :class:`controller.StrainController`."""

    author = "drillcosim"
    version = "0.1.0"
    description = (
        "Proportional strain-feedback controller for lateral drillstring vibration "
        "(4 channels: sites 1/2 x gauges C/E); F = gain*strain, F > 0 = compressive at "
        "D / tensile at C; saturation, switch-on time, first-order actuator lag")

    #: Sites served and the start of the relative gain matrix (None: no matrix parameters,
    #: the default build). A variant sets ``LAYOUT`` and gets them derived.
    N_SITES: ClassVar[int] = 2
    GAIN_MATRIX: ClassVar[tuple[tuple[float, ...], ...] | None] = None
    SITE_NAMES: ClassVar[dict[int, str]] = {1: "site 1 (long span)", 2: "site 2 (short span)"}
    REAL_INPUTS = INPUTS
    REAL_OUTPUTS = OUTPUTS
    TUNABLE = TUNABLE
    FIXED = FIXED
    LAW_PACKAGE = _CONTROLLER
    #: Units of the Real variables, written into modelDescription.xml by the build.
    VARIABLE_UNITS: ClassVar[dict[str, str]] = _units(INPUTS, OUTPUTS, 0)
    #: Inputs each output depends on *directly* (within the same communication
    #: point): none for every output, they change only in doStep.
    DIRECT_FEEDTHROUGH: ClassVar[dict[str, tuple[str, ...]]] = dict.fromkeys(OUTPUTS, ())

    def __init_subclass__(cls, **kwargs: Any) -> None:
        """A variant: the class tables from its ``LAYOUT`` (``n_sites``, ``gain_matrix``)."""
        super().__init_subclass__(**kwargs)
        layout = cls.__dict__.get("LAYOUT")
        if layout is None:
            return
        n = int(layout["n_sites"])
        cls.N_SITES = n
        cls.GAIN_MATRIX = tuple(tuple(float(x) for x in row) for row in layout["gain_matrix"])
        if len(cls.GAIN_MATRIX) != n or any(len(row) != n for row in cls.GAIN_MATRIX):
            raise ValueError(f"{cls.__name__}: LAYOUT gain_matrix must be {n} x {n}")
        cls.SITE_NAMES = {s: f"site {s}" for s in range(1, n + 1)}
        cls.REAL_INPUTS, cls.REAL_OUTPUTS = _io_names(n)
        cls.TUNABLE = TUNABLE + _matrix_names(n)
        cls.VARIABLE_UNITS = _units(cls.REAL_INPUTS, cls.REAL_OUTPUTS, n)
        cls.DIRECT_FEEDTHROUGH = dict.fromkeys(cls.REAL_OUTPUTS, ())
        cls.description = str(layout["description"])

    def __init__(self, **kwargs: Any) -> None:
        super().__init__(**kwargs)
        self.default_experiment = DefaultExperiment(start_time=0.0, stop_time=30.0,
                                                    step_size=1e-3)
        defaults = ControllerParams()
        self.gain = defaults.gain
        self.force_limit = defaults.force_limit
        self.symmetric_force_limit = 1e30
        self.switch_on_time = defaults.switch_on_time
        self.mode = MODES.index(defaults.mode)
        self.lag_time_constant = defaults.lag_time_constant
        self.enabled = defaults.enabled
        self._law = StrainLaw(defaults, self.N_SITES)

        sites = self.SITE_NAMES
        for name in self.REAL_INPUTS:
            site, axis = int(name[6:-2]), name[-1]
            self.register_real_io(Real(
                name, causality=Fmi2Causality.input, variability=Fmi2Variability.continuous,
                description=f"Surface strain at gauge {axis}, {sites[site]}; tensile > 0"))
        for name in self.REAL_OUTPUTS:
            site, axis = int(name[8:-8]), name[-1]
            other = {"C": "D", "E": "F"}[axis]
            self.register_real_io(Real(
                name, causality=Fmi2Causality.output, variability=Fmi2Variability.continuous,
                initial=Fmi2Initial.exact,
                description=(f"Actuator force at {sites[site]}, axis {axis}; > 0 = compressive "
                             f"at {other} / tensile at {axis} (couple opposing positive strain)")))
        tunable, fixed = Fmi2Variability.tunable, Fmi2Variability.fixed
        param = Fmi2Causality.parameter
        self.register_variable(Real(
            "gain", causality=param, variability=tunable,
            description="Proportional gain, N per unit strain; 0 <= gain < inf (paper: 1e9)"))
        self.register_variable(Real(
            "force_limit", causality=param, variability=tunable,
            description="Peak push force in compressive_only mode; 0 <= force_limit <= inf"))
        self.register_variable(Real(
            "symmetric_force_limit", causality=param, variability=tunable,
            description="Limit on |force| in unrestricted mode; >= 0 (1e30 = effectively none)"))
        self.register_variable(Real(
            "switch_on_time", causality=param, variability=tunable,
            description="Controller output is zero before this time; >= 0"))
        self.register_variable(Integer(
            "mode", causality=param, variability=fixed,
            description="0 = unrestricted (push and pull), 1 = compressive_only (push only)"))
        self.register_variable(Real(
            "lag_time_constant", causality=param, variability=fixed,
            description="First-order actuator lag time constant; 0 = no lag"))
        self.register_variable(Boolean(
            "enabled", causality=param, variability=fixed,
            description="false = open loop (zero force at all times)"))
        if self.GAIN_MATRIX is not None:
            self._register_matrix()
        if _IMPORT_WARNING:
            self.log(f"{self.instance_name}: {_IMPORT_WARNING}", status=Fmi2Status.warning)

    def _register_matrix(self) -> None:
        """The tunable relative gains ``gain_matrix_<i>_<j>`` [1], start = the layout's."""
        n = self.N_SITES
        for name, start in zip(_matrix_names(n), (x for row in self.GAIN_MATRIX for x in row)):
            i, j = name.split("_")[2:]
            self.param_values[name] = start

            def getter(name: str = name) -> float:
                return self.param_values[name]

            def setter(value: float, name: str = name) -> None:
                self.param_values[name] = value

            self.register_variable(Real(
                name, causality=Fmi2Causality.parameter, variability=Fmi2Variability.tunable,
                getter=getter, setter=setter,
                description=(f"Relative gain from the strain of site {j} to the force of site "
                             f"{i}, both axes: F_axis = gain * M @ strain_axis; identity = "
                             f"one P law per channel")), nested=False)

    # ------------------------------------------------------------------ the law
    def _params_from_variables(self) -> ControllerParams:
        """Build validated parameters from the FMU variables (ValueError if invalid)."""
        mode = self.mode
        if isinstance(mode, bool) or not isinstance(mode, int) or not 0 <= mode < len(MODES):
            raise ValueError(f"mode = {mode!r} is not allowed; allowed: 0 (unrestricted) or "
                             f"1 (compressive_only)")
        matrix: tuple = ()
        if self.GAIN_MATRIX is not None:
            n = self.N_SITES
            flat = [self.param_values[name] for name in _matrix_names(n)]
            matrix = tuple(tuple(flat[i * n:(i + 1) * n]) for i in range(n))
        return ControllerParams(
            gain=self.gain, mode=MODES[mode], force_limit=self.force_limit,
            symmetric_force_limit=self.symmetric_force_limit,
            switch_on_time=self.switch_on_time, lag_time_constant=self.lag_time_constant,
            enabled=bool(self.enabled), gain_matrix=matrix)

    def _make_law(self, params: ControllerParams) -> StrainLaw:
        return StrainLaw(params, self.N_SITES)

    def _step_law(self, t: float, h: float) -> None:
        self.outputs[:] = self._law.step(t, h, self.inputs)
