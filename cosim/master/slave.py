"""The slave protocol of the master, and its FMU implementation.

The master (:mod:`.execution`, :mod:`.algorithms`) drives every component of a system
through :class:`Slave`; :class:`FmuSlave` is an FMI 2.0 co-simulation FMU behind fmpy's
low-level API. Other implementations (in-process models, see
:mod:`cosim.scenario.inprocess`) are handed to :class:`~.execution.Execution` ready-made and
stepped by the same algorithms with the same exchange timing.
"""

from __future__ import annotations

import abc
import ctypes
import functools
import hashlib
import math
import shutil
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, NoReturn

from fmpy import read_model_description
from fmpy.fmi2 import FMU2Slave

from . import fmi_log
from .errors import FMI2_ERROR, FMI2_FATAL, CosimError, raise_for_status
from .system import FmuSpec, ParameterValue, _did_you_mean
from .unpack import unpack

__all__ = ["CompiledCalls", "FmiCalls", "FmuSlave", "Slave", "c_double_ptr"]

_C_DOUBLE_P = ctypes.POINTER(ctypes.c_double)
_C_UINT_P = ctypes.POINTER(ctypes.c_uint)


class Slave(abc.ABC):
    """One component of a co-simulation, as the master sees it.

    A slave must implement (the master relies on nothing else):

    1. ``name``: its instance name in the system (a :class:`~.system.FmuSpec` of that name
       gives its sample period).
    2. :meth:`check_variable` ``(name, causalities)``: raise ``ValueError`` (one line, with a
       "did you mean") unless it has a Real variable ``name`` of one of ``causalities``
       (FMI 2 causality names).
    3. :meth:`instantiate` ``(start_time, stop_time)``: be ready to step from ``start_time``
       [s], parameters applied, outputs valid; raise :class:`~.errors.CosimError` on failure.
    4. :meth:`bind` ``(outputs, y, offset, inputs, u)``, once after :meth:`instantiate`:
       from then on :meth:`read_outputs` writes output ``outputs[i]`` to ``y[offset + i]``
       and :meth:`write_inputs` takes input ``inputs[i]`` from ``u[i]`` (``y``, ``u``: the
       master's ``ctypes.c_double`` arrays, owned by the master). :meth:`bind` may replace
       the three hot methods by equivalent callables on the instance (the master looks them
       up after binding).
    5. The hot calls :meth:`write_inputs` ``()``, :meth:`do_step` ``(t, h)`` (advance from
       ``t`` by ``h`` [s] with the inputs held) and :meth:`read_outputs` ``()`` return an FMI 2
       status (0 OK, 1 Warning, 2 Discard, 3 Error, 4 Fatal) and do not raise for a failure of
       the component; the master then calls :meth:`fail`.
    6. :meth:`fail` ``(status, call, time)`` raises a :class:`~.errors.CosimError` naming the
       slave, the call, the time and the component's own message; after status Error the
       master calls nothing but :meth:`set_state` and :meth:`close`, after Fatal only
       :meth:`close`.
    7. :meth:`get_real` ``(name, time)`` and :meth:`set_value` ``(name, value, time)``: slow
       access by name (recording of unexchanged variables, manipulators).
    8. :meth:`get_state` / :meth:`set_state` / :meth:`free_state` if ``can_get_set_state``:
       save and restore the component's full state (:meth:`get_state` may be called many
       times; a state can be restored many times).
    9. :meth:`close` ``()``: release everything; idempotent; called once by the execution,
       after failures too.
    10. Optional, for the master's native loop (:mod:`.native`): :meth:`native_calls` ``()``
        returns the C entry points equivalent to the three hot calls, valid from :meth:`bind`
        until the next call of any other method of the slave (the master asks again before
        each chunk of steps): :class:`FmiCalls` (an FMU's functions) or :class:`CompiledCalls`
        (a compiled step over arrays the slave keeps alive and in place); None (the default):
        the master steps this slave in Python. A compiled step returns 0 (done) or another
        code; for that the master calls :meth:`native_step_failed` ``(code, t, h)``, which
        settles the step as the Python :meth:`do_step` would (e.g. does it in Python, or
        records the failure for :meth:`take_problem`) and returns its status: OK or Warning
        and the run goes on after that step, else the failure is reported as from
        :meth:`do_step`.

    This base class implements :meth:`fail` from :meth:`take_problem` and refuses state
    handling.
    """

    name: str
    can_get_set_state: bool = False
    #: The last call returned fmi2Error (FMI 2.0: then only reset/set state/free are allowed).
    errored: bool = False
    #: The last call returned fmi2Fatal (nothing may be called any more but close).
    dead: bool = False

    @abc.abstractmethod
    def check_variable(self, name: str, causalities: Sequence[str]) -> None:
        """Raise ``ValueError`` unless ``name`` is a Real variable of ``causalities``."""

    @abc.abstractmethod
    def instantiate(self, start_time: float, stop_time: float | None) -> None:
        """Make the component ready to step from ``start_time`` [s]."""

    @abc.abstractmethod
    def bind(self, outputs: Sequence[str], y, offset: int, inputs: Sequence[str], u) -> None:
        """Bind the exchange buffers (contract item 4)."""

    @abc.abstractmethod
    def write_inputs(self) -> int:
        """Pass the bound inputs to the component; FMI status."""

    @abc.abstractmethod
    def do_step(self, t: float, h: float) -> int:
        """Advance from ``t`` by ``h`` [s]; FMI status."""

    @abc.abstractmethod
    def read_outputs(self) -> int:
        """Write the bound outputs into the master's buffer; FMI status."""

    @abc.abstractmethod
    def get_real(self, name: str, time: float) -> float:
        """Current value of Real variable ``name`` (slow path)."""

    @abc.abstractmethod
    def set_value(self, name: str, value: ParameterValue, time: float) -> None:
        """Set variable ``name`` now (slow path; raises :class:`CosimError` on failure)."""

    @abc.abstractmethod
    def close(self) -> None:
        """Release the component (idempotent)."""

    def take_problem(self) -> str | None:
        """The component's newest problem message not reported yet (one line), or None."""
        return None

    def native_calls(self) -> FmiCalls | CompiledCalls | None:
        """C entry points of the hot calls (contract item 10); None: stepped in Python."""
        return None

    def native_step_failed(self, code: int, t: float, h: float) -> int:
        """Settle a compiled step that returned ``code``; its FMI status (item 10)."""
        raise NotImplementedError(f"{type(self).__name__} has no compiled step")

    def fail(self, status: int, call: str, time: float) -> NoReturn:
        """Record a failed status (errored on Error, dead on Fatal) and raise
        :class:`CosimError` with the component's own message."""
        if status >= FMI2_ERROR:
            self.errored = True
        if status >= FMI2_FATAL:
            self.dead = True
        raise_for_status(status, self.name, call, time, self.take_problem())
        raise CosimError(self.name, call, time, f"status {status}", status=status)

    def get_state(self, time: float) -> Any:
        """Saved component state (contract item 8)."""
        raise CosimError(self.name, "fmi2GetFMUstate", time,
                         "the component cannot save its state")

    def set_state(self, state: Any, time: float) -> None:
        """Restore a state from :meth:`get_state`."""
        raise CosimError(self.name, "fmi2SetFMUstate", time,
                         "the component cannot restore a state")

    def free_state(self, state: Any) -> None:
        """Release a state from :meth:`get_state` (errors ignored)."""
        del state   # nothing to release unless a subclass holds native resources

    def state_identity(self) -> dict[str, Any]:
        """What a serialized state of this component belongs to (JSON-ready): a checkpoint
        restores it only into a component of the same identity."""
        return {"class": type(self).__qualname__}

    def serialize_state(self, time: float) -> bytes:
        """The component's full state as bytes (:meth:`deserialize_state` restores it)."""
        raise CosimError(self.name, "fmi2SerializeFMUstate", time,
                         "the component cannot serialize its state")

    def deserialize_state(self, data: bytes, time: float) -> None:
        """Restore a state written by :meth:`serialize_state` (all of it or, raising, none)."""
        raise CosimError(self.name, "fmi2DeSerializeFMUstate", time,
                         "the component cannot restore a serialized state")

    def restore_parameters(self, changed: Mapping[str, ParameterValue], time: float) -> None:
        """Set the start values ``changed`` (those of this run that differ from the run whose
        state was restored) again after a restore; nothing here: a component that takes its
        parameters at construction already has them."""
        del changed, time


