"""pythonfmu adapter: the top-drive speed controller as an FMI 2.0 co-simulation FMU.

This file is the FMU's slave module. It holds no control law: ``do_step`` reads the
measured drive speed and top torque, calls the vendored copy of the ``controller`` package
(:class:`controller.TopDriveController`, shipped as ``resources/_dcs_controller_0_1_0/``)
and writes the motor torque. It drives a plant FMU whose top drive is in mode ``"torque"``
(``[top_drive] mode = "torque"``; ``drillcosim build --scene SCENE`` builds that plant with
the input ``top_drive_torque``). Where numba is loaded in the process (by the plant FMU),
every doStep runs the law's compiled step (``controller.compiled``, ``slave_support.LawSlave``)
without entering Python.

Interface (value references follow the registration order below)
-----------------------------------------------------------------
inputs (Real, continuous, start 0):
    top_rotary_speed [rad/s] (drive speed), top_torque [N.m] (torque the drive applies to
    the string); the plant outputs of the same names.
output (Real, continuous, initial exact, start 0):
    top_drive_torque [N.m]: the motor torque after ``doStep(t, h)`` (at ``t + h``), computed
    from the inputs set before the step (held over it). No direct feedthrough.
parameters:
    target_speed [rad/s], p_gain [N.m.s/rad], i_gain [N.m/rad], torque_feedback [1],
    ramp_time [s] (all tunable), enabled (Boolean, fixed). The law:
    ``T_m = p_gain e + i_gain integral(e) + torque_feedback top_torque``,
    ``e = target_speed min(t / ramp_time, 1) - top_rotary_speed`` (``controller/top_drive.py``).

Error handling and FMU state: the status protocol of ``slave_support.LawSlave`` (invalid
parameters -> fmi2Error at fmi2ExitInitializationMode naming them, every doStep refused; a
non-finite input -> fmi2Error from that doStep, state unchanged; the FMU state holds the
integral and the last motor torque, bit for bit).
"""

from __future__ import annotations

from typing import Any, ClassVar

from _dcs_pythonfmu_0_7_0 import (
    Boolean,
    DefaultExperiment,
    Fmi2Causality,
    Fmi2Initial,
    Fmi2Variability,
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
    TopDriveController as TopDriveLaw,
)
from _dcs_controller_0_1_0 import TopDriveControllerParams  # noqa: E402

INPUTS: tuple[str, ...] = ("top_rotary_speed", "top_torque")
OUTPUTS: tuple[str, ...] = ("top_drive_torque",)
#: (name, unit, description) of the tunable Real parameters, in registration order.
PARAMETERS: tuple[tuple[str, str, str], ...] = (
    ("target_speed", "rad/s", "Target rotary speed of the drive; |target_speed| <= 1e3"),
    ("p_gain", "N.m.s/rad", "Proportional gain P of the speed controller; 0 <= P < inf"),
    ("i_gain", "N.m/rad", "Integral gain I of the speed controller; 0 <= I < inf"),
    ("torque_feedback", "1", "Top-torque feedback gain k_T: T_m += k_T top_torque; "
                             "-10 <= k_T < 1 (0 = plain PI)"),
    ("ramp_time", "s", "The speed reference ramps from 0 to target_speed over this time; >= 0"),
)


class TopDriveController(LawSlave):
    """FMI 2.0 co-simulation adapter of :class:`controller.TopDriveController`."""

    author = "drillcosim"
    version = "0.1.0"
    description = (
        "Top-drive speed controller (PI on the drive speed with top-torque feedback, soft-torque "
        "style): motor torque = P e + I integral(e) + k_T top_torque, e = speed reference - "
        "drive speed; drives a plant in top_drive.mode 'torque'")

    REAL_INPUTS = INPUTS
    REAL_OUTPUTS = OUTPUTS
    TUNABLE = tuple(row[0] for row in PARAMETERS)
    FIXED = ("enabled",)
    LAW_PACKAGE = _CONTROLLER
    #: Units of the Real variables, written into modelDescription.xml by the build.
    VARIABLE_UNITS: ClassVar[dict[str, str]] = {
        "top_rotary_speed": "rad/s", "top_torque": "N.m", "top_drive_torque": "N.m",
        **{name: unit for name, unit, _doc in PARAMETERS}}
    #: No output depends directly on an input (it changes only in doStep).
    DIRECT_FEEDTHROUGH: ClassVar[dict[str, tuple[str, ...]]] = dict.fromkeys(OUTPUTS, ())

    def __init__(self, **kwargs: Any) -> None:
        super().__init__(**kwargs)
        self.default_experiment = DefaultExperiment(start_time=0.0, stop_time=60.0,
                                                    step_size=1e-3)
        defaults = TopDriveControllerParams()
        for name, _unit, _doc in PARAMETERS:
            setattr(self, name, getattr(defaults, name))
        self.enabled = defaults.enabled
        self._law = TopDriveLaw(defaults)
        cont = Fmi2Variability.continuous
        self.register_real_io(Real("top_rotary_speed", causality=Fmi2Causality.input,
                                   variability=cont, description="Rotary speed of the top drive"))
        self.register_real_io(Real("top_torque", causality=Fmi2Causality.input, variability=cont,
                                   description="Torque the top drive applies to the string"))
        self.register_real_io(Real(
            "top_drive_torque", causality=Fmi2Causality.output, variability=cont,
            initial=Fmi2Initial.exact, description="Motor torque on the top-drive rotor"))
        param = Fmi2Causality.parameter
        for name, _unit, doc in PARAMETERS:
            self.register_variable(Real(name, causality=param,
                                        variability=Fmi2Variability.tunable, description=doc))
        self.register_variable(Boolean("enabled", causality=param,
                                       variability=Fmi2Variability.fixed,
                                       description="false = zero motor torque at all times"))
        if _IMPORT_WARNING:
            self.log(f"{self.instance_name}: {_IMPORT_WARNING}", status=Fmi2Status.warning)

    def _params_from_variables(self) -> TopDriveControllerParams:
        """Validated parameters from the FMU variables (ValueError naming a bad one)."""
        return TopDriveControllerParams(
            **{name: getattr(self, name) for name, _u, _d in PARAMETERS},
            enabled=bool(self.enabled))

    def _make_law(self, params: TopDriveControllerParams) -> TopDriveLaw:
        return TopDriveLaw(params)

    def _step_law(self, t: float, h: float) -> None:
        speed, torque = self.inputs
        self.outputs[0] = self._law.step(t, h, float(speed), float(torque))
