"""The base class of our pythonfmu adapters: one status protocol, guarded access, Real buffers.

Vendored into every FMU as ``_dcs_slave_support_0_1_0`` (see ``fmu_src/build.py``); the FMUs
run on our C wrapper (``fmu_src/wrapper``), whose status protocol this class speaks:

* **Status.** Every FMI callback returns None; a problem is reported by :meth:`DcsSlave._error`,
  which logs the message (status and category ``logStatus<Status>``) and raises
  ``self._fmi2_status`` to that status; the wrapper returns the highest status of the call
  and resets the attribute (the constructor's too: fmi2Error there makes fmi2Instantiate
  fail, e.g. a resource file that does not fit). No anticipated problem raises; an unexpected
  exception becomes fmi2Error with its traceback and the instance stays usable.
* **Guarded get/set.** A bad value reference, a wrong type or writing a variable that is not
  settable is fmi2Error from that get/set call, naming the variable (a get returns NaN / 0 /
  false / "" for it, a set ignores it). Adapters add their own rules by overriding
  :meth:`DcsSlave._access_problem`.
* **Real buffers.** The Real inputs and outputs named in ``REAL_INPUTS`` / ``REAL_OUTPUTS`` live
  in two float64 arrays, ``self.inputs`` and ``self.outputs`` (shapes ``(len(REAL_INPUTS),)``
  and ``(len(REAL_OUTPUTS),)``), fixed for the instance's lifetime: the adapter reads inputs
  and writes outputs in place (``out=``, ``[:] =``), never rebinds them. The wrapper takes them
  once through :meth:`DcsSlave._fmi2_real_buffers` and then moves those values in step mode
  without calling Python (one Python call per doStep).
* **Guarded set, all or nothing.** Every value reference of a set call is checked before any
  value is written: one refused variable (among them a fixed parameter after initialization,
  :meth:`DcsSlave._fixed_parameters_locked`) makes the whole call fmi2Error, one logged line,
  nothing written (inputs of the same call included).
* **FMU state** (:mod:`.state`): the registered variables plus :meth:`DcsSlave._internal_state`;
  ``fmi2SetFMUstate`` checks it as a parameter set (:meth:`DcsSlave._restore_internal`) and
  applies all of it or nothing (fmi2Error naming why).
"""

from __future__ import annotations

import importlib
import math
import sys
from collections.abc import Callable
from types import ModuleType
from typing import Any, ClassVar

import numpy as np
from _dcs_pythonfmu_0_7_0 import (
    Boolean,
    DefaultExperiment,
    Fmi2Causality,
    Fmi2Initial,
    Fmi2Slave,
    Fmi2Variability,
    Integer,
    Real,
    String,
    enums,
)

from . import state as fmu_state
from . import vendored
from .native import provide

Fmi2Status = enums.Fmi2Status

__all__ = ["DcsSlave", "DefaultExperiment", "Fmi2Status", "LawSlave", "XmlReal", "ranges_of",
           "units_of", "vendored"]

#: (variable class, conversion of a value, neutral value of a rejected get)
_KINDS: dict[str, tuple[type, Callable[[Any], Any], Any]] = {
    "Real": (Real, float, math.nan),
    "Integer": (Integer, int, 0),
    "Boolean": (Boolean, bool, False),
    "String": (String, str, ""),
}


def _xml_double(value: float) -> str:
    """Shortest round-trip text of a float in XML Schema form (INF, -INF, NaN)."""
    if math.isnan(value):
        return "NaN"
    if math.isinf(value):
        return "INF" if value > 0 else "-INF"
    return repr(float(value))


class XmlReal(Real):
    """A Real whose start is written round-trip exact and XML-Schema valid (``INF``)."""

    def to_xml(self) -> Any:
        node = super().to_xml()
        real = node.find("Real")
        if real is not None and self.start is not None:
            real.set("start", _xml_double(float(self.start)))
        return node


#: FMI type name of a port -> (variable class, conversion of a start value)
_TYPES: dict[str, tuple[type, Callable[[Any], Any]]] = {
    "Real": (XmlReal, float), "Integer": (Integer, int), "Boolean": (Boolean, bool),
    "String": (String, str)}