@dataclass(frozen=True)
class FmiCalls:
    """An FMU instance's hot calls as C entry points (addresses, ``int``).

    ``set_real(component, in_vrs, n, u)``, ``do_step(component, t, h, 0)`` and
    ``get_real(component, out_vrs, n, y)`` with the value references of the bound inputs and
    outputs (addresses of ``unsigned int`` arrays of the bound lengths, kept alive by the slave).
    """

    component: int
    set_real: int
    do_step: int
    get_real: int
    in_vrs: int
    out_vrs: int


@dataclass(frozen=True)
class CompiledCalls:
    """A compiled step ``int step(void *context, double t, double h)`` (0: OK) and its arrays.

    Bound input ``i`` is written to ``inputs[input_slots[i]]`` before the step; bound output
    ``i`` is read from ``outputs[output_slots[i]]`` after it (``inputs``, ``outputs``: addresses
    of float64 arrays the slave keeps alive and in place, contract item 10).
    """

    step: int
    context: int
    inputs: int
    input_slots: tuple[int, ...]
    outputs: int
    output_slots: tuple[int, ...]


def _vr_array(vrs: Sequence[int]):
    arr = (ctypes.c_uint * max(1, len(vrs)))(*vrs)
    return arr, ctypes.cast(arr, _C_UINT_P)


