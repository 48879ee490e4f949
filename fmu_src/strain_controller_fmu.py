"""pythonfmu adapter: the strain-feedback controller as an FMI 2.0 co-simulation FMU.

This file is the FMU's slave module. It holds no control law: ``do_step`` reads the
inputs, calls the vendored copy of the ``controller`` package and writes the
outputs. The build (``fmu_src/build.py``) ships ``controller/`` inside the FMU as
``resources/_dcs_controller_0_1_0/`` and imports it under that name, so the FMU
runs in a Python that has only numpy, and it never shadows (nor is shadowed by) a
``controller`` package imported by the host process.

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

Error handling (the wrapper's status protocol, see ``fmu_src/slave_support``)
------------------------------------------------------------------------------
* parameter out of range: fmi2ExitInitializationMode -> fmi2Error naming it; the instance
  stays in initialization mode (a doStep is refused). Use ``fmi2Reset`` or a new instance;
* non-finite input or time, invalid tunable parameter, fixed parameter changed,
  negative step -> fmi2Error from that doStep (state unchanged, the importer may
  correct the cause and retry); doStep before initialization -> fmi2Error
  (checked by the wrapper itself);
* unknown value reference, wrong type, setting an output, a state that is not one
  of this FMU -> fmi2Error from that get/set/setFMUstate call itself (a get
  returns NaN / 0 / false for that reference, a set ignores it);
* an unexpected exception -> fmi2Error, the instance stays usable. Never fmi2Fatal.

The Real inputs and outputs live in the shared buffers ``self.inputs`` / ``self.outputs``:
in step mode the wrapper moves them without Python, and ``fmi2DoStep`` is one Python call.

FMU state (``fmi2Get/SetFMUstate``, serialisable): pythonfmu's default saves the
registered variables only (here including the buffered inputs and outputs);
``_get_fmu_state`` / ``_set_fmu_state`` are overridden to add the lag state of the
controller and the initialization flag (JSON-safe Python floats, so serialisation
round-trips bit for bit).
"""

from __future__ import annotations

from typing import Any, ClassVar

import numpy as np
from _dcs_controller_0_1_0 import MODES, ControllerParams
from _dcs_controller_0_1_0 import StrainController as StrainLaw
from _dcs_pythonfmu_0_7_0 import (
    Boolean,
    DefaultExperiment,
    Fmi2Causality,
    Fmi2Initial,
    Fmi2Variability,
    Integer,
    Real,
)
from _dcs_slave_support_0_1_0 import DcsSlave

#: Name under which the build vendors ``controller/`` into this FMU's resources.
VENDORED_CONTROLLER = "_dcs_controller_0_1_0"

INPUTS: tuple[str, ...] = ("strain1_C", "strain1_E", "strain2_C", "strain2_E")
OUTPUTS: tuple[str, ...] = (
    "actuator1_force_C", "actuator1_force_E", "actuator2_force_C", "actuator2_force_E")
TUNABLE: tuple[str, ...] = ("gain", "force_limit", "symmetric_force_limit", "switch_on_time")
FIXED: tuple[str, ...] = ("mode", "lag_time_constant", "enabled")

_STATE_KEY = "__dcs_controller_state__"
_INIT_KEY = "__dcs_initialized__"
_INIT_ERROR_KEY = "__dcs_init_error__"