def units_of(ports: Any) -> dict[str, str]:
    """``{name: unit}`` of the Real ports that have a unit (what the build writes into the
    modelDescription: ``VARIABLE_UNITS``)."""
    return {p.name: p.unit for p in ports if p.type == "Real" and p.unit}


def ranges_of(ports: Any) -> dict[str, tuple[float, float]]:
    """``{name: (min, max)}`` of the ports with a declared range (``VARIABLE_RANGES``)."""
    return {p.name: tuple(p.range) for p in ports if p.range is not None}


class DcsSlave(Fmi2Slave):
    """pythonfmu slave with our status protocol, guarded access and shared Real buffers.

    Subclasses set ``REAL_INPUTS`` / ``REAL_OUTPUTS`` (names, in value-reference order of
    registration) and register those variables with :meth:`register_real_io`.
    """

    #: Names of the Real inputs held in ``self.inputs`` (index = position).
    REAL_INPUTS: ClassVar[tuple[str, ...]] = ()
    #: Names of the Real outputs held in ``self.outputs`` (index = position).
    REAL_OUTPUTS: ClassVar[tuple[str, ...]] = ()

    def __init__(self, **kwargs: Any) -> None:
        super().__init__(**kwargs)
        #: Highest status reported during the current call; read and reset by the wrapper.
        self._fmi2_status: int | None = None
        #: Real inputs [input units], shape (len(REAL_INPUTS),); shared with the wrapper.
        self.inputs = np.zeros(len(self.REAL_INPUTS))
        #: Real outputs [output units], shape (len(REAL_OUTPUTS),); shared with the wrapper.
        self.outputs = np.zeros(len(self.REAL_OUTPUTS))

    # ---------------------------------------------------------------- the protocol
    def _error(self, msg: str, status: Fmi2Status = Fmi2Status.error) -> None:
        """Log ``msg`` (prefixed by the instance name) and raise the call's status to ``status``."""
        self.log(f"{self.instance_name}: {msg}", status=status)
        self._fmi2_status = max(self._fmi2_status or 0, int(status))

    # ------------------------------------------------------------------- buffers
    def register_real_io(self, var: Real) -> None:
        """Register a Real input or output whose value lives in ``inputs`` / ``outputs``."""
        if var.causality == Fmi2Causality.input:
            array, i = self.inputs, self.REAL_INPUTS.index(var.name)
        elif var.causality == Fmi2Causality.output:
            array, i = self.outputs, self.REAL_OUTPUTS.index(var.name)
        else:
            raise ValueError(f"{var.name}: only inputs and outputs live in the buffers")

        def getter() -> float:
            return float(array[i])

        def setter(value: float) -> None:
            array[i] = value

        var.getter, var.setter = getter, setter
        self.register_variable(var, nested=False)

    def register_ports(self, ports: Any, values: dict[str, Any]) -> None:
        """Register the variables of a port table (``controller/ports.py``, ``plant/signals.py``
        rows: name, causality, variability, unit, description, start, range, type), in order.

        Real inputs and outputs live in the buffers (:meth:`register_real_io`; an output with a
        start is ``initial="exact"``, one without ``"calculated"``); a parameter's value lives
        in ``values`` (set to its start here), read and written through getter and setter.
        """
        for port in ports:
            cls, convert = _TYPES[port.type]
            causality = Fmi2Causality[port.causality]
            variability = Fmi2Variability[port.variability]
            if port.causality in ("input", "output"):
                initial = None
                if port.causality == "output":
                    initial = Fmi2Initial.calculated if port.start is None else Fmi2Initial.exact
                self.register_real_io(cls(port.name, causality=causality, variability=variability,
                                          initial=initial, description=port.description))
                continue
            values[port.name] = convert(port.start)

            def getter(name: str = port.name) -> Any:
                return values[name]

            def setter(value: Any, name: str = port.name) -> None:
                values[name] = value

            self.register_variable(cls(port.name, causality=causality, variability=variability,
                                       description=port.description, getter=getter,
                                       setter=setter), nested=False)

    def _fmi2_real_buffers(self) -> tuple[list[int], np.ndarray, list[int], np.ndarray]:
        """(input vrs, inputs, output vrs, outputs): what the wrapper moves without Python."""
        vr_of = {var.name: vr for vr, var in self.vars.items()}
        return ([vr_of[n] for n in self.REAL_INPUTS], self.inputs,
                [vr_of[n] for n in self.REAL_OUTPUTS], self.outputs)

    # ----------------------------------------------------------- guarded access
    def _access_problem(self, vr: int, kind: type, call: str) -> str | None:
        """Why ``call`` (e.g. ``"setReal"``) may not access ``vr``, or None if it may."""
        var = self.vars.get(vr)
        if var is None:
            return f"unknown value reference {vr} (valid: 0..{len(self.vars) - 1})"
        if not isinstance(var, kind):
            return f"value reference {vr} ({var.name}) is not of type {kind.__name__}"
        if call.startswith("set") and var.causality not in (Fmi2Causality.input,
                                                            Fmi2Causality.parameter):
            return f"{var.name} (value reference {vr}) is an {var.causality.name}: not settable"
        if (call.startswith("set") and var.variability == Fmi2Variability.fixed
                and self._fixed_parameters_locked()):
            return (f"{var.name} (value reference {vr}) is a fixed parameter: it cannot be set "
                    f"after initialization")
        return None

    def _fixed_parameters_locked(self) -> bool:
        """Whether the instance is past ``fmi2ExitInitializationMode`` (fixed parameters then
        refuse a set). Adapters with fixed parameters override it."""
        return False

    def _accessible(self, vr: int, kind: type, call: str) -> bool:
        """Whether ``call`` may access ``vr``; if not, the call is fmi2Error naming why."""
        problem = self._access_problem(vr, kind, call)
        if problem is not None:
            self._error(f"{call}: {problem}")
        return problem is None

    def _get(self, vrs: list[int], kind_name: str) -> list[Any]:
        kind, convert, neutral = _KINDS[kind_name]
        call = f"get{kind_name}"
        return [convert(self.vars[vr].getter()) if self._accessible(vr, kind, call) else neutral
                for vr in vrs]

    def _set(self, vrs: list[int], values: list[Any], kind_name: str) -> None:
        kind, convert, _neutral = _KINDS[kind_name]
        call = f"set{kind_name}"
        problems = [p for p in (self._access_problem(vr, kind, call) for vr in vrs) if p]
        if problems:  # the whole call is refused: nothing written
            return self._error(f"{call}: {'; '.join(problems)} (nothing of this call was set)")
        for vr, value in zip(vrs, values):
            self.vars[vr].setter(convert(value))
        return None

    def get_real(self, vrs: list[int]) -> list[float]:
        return self._get(vrs, "Real")

    def get_integer(self, vrs: list[int]) -> list[int]:
        return self._get(vrs, "Integer")

    def get_boolean(self, vrs: list[int]) -> list[bool]:
        return self._get(vrs, "Boolean")

    def get_string(self, vrs: list[int]) -> list[str]:
        return self._get(vrs, "String")

    def set_real(self, vrs: list[int], values: list[float]) -> None:
        self._set(vrs, values, "Real")

    def set_integer(self, vrs: list[int], values: list[int]) -> None:
        self._set(vrs, values, "Integer")

    def set_boolean(self, vrs: list[int], values: list[bool]) -> None:
        self._set(vrs, values, "Boolean")

    def set_string(self, vrs: list[int], values: list[str]) -> None:
        self._set(vrs, values, "String")

    # ------------------------------------------------------------- FMU state
    def _get_fmu_state(self) -> dict[str, Any]:
        return fmu_state.capture(self)

    def _set_fmu_state(self, state: dict[str, Any]) -> None:
        problem = fmu_state.restore(self, state)
        if problem is not None:
            self._error(f"fmi2SetFMUstate: refused: {problem}; the instance is unchanged")

    def _fmu_state_to_bytes(self, state: dict[str, Any]) -> bytes:
        return fmu_state.encode(state)

    def _fmu_state_from_bytes(self, payload: bytes) -> dict[str, Any] | None:
        """The state of a payload (the wrapper checked the rest); None and fmi2Error if it is
        not one."""
        try:
            return fmu_state.decode(payload)
        except ValueError as exc:
            self._error(f"fmi2DeSerializeFMUstate: refused: {exc}")
            return None

    def _internal_state(self) -> dict[str, Any]:
        """What the instance keeps besides its variables (JSON-safe); adapters extend it."""
        return {}

    def _restore_internal(self, internal: dict[str, Any]) -> str | None:
        """Check ``internal`` (the variables of the state are already written) and apply it only
        if every check passes: why it is refused, or None. The base has nothing to restore."""
        return None if not internal else f"unexpected internal state {sorted(internal)}"