def _address_of(dll, name: str) -> int:
    """Address of the exported function ``name`` of a loaded library."""
    return ctypes.cast(getattr(dll, name), ctypes.c_void_p).value


def c_double_ptr(buf, offset: int = 0):
    """Pointer to element ``offset`` of a ctypes double array (no copy)."""
    return ctypes.cast(ctypes.addressof(buf) + 8 * offset, _C_DOUBLE_P)


class FmuSlave(Slave):
    """An FMI 2.0 co-simulation FMU instance (fmpy's low-level API).

    The model description is read once and value references cached; the hot calls go to the
    shared library's ``fmi2SetReal`` / ``fmi2DoStep`` / ``fmi2GetReal`` with preallocated
    buffers (one call per direction for all bound variables). The FMU logs through
    :mod:`.fmi_log` (logging on); an error carries its newest problem message.

    Parameters
    ----------
    spec : FmuSpec
        Instance name, path, parameters.
    unzip_dir : str, optional
        Where the FMU was already unpacked (shared between instances of one file); unpacked
        by :func:`.unpack.unpack` otherwise.
    """

    def __init__(self, spec: FmuSpec, unzip_dir: str | None = None):
        self.spec = spec
        self.name = spec.name
        path = Path(spec.path)
        if not path.is_file():
            raise CosimError(spec.name, "load", math.nan, f"no FMU file at '{path}'")
        self.model_description = md = read_model_description(str(path))
        if md.coSimulation is None:
            raise CosimError(spec.name, "load", math.nan, "the FMU has no co-simulation interface")
        self._own_dir = False
        if unzip_dir is None:
            unzip_dir, self._own_dir = unpack(path)
        self.unzip_dir = unzip_dir
        self.variables = {v.name: v for v in md.modelVariables}
        self.can_get_set_state = bool(md.coSimulation.canGetAndSetFMUstate)
        self.fmu = FMU2Slave(guid=md.guid, unzipDirectory=self.unzip_dir,
                             modelIdentifier=md.coSimulation.modelIdentifier,
                             instanceName=spec.name)
        dll = self.fmu.dll
        self.c_do_step = dll.fmi2DoStep
        self.c_get_real = dll.fmi2GetReal
        self.c_set_real = dll.fmi2SetReal
        self.log = fmi_log.LogBook(spec.name)
        self.component = None
        self.instantiated = False
        #: fmi2ExitInitializationMode succeeded (fmi2Terminate is allowed only then)
        self.initialized = False
        self._bound: tuple = ()
        self._native: FmiCalls | None = None
        self._identity: dict[str, Any] | None = None

    # -- variables -------------------------------------------------------------
    def variable(self, name: str, causality: Sequence[str] | None = None):
        """Model variable ``name``; ``ValueError`` (with suggestion) if unknown."""
        var = self.variables.get(name)
        if var is None:
            raise ValueError(f"FMU '{self.name}' has no variable '{name}'"
                             f"{_did_you_mean(name, list(self.variables))}")
        if causality is not None and var.causality not in causality:
            raise ValueError(f"'{self.name}.{name}' has causality '{var.causality}', "
                             f"expected one of {tuple(causality)}")
        return var

    def check_variable(self, name: str, causalities: Sequence[str]) -> None:
        """``ValueError`` unless ``name`` is a Real variable of one of ``causalities``."""
        self.variable(name, causalities)
        self.real_vrs([name])

    def real_vrs(self, names: Sequence[str]) -> list[int]:
        """Value references of Real variables ``names``."""
        vrs = []
        for n in names:
            var = self.variable(n)
            if var.type != "Real":
                raise ValueError(f"'{self.name}.{n}' is of type {var.type}; only Real "
                                 f"variables can be connected or recorded")
            vrs.append(var.valueReference)
        return vrs

    # -- life cycle ------------------------------------------------------------
    def instantiate(self, start_time: float, stop_time: float | None) -> None:
        """Instantiate (logging on), set parameters and enter/exit initialisation mode."""
        fmu = self.fmu
        fmi_log.claim()
        fmu.instantiate(callbacks=self.log.callbacks, loggingOn=True)
        self.instantiated = True
        self.initialized = self.errored = False
        self.log.take_problem()
        self.component = fmu.component
        self._call("fmi2SetupExperiment", start_time,
                   lambda: fmu.fmi2SetupExperiment(self.component, 0, 0.0, start_time,
                                                   stop_time is not None, stop_time or 0.0))
        for name, value in self.spec.parameters.items():
            self.set_value(name, value, start_time)
        self._call("fmi2EnterInitializationMode", start_time,
                   lambda: fmu.fmi2EnterInitializationMode(self.component))
        self._call("fmi2ExitInitializationMode", start_time,
                   lambda: fmu.fmi2ExitInitializationMode(self.component))
        self.initialized = True

    def bind(self, outputs: Sequence[str], y, offset: int, inputs: Sequence[str], u) -> None:
        """Precompute the value-reference arrays and buffer pointers of the hot calls."""
        out_vrs, out_p = _vr_array(self.real_vrs(outputs))
        in_vrs, in_p = _vr_array(self.real_vrs(inputs))
        self._bound = (out_vrs, in_vrs, y, u)           # keep the buffers alive
        comp = self.component
        address = functools.partial(_address_of, self.fmu.dll)
        self._native = FmiCalls(comp or 0, address("fmi2SetReal"), address("fmi2DoStep"),
                                address("fmi2GetReal"), ctypes.addressof(in_vrs),
                                ctypes.addressof(out_vrs))
        n_out, n_in = len(outputs), len(inputs)
        y_p = c_double_ptr(y, offset)
        self._step = (self.c_do_step, comp)
        # the hot calls become the library functions with their arguments bound (no Python
        # frame per call)
        if n_out:
            self.read_outputs = functools.partial(self.c_get_real, comp, out_p, n_out, y_p)
        if n_in:
            self.write_inputs = functools.partial(self.c_set_real, comp, in_p, n_in, u)

    def write_inputs(self) -> int:
        """``fmi2SetReal`` of all bound inputs (nothing bound: nothing to do)."""
        return 0

    def native_calls(self) -> FmiCalls | None:
        """The library's ``fmi2SetReal`` / ``fmi2DoStep`` / ``fmi2GetReal`` (after :meth:`bind`)."""
        return self._native if self._bound and not (self.errored or self.dead) else None

    def do_step(self, t: float, h: float) -> int:
        """``fmi2DoStep(t, h, noSetFMUStatePriorToCurrentPoint = false)``."""
        s = self._step
        return s[0](s[1], t, h, 0)

    def read_outputs(self) -> int:
        """``fmi2GetReal`` of all bound outputs (nothing bound: nothing to do)."""
        return 0

    def take_problem(self) -> str | None:
        """The newest Discard/Error/Fatal message the FMU logged and nobody reported yet."""
        return self.log.take_problem()

    def set_value(self, name: str, value: ParameterValue, time: float) -> None:
        """Set a variable by name with the setter matching its FMI type."""
        fmu = self.fmu
        var = self.variable(name)
        vr, _ = _vr_array([var.valueReference])
        if var.type == "Real":
            call, buf = "fmi2SetReal", (ctypes.c_double * 1)(float(value))
            fn = fmu.fmi2SetReal
        elif var.type in ("Integer", "Enumeration"):
            call, buf = "fmi2SetInteger", (ctypes.c_int * 1)(int(value))
            fn = fmu.fmi2SetInteger
        elif var.type == "Boolean":
            call, buf = "fmi2SetBoolean", (ctypes.c_int * 1)(int(bool(value)))
            fn = fmu.fmi2SetBoolean
        else:
            call, buf = "fmi2SetString", (ctypes.c_char_p * 1)(str(value).encode())
            fn = fmu.fmi2SetString
        self._call(f"{call}({name})", time, lambda: fn(self.component, vr, 1, buf))

    def get_real(self, name: str, time: float) -> float:
        """``fmi2GetReal`` of one variable (slow path)."""
        arr, _ = _vr_array(self.real_vrs([name]))
        out = (ctypes.c_double * 1)()
        self._call("fmi2GetReal", time, lambda: self.c_get_real(self.component, arr, 1, out))
        return out[0]

    def get_state(self, time: float):
        """FMU state handle (``fmi2GetFMUstate``); free with :meth:`free_state`."""
        if not self.can_get_set_state:
            raise CosimError(self.name, "fmi2GetFMUstate", time,
                             "the FMU does not declare canGetAndSetFMUstate")
        state = ctypes.c_void_p()
        self._call("fmi2GetFMUstate", time,
                   lambda: self.fmu.fmi2GetFMUstate(self.component, ctypes.byref(state)))
        return state

    def set_state(self, state, time: float) -> None:
        """Restore a state from :meth:`get_state` (``fmi2SetFMUstate``)."""
        self._call("fmi2SetFMUstate", time,
                   lambda: self.fmu.fmi2SetFMUstate(self.component, state))
        self.errored = False

    def state_identity(self) -> dict[str, Any]:
        """The model identifier, GUID and SHA-256 of the FMU file (computed once)."""
        if self._identity is None:
            md = self.model_description
            digest = hashlib.sha256(Path(self.spec.path).read_bytes()).hexdigest()
            self._identity = {"model": md.coSimulation.modelIdentifier, "guid": md.guid,
                              "fmu_sha256": digest}
        return self._identity

    def serialize_state(self, time: float) -> bytes:
        """``fmi2GetFMUstate`` then ``fmi2SerializeFMUstate`` (the FMU's own format)."""
        state = self.get_state(time)
        try:
            out: list[bytes] = []
            self._call("fmi2SerializeFMUstate", time,
                       lambda: out.append(bytes(self.fmu.serializeFMUstate(state))))
            return out[0]
        finally:
            self.free_state(state)

    def deserialize_state(self, data: bytes, time: float) -> None:
        """``fmi2DeSerializeFMUstate`` then ``fmi2SetFMUstate`` (the FMU checks the bytes)."""
        if not self.can_get_set_state:
            raise CosimError(self.name, "fmi2DeSerializeFMUstate", time,
                             "the FMU does not declare canGetAndSetFMUstate")
        box: list = []
        self._call("fmi2DeSerializeFMUstate", time,
                   lambda: box.append(self.fmu.deSerializeFMUstate(bytes(data))))
        try:
            self.set_state(box[0], time)
        finally:
            self.free_state(box[0])

    def restore_parameters(self, changed: Mapping[str, ParameterValue], time: float) -> None:
        """``fmi2SetXxx`` of each changed start value (the FMU refuses a fixed one)."""
        for name, value in changed.items():
            self.set_value(name, value, time)

    def free_state(self, state) -> None:
        """Release a state handle (errors ignored)."""
        if self.instantiated and not self.dead:
            try:
                self.fmu.fmi2FreeFMUstate(self.component, ctypes.byref(state))
            except Exception:  # noqa: BLE001 - cleanup must not mask the real error
                pass

    def close(self, terminate: bool = True) -> None:
        """Terminate and free the instance, then delete the extracted files it owns.

        After ``fmi2Fatal`` nothing is called on the instance any more. ``fmi2Terminate``
        is called only after a successful initialization and not after ``fmi2Error``
        (FMI 2.0's state machine: then only ``fmi2FreeInstance``).
        """
        if self.instantiated and not self.dead:
            try:
                if terminate and self.initialized and not self.errored:
                    self.fmu.fmi2Terminate(self.component)
            except Exception:  # noqa: BLE001
                pass
            try:
                self.fmu.freeInstance()
            except Exception:  # noqa: BLE001
                pass
        self.instantiated = self.initialized = False
        self._bound = ()
        self.__dict__.pop("read_outputs", None)
        self.__dict__.pop("write_inputs", None)
        if self._own_dir:
            shutil.rmtree(self.unzip_dir, ignore_errors=True)

    # -- helpers ---------------------------------------------------------------
    def _call(self, call: str, time: float, fn) -> None:
        try:
            status = fn()
        except CosimError:
            raise
        except Exception as exc:  # fmpy raises FMICallException on bad status
            status = getattr(exc, "status", None)
            if status is None:
                raise CosimError(self.name, call, time, str(exc)) from exc
        if status is not None and status > 1:
            self.fail(status, call, time)
