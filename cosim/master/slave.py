"""One FMU instance driven through fmpy's low-level FMI 2 API.

:class:`Slave` loads the model description once, caches value references,
and exposes the raw ctypes FMI functions (``fmi2DoStep``, ``fmi2GetReal``,
``fmi2SetReal``) together with preallocated C buffers, so the algorithms' hot
loops call the shared library directly: no list conversion, no dict lookup,
no Python object creation per call. Status codes are returned to the caller,
which hands any status worse than ``fmi2Warning`` to
:func:`cosim.master.errors.raise_for_status`.
"""

from __future__ import annotations

import ctypes
import math
import shutil
from collections.abc import Sequence
from pathlib import Path

from fmpy import extract, read_model_description
from fmpy.fmi2 import FMU2Slave

from .errors import FMI2_ERROR, FMI2_FATAL, CosimError, raise_for_status
from .system import FmuSpec, ParameterValue, _did_you_mean

_C_DOUBLE_P = ctypes.POINTER(ctypes.c_double)
_C_UINT_P = ctypes.POINTER(ctypes.c_uint)


def _vr_array(vrs: Sequence[int]):
    arr = (ctypes.c_uint * max(1, len(vrs)))(*vrs)
    return arr, ctypes.cast(arr, _C_UINT_P)


class Slave:
    """An instantiated FMI 2 co-simulation FMU.

    Parameters
    ----------
    spec : FmuSpec
        Instance name, path, parameters and sample period.
    unzip_dir : str, optional
        Where the FMU was already extracted (shared between instances of one
        file); extracted to a temporary folder owned by this object otherwise.
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
        self._own_dir = unzip_dir is None
        self.unzip_dir = unzip_dir or extract(str(path))
        self.variables = {v.name: v for v in md.modelVariables}
        self.can_get_set_state = bool(md.coSimulation.canGetAndSetFMUstate)
        self.fmu = FMU2Slave(guid=md.guid, unzipDirectory=self.unzip_dir,
                             modelIdentifier=md.coSimulation.modelIdentifier,
                             instanceName=spec.name)
        dll = self.fmu.dll
        self.c_do_step = dll.fmi2DoStep
        self.c_get_real = dll.fmi2GetReal
        self.c_set_real = dll.fmi2SetReal
        self.component = None
        self.dead = False
        self.instantiated = False
        #: fmi2ExitInitializationMode succeeded (fmi2Terminate is allowed only then)
        self.initialized = False
        #: a call returned fmi2Error: FMI 2.0 then allows only fmi2FreeInstance,
        #: fmi2Reset or fmi2SetFMUstate (a successful one clears the flag)
        self.errored = False

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
        """Instantiate, set parameters and enter/exit initialisation mode."""
        fmu = self.fmu
        fmu.instantiate()
        self.instantiated = True
        self.initialized = self.errored = False
        self.component = fmu.component
        self._call("fmi2SetupExperiment", start_time,
                   lambda: fmu.fmi2SetupExperiment(self.component, 0, 0.0, start_time,
                                                   stop_time is not None, stop_time or 0.0))
        self.set_values(self.spec.parameters, start_time)
        self._call("fmi2EnterInitializationMode", start_time,
                   lambda: fmu.fmi2EnterInitializationMode(self.component))
        self._call("fmi2ExitInitializationMode", start_time,
                   lambda: fmu.fmi2ExitInitializationMode(self.component))
        self.initialized = True

    def set_values(self, values: dict[str, ParameterValue], time: float) -> None:
        """Set variables by name with the setter matching their FMI type."""
        fmu = self.fmu
        for name, value in values.items():
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
            self._call(f"{call}({name})", time,
                       lambda fn=fn, vr=vr, buf=buf: fn(self.component, vr, 1, buf))

    def get_reals(self, vrs: Sequence[int], time: float) -> list[float]:
        """Read Real variables by value reference (slow path, not for hot loops)."""
        arr, _ = _vr_array(vrs)
        out = (ctypes.c_double * max(1, len(vrs)))()
        self._call("fmi2GetReal", time, lambda: self.c_get_real(self.component, arr,
                                                                len(vrs), out))
        return list(out[: len(vrs)])

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
        if self._own_dir:
            shutil.rmtree(self.unzip_dir, ignore_errors=True)

    # -- helpers ---------------------------------------------------------------
    def fail(self, status: int, call: str, time: float) -> None:
        """Record a failed status (errored on fmi2Error, dead on fmi2Fatal) and raise."""
        if status >= FMI2_ERROR:
            self.errored = True
        if status >= FMI2_FATAL:
            self.dead = True
        raise_for_status(status, self.name, call, time)

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


def c_double_ptr(buf, offset: int = 0):
    """Pointer to element ``offset`` of a ctypes double array (no copy)."""
    return ctypes.cast(ctypes.addressof(buf) + 8 * offset, _C_DOUBLE_P)


def vr_pointer(vrs: Sequence[int]):
    """``(array, pointer)`` of a C ``unsigned int`` array holding ``vrs``."""
    return _vr_array(vrs)