class LawSlave(DcsSlave):
    """A controller FMU: a law object stepped once per doStep, parameters checked at
    initialization and, when tunable ones change, before the next step.

    Subclasses set ``TUNABLE`` / ``FIXED`` (parameter names: attributes of the instance, or
    entries of ``self.param_values`` for parameters registered with getter and setter on it)
    and implement :meth:`_params_from_variables` (validated parameters from the
    variables; ValueError naming the bad one), :meth:`_make_law` (a law of those parameters:
    it has ``params`` (settable, keeps the state), ``get_state()`` / ``set_state(array)``) and
    :meth:`_step_law` (one step: read ``self.inputs``, write ``self.outputs``; ValueError for bad
    inputs). The rules (the status protocol of :class:`DcsSlave`):

    * invalid parameters at ``fmi2ExitInitializationMode``: fmi2Error naming them; the instance
      stays in initialization mode (no doStep) until corrected parameters initialize it;
    * a fixed parameter set after initialization: fmi2Error from that set call, nothing set;
    * an invalid tunable parameter, a bad input: fmi2Error from that doStep, state unchanged;
    * FMU state: the registered variables plus the law's state; after initialization a state's
      parameters must pass the checks of initialization (they reach the law at the next doStep);
    * compiled step (the wrapper's accelerator, ``fmu_src/wrapper``): the law's, made at the
      first request after initialization (where numba is loaded in the process by then: the
      hosts instantiate every FMU, the plant's import loads it, before they initialize any),
      offered while the instance is initialized and its parameters are the ones last
      validated; a parameter
      set through FMI makes the next doStep run in Python, which validates and applies it, and
      the compiled step is offered again after it. A step the compiled law leaves to Python (a
      refused input, a new lag decay) runs :meth:`do_step`: the same status and message.
    """

    TUNABLE: ClassVar[tuple[str, ...]] = ()
    FIXED: ClassVar[tuple[str, ...]] = ()
    #: The vendored ``controller`` package of the adapter: its compiled entry points get their
    #: addresses from its native image when there is one (``native.provide``).
    LAW_PACKAGE: ClassVar[ModuleType | None] = None

    def __init__(self, **kwargs: Any) -> None:
        super().__init__(**kwargs)
        self._initialized = False
        self._init_error: str | None = None  # invalid parameters at initialization
        self._fixed_values: tuple[Any, ...] = ()
        self._tunable_values: tuple[Any, ...] | None = None
        #: values of parameters that are not attributes (e.g. generated names), by name
        self.param_values: dict[str, Any] = {}
        self._law: Any = None
        self._step: Any = None  # the compiled step of self._step_law_obj (None: none)
        self._step_law_obj: Any = None

    # ------------------------------------------------------------ for subclasses
    def _params_from_variables(self) -> Any:  # pragma: no cover - each adapter has its own
        raise NotImplementedError

    def _make_law(self, params: Any) -> Any:  # pragma: no cover
        raise NotImplementedError

    def _step_law(self, t: float, h: float) -> None:  # pragma: no cover
        raise NotImplementedError

    def _value(self, name: str) -> Any:
        """The current value of parameter ``name`` (an entry of ``param_values``, else the
        attribute)."""
        values = self.param_values
        return values[name] if name in values else getattr(self, name)

    def _snapshot(self, names: tuple[str, ...]) -> tuple[Any, ...]:
        return tuple(self._value(n) for n in names)

    # ---------------------------------------------------------------- FMI calls
    def exit_initialization_mode(self) -> None:
        try:
            params = self._params_from_variables()
        except ValueError as exc:
            self._init_error = f"invalid parameter: {exc}"
            self._initialized = False
            self._error(f"fmi2ExitInitializationMode: {self._init_error}; correct the "
                        f"parameters and call it again (or reset)")
            return
        self._init_error = None
        self._law = self._make_law(params)
        self._fixed_values = self._snapshot(self.FIXED)
        self._tunable_values = self._snapshot(self.TUNABLE)
        self._initialized = True

    def do_step(self, current_time: float, step_size: float) -> None:
        if self._init_error is not None:
            return self._error(f"step rejected: {self._init_error}")
        if not self._initialized:
            return self._error("doStep called before initialization "
                               "(fmi2ExitInitializationMode); step rejected")
        if self._snapshot(self.FIXED) != self._fixed_values:
            return self._error(f"fixed parameters {self.FIXED} changed after initialization; "
                               f"step rejected")
        tunable = self._snapshot(self.TUNABLE)
        if tunable != self._tunable_values:
            try:
                self._law.params = self._params_from_variables()  # keeps the law's state
            except ValueError as exc:
                return self._error(f"invalid parameter: {exc}; step rejected")
            self._tunable_values = tunable
        try:
            self._step_law(current_time, step_size)
        except ValueError as exc:
            return self._error(f"at t = {current_time!r}: {exc}; step rejected")
        return None

    # ---------------------------------------------------------- compiled step
    def _fmi2_compiled_step(self) -> tuple[int, int] | None:
        """The law's compiled step for the wrapper, or None (see the class docstring)."""
        if (not self._initialized or self._init_error is not None
                or self._snapshot(self.FIXED) != self._fixed_values
                or self._snapshot(self.TUNABLE) != self._tunable_values):
            return None
        if self._step_law_obj is not self._law:  # once per law (per initialization)
            self._step_law_obj = self._law
            self._provide_entries()
            self._step = self._law.compiled_step(self.inputs, self.outputs)
        step = self._step
        if step is None:
            return None
        step.refresh()  # the law's parameters may have been replaced
        return step.function, step.context

    def _provide_entries(self) -> None:
        """Where the law would get a compiled step (numba loaded, compiled steps on), give the
        package's entry points their addresses first (once per process: ``native.provide``)."""
        package = self.LAW_PACKAGE
        if package is None or "numba" not in sys.modules:
            return
        if importlib.import_module(f"{package.__name__}.acceleration").enabled():
            provide(package, importlib.import_module(f"{package.__name__}.compiled"))

    def _fmi2_compiled_step_failed(self, code: int, t: float, h: float) -> None:
        """A step the compiled law left to Python (nothing changed): :meth:`do_step`. An
        internal failure raises (fmi2Error with its traceback)."""
        self._step.check(code, t, h)
        return self.do_step(t, h)

    # ------------------------------------------------------------- FMU state
    def _fixed_parameters_locked(self) -> bool:
        return self._initialized

    def _internal_state(self) -> dict[str, Any]:
        return {"law": self._law.get_state().tolist()}

    def _restore_internal(self, internal: dict[str, Any]) -> str | None:
        law = internal.get("law")
        if set(internal) != {"law"} or not isinstance(law, list):
            return f"not a state of this FMU (internal part {sorted(internal)})"
        problem = fmu_state.numbers_problem("its law state", law)
        shape = self._law.get_state().shape
        if problem is None and len(law) != shape[0]:
            problem = f"its law state has {len(law)} values; this law has {shape[0]}"
        if problem is not None:
            return problem
        fixed, tunable = self._snapshot(self.FIXED), self._snapshot(self.TUNABLE)
        changed = (fixed, tunable) != (self._fixed_values, self._tunable_values)
        if self._initialized and changed:  # checked as fmi2ExitInitializationMode checks them
            try:
                self._params_from_variables()
            except ValueError as exc:
                return f"invalid parameter: {exc}"
        # every check passed: apply. Parameters other than the law's reach it at the next
        # doStep, in Python (as a tunable one set through FMI does)
        if self._initialized and changed:
            self._fixed_values, self._tunable_values = fixed, None
        self._law.set_state(np.array(law, dtype=float))
        return None