class StrainController(DcsSlave):
    """FMI 2.0 co-simulation adapter of :class:`controller.StrainController`."""

    author = "drillcosim"
    version = "0.1.0"
    description = (
        "Proportional strain-feedback controller for lateral drillstring vibration "
        "(4 channels: sites 1/2 x gauges C/E); F = gain*strain, F > 0 = compressive at "
        "D / tensile at C; saturation, switch-on time, first-order actuator lag")

    REAL_INPUTS = INPUTS
    REAL_OUTPUTS = OUTPUTS
    #: Units of the Real variables, written into modelDescription.xml by the build.
    VARIABLE_UNITS: ClassVar[dict[str, str]] = {
        **dict.fromkeys(INPUTS, "1"),
        **dict.fromkeys(OUTPUTS, "N"),
        "gain": "N",
        "force_limit": "N",
        "symmetric_force_limit": "N",
        "switch_on_time": "s",
        "lag_time_constant": "s",
    }
    #: Inputs each output depends on *directly* (within the same communication
    #: point): none for every output, they change only in doStep.
    DIRECT_FEEDTHROUGH: ClassVar[dict[str, tuple[str, ...]]] = dict.fromkeys(OUTPUTS, ())

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

        self._law = StrainLaw(defaults)
        self._initialized = False
        self._init_error: str | None = None  # invalid parameters at initialization
        self._fixed_values: tuple[Any, ...] = ()
        self._tunable_values: tuple[Any, ...] | None = None

        sites = {"1": "site 1 (long span)", "2": "site 2 (short span)"}
        for name in INPUTS:
            site, axis = name[6], name[-1]
            self.register_real_io(Real(
                name, causality=Fmi2Causality.input, variability=Fmi2Variability.continuous,
                description=f"Surface strain at gauge {axis}, {sites[site]}; tensile > 0"))
        for name in OUTPUTS:
            site, axis = name[8], name[-1]
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

    # ------------------------------------------------------------------ helpers
    def _params_from_variables(self) -> ControllerParams:
        """Build validated parameters from the FMU variables (ValueError if invalid)."""
        mode = self.mode
        if isinstance(mode, bool) or not isinstance(mode, int) or not 0 <= mode < len(MODES):
            raise ValueError(f"mode = {mode!r} is not allowed; allowed: 0 (unrestricted) or "
                             f"1 (compressive_only)")
        return ControllerParams(
            gain=self.gain, mode=MODES[mode], force_limit=self.force_limit,
            symmetric_force_limit=self.symmetric_force_limit,
            switch_on_time=self.switch_on_time, lag_time_constant=self.lag_time_constant,
            enabled=bool(self.enabled))

    def _snapshot(self, names: tuple[str, ...]) -> tuple[Any, ...]:
        return tuple(getattr(self, n) for n in names)

    # ---------------------------------------------------------------- FMI calls
    def exit_initialization_mode(self) -> None:
        try:
            params = self._params_from_variables()
        except ValueError as exc:
            self._init_error = f"invalid parameter: {exc}"
            self._initialized = False
            self._error(f"fmi2ExitInitializationMode: {self._init_error}; every doStep "
                        f"will be rejected (reset or re-instantiate with valid parameters)")
            return
        self._init_error = None
        self._law = StrainLaw(params)
        self._fixed_values = self._snapshot(FIXED)
        self._tunable_values = self._snapshot(TUNABLE)
        self._initialized = True

    def do_step(self, current_time: float, step_size: float) -> None:
        if self._init_error is not None:
            return self._error(f"step rejected: {self._init_error}")
        if not self._initialized:
            return self._error("doStep called before initialization "
                               "(fmi2ExitInitializationMode); step rejected")
        if self._snapshot(FIXED) != self._fixed_values:
            return self._error(f"fixed parameters {FIXED} changed after initialization; "
                               f"step rejected")
        tunable = self._snapshot(TUNABLE)
        if tunable != self._tunable_values:
            try:
                self._law.params = self._params_from_variables()  # keeps the lag state
            except ValueError as exc:
                return self._error(f"invalid parameter: {exc}; step rejected")
            self._tunable_values = tunable
        try:
            forces = self._law.step(current_time, step_size, self.inputs)
        except ValueError as exc:
            return self._error(f"at t = {current_time!r}: {exc}; step rejected")
        self.outputs[:] = forces
        return None

    # ------------------------------------------------------------- FMU state
    def _get_fmu_state(self) -> dict[str, Any]:
        state = super()._get_fmu_state()
        state[_STATE_KEY] = self._law.get_state().tolist()
        state[_INIT_KEY] = self._initialized
        state[_INIT_ERROR_KEY] = self._init_error
        return state

    def _set_fmu_state(self, state: dict[str, Any]) -> None:
        try:
            state = dict(state)  # the importer may set the same state again: do not mutate it
            law_state = np.array(state.pop(_STATE_KEY), dtype=float)
            initialized = state.pop(_INIT_KEY)
            init_error = state.pop(_INIT_ERROR_KEY)
            super()._set_fmu_state(state)
            self._law.set_state(law_state)
        except Exception as exc:  # noqa: BLE001 - a foreign state is the importer's error
            return self._error(f"fmi2SetFMUstate: not a state of this FMU ({exc!r})")
        self._init_error = init_error
        self._initialized = bool(initialized)
        # the parameters came back with the registered variables: take the fixed ones
        # as the reference and make the next doStep re-validate and apply all of them
        self._fixed_values = self._snapshot(FIXED)
        self._tunable_values = None
        return None
