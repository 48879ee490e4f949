"""pythonfmu adapter: any registered controller law as an FMI 2.0 co-simulation FMU.

This file is the slave module of every controller FMU of the project (``StrainController``,
``TopDriveController``, ``StateSpaceController``, ``PDStrainController``, ...). It holds no
control law and spells no variable: the build (``fmu_src/build.py``) generates, per law and
layout, a subclass of :class:`LawController` whose class attributes ``KIND`` (the law's kind in
``controller/registry.py``) and ``LAYOUT`` (its interface: ``Law.layout_for``) select the law;
the adapter registers the law's port table (``Law.ports(LAYOUT)``: inputs, outputs,
parameters, in that order = the value references), turns the parameters into the law's
validated parameters (``Law.decode``) and steps the law (``Law.advance``, or its compiled
step). The build ships ``controller/`` inside the FMU under a versioned name (imported from a
stable per-user copy where numba is installed: ``slave_support.vendored``), so the FMU runs in a
Python that has only numpy and never shadows a ``controller`` package of the host.

Interface: the law's port table (the README's generated tables show the default FMUs). Outputs
are ``initial="exact"``, start 0; the outputs after ``doStep(t, h)`` are the law's at ``t + h``
from the inputs set before the step (held over it): no direct feedthrough.

A law whose numbers come from a file (``Law.RESOURCE``, e.g. the state-space matrices) reads it
from ``resources/<RESOURCE>`` at instantiation, checked against ``LAYOUT``
(``Law.load_resource``); a file that does not fit fails ``fmi2Instantiate`` with one message.

Error handling and FMU state: the status protocol of ``slave_support.LawSlave`` (invalid
parameters -> fmi2Error at fmi2ExitInitializationMode naming them, every doStep refused until a
reset; a fixed parameter changed after initialization, an invalid tunable one or a bad input ->
fmi2Error from that doStep, state unchanged; the FMU state holds the law's state bit for bit).
Where numba is loaded in the process (by the plant FMU), every doStep runs the law's compiled
step without entering Python; ``DRILLCOSIM_COMPILED_STEP=0`` switches it off.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, ClassVar

import _dcs_slave_support_0_1_0 as support

#: The controller package, imported from its stable copy where numba can compile the laws'
#: steps (numba's cache needs a fixed path).
_CONTROLLER, _IMPORT_WARNING = support.vendored.import_vendored(
    "_dcs_controller_0_1_0", __file__, ("registry", "ports"), only_with="numba")


class LawController(support.LawSlave):
    """FMI 2.0 co-simulation adapter of the registered law ``KIND`` for ``LAYOUT``."""

    author = "drillcosim"
    version = "0.1.0"
    #: The law (a kind of ``controller/registry.py``) and its layout: set by the build's variant.
    KIND: ClassVar[str] = ""
    LAYOUT: ClassVar[dict[str, Any]] = {}
    LAW: ClassVar[Any] = None
    PORTS: ClassVar[tuple[Any, ...]] = ()
    LAW_PACKAGE = _CONTROLLER

    def __init_subclass__(cls, **kwargs: Any) -> None:
        """A law's FMU: its tables from ``KIND`` and ``LAYOUT``."""
        super().__init_subclass__(**kwargs)
        if not cls.__dict__.get("KIND"):
            return
        ports = _CONTROLLER.ports
        cls.LAW = _CONTROLLER.registry.law_named(cls.KIND)
        cls.PORTS = cls.LAW.ports(cls.LAYOUT)
        cls.REAL_INPUTS = ports.names(ports.inputs(cls.PORTS))
        cls.REAL_OUTPUTS = ports.names(ports.outputs(cls.PORTS))
        params = ports.parameters(cls.PORTS)
        cls.TUNABLE = tuple(p.name for p in params if p.variability == "tunable")
        cls.FIXED = tuple(p.name for p in params if p.variability == "fixed")
        cls.VARIABLE_UNITS = support.units_of(cls.PORTS)
        cls.VARIABLE_RANGES = support.ranges_of(cls.PORTS)
        cls.DIRECT_FEEDTHROUGH = dict.fromkeys(cls.REAL_OUTPUTS, ())
        cls.description = str(cls.LAYOUT.get("description") or cls.LAW.DESCRIPTION)

    def __init__(self, **kwargs: Any) -> None:
        super().__init__(**kwargs)
        self.default_experiment = support.DefaultExperiment(
            start_time=0.0, stop_time=30.0,
            step_size=float(self.LAYOUT.get("sample_period", 1e-3)))
        self._base: Any = None  # what the law reads from its resource file
        self.register_ports(self.PORTS, self.param_values)
        resource = getattr(self.LAW, "RESOURCE", "")
        try:
            if resource:
                if not self.resources:
                    raise ValueError(f"no resources folder: {resource} cannot be found")
                self._base = self.LAW.load_resource(Path(self.resources) / resource,
                                                    self.LAYOUT)
            self._law = self.LAW.create(self._params_from_variables(), self.LAYOUT)
        except ValueError as exc:
            # the wrapper takes this status from the construction: fmi2Instantiate fails
            self._error(f"fmi2Instantiate: {exc}")
        if _IMPORT_WARNING:
            self.log(f"{self.instance_name}: {_IMPORT_WARNING}",
                     status=support.Fmi2Status.warning)

    # ------------------------------------------------------------------ the law
    def _params_from_variables(self) -> Any:
        """The law's validated parameters from the parameter variables (ValueError naming a
        bad one)."""
        if self._base is not None:
            return self.LAW.decode(self.param_values, self.LAYOUT, self._base)
        return self.LAW.decode(self.param_values, self.LAYOUT)

    def _make_law(self, params: Any) -> Any:
        return self.LAW.create(params, self.LAYOUT)

    def _step_law(self, t: float, h: float) -> None:
        self._law.advance(t, h, self.inputs, self.outputs)
