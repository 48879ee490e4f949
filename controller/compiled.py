"""Compiled steps of the controller laws: one step as a C function, without the GIL.

:func:`strain_step` and :func:`top_drive_step` (numba ``cfunc`` entry points, :func:`cfuncs`,
``int32 step(void *context, double t, double h)``) do what
:meth:`controller.StrainController.step` (any number of sites, SISO or gain matrix, saturation,
switch-on, lag) and :meth:`controller.TopDriveController.step`
do, bit for bit, and :func:`state_space_step` what
:meth:`controller.StateSpaceController.step` does (to rounding: its matrix-vector product is a
call of numba's BLAS, numpy's of numpy's), reading the inputs from an input buffer and writing
the outputs into an output buffer. They change nothing and return :data:`REFUSED` for a step
the Python law refuses (non-finite time, step or input; negative step; a step that is not a
whole number of the state-space law's samples) and :data:`FALLBACK` for one they leave to Python
(the lag's decay factor for a new step size, which the Python law computes and keeps); the
caller then runs the law's Python ``step``, which gives today's result or error message.

The context is an int64 array of ``(address, d0, d1)`` per array (:class:`CompiledLaw`); the
arrays are the law's own (its state, its decay cache), so state save/restore sees what the
compiled step changes. This module needs numba; the laws import it only when a compiled step is
asked for, and only where numba is loaded anyway (``acceleration.py``; the controller FMUs also
run in a Python with only numpy). ``DRILLCOSIM_COMPILED_STEP=0`` switches compiled steps off.
"""

from __future__ import annotations

import ctypes
import math
from collections.abc import Mapping
from typing import Any

import numpy as np
from numba import carray, cfunc, njit, types
from numba.core import cgutils
from numba.extending import intrinsic

__all__ = ["ENTRIES", "FALLBACK", "INTERNAL", "OK", "REFUSED", "CompiledLaw", "addresses",
           "cfuncs", "state_space_step", "strain_step", "top_drive_step", "use_addresses"]

OK = 0
FALLBACK = 1  # run this step in Python (nothing changed)
REFUSED = 2  # the Python law refuses this step (nothing changed)
INTERNAL = 9  # an exception inside the compiled code (a bug; numba's wrapper would return 0)

_WIDTH = 3  # address, d0, d1

# strain law: params (float64); the switch-on tolerance is passed in, not imported: numba's
# cache of this file would not see a change in another file
P_GAIN, P_LOWER, P_UPPER, P_SWITCH_ON, P_ENABLED, P_TAU, P_RTOL = range(7)
# top-drive law: params
T_TARGET, T_P, T_I, T_KT, T_RAMP, T_ENABLED = range(6)
# state-space law: timing (the sample period, the samples run, the tolerance of "h is a
# multiple of the sample period")
S_PERIOD, S_COUNT, S_RTOL = range(3)


@intrinsic
def _pointer(typingctx, address):
    """An int64 address as a ``void *`` (numba has no cast for it)."""
    sig = types.voidptr(types.int64)

    def codegen(context, builder, signature, args):
        return builder.inttoptr(args[0], cgutils.voidptr_t)

    return sig, codegen


@njit(cache=True, inline="always")
def _f1(c, k):
    return carray(_pointer(c[_WIDTH * k]), c[_WIDTH * k + 1], dtype=np.float64)


@njit(cache=True, inline="always")
def _f2(c, k):
    return carray(_pointer(c[_WIDTH * k]), (c[_WIDTH * k + 1], c[_WIDTH * k + 2]),
                  dtype=np.float64)


# ------------------------------------------------------------------------ strain feedback
@njit(cache=True)
def strain_core(t, dt, params, matrix, decay, force, inputs, outputs):
    """:meth:`controller.StrainController.step` on the buffers (see the module docstring)."""
    if not (math.isfinite(t) and math.isfinite(dt) and dt >= 0.0):
        return REFUSED
    nch = force.size
    for i in range(nch):
        if not math.isfinite(inputs[i]):
            return REFUSED
    tau = params[P_TAU]
    if tau != 0.0 and dt != decay[0]:
        return FALLBACK  # the Python law computes exp(-dt / tau) and keeps it in `decay`
    t_on = params[P_SWITCH_ON]
    active = params[P_ENABLED] != 0.0 and t >= t_on - params[P_RTOL] * max(1.0, abs(t_on))
    gain = params[P_GAIN]
    lower = params[P_LOWER]
    upper = params[P_UPPER]
    n = matrix.shape[0]
    for i in range(nch):
        u = 0.0
        if active:
            if n == 0:
                v = gain * inputs[i]
            else:  # site s, axis a: sum over the sites j in order, as the Python law
                s = i // 2
                a = i - 2 * s
                acc = matrix[s, 0] * inputs[a]
                for j in range(1, n):
                    acc = acc + matrix[s, j] * inputs[2 * j + a]
                v = gain * acc
            v = lower if v < lower else v  # numpy's clip keeps v when equal to a limit
            u = upper if v > upper else v
        if tau == 0.0:
            force[i] = u
        else:
            force[i] = u + (force[i] - u) * decay[1]
        outputs[i] = force[i]
    return OK


def strain_step(context, t, h):
    """C entry point of the strain law: slots params, matrix, decay, force, inputs, outputs."""
    c = carray(context, 6 * _WIDTH, dtype=np.int64)
    try:
        return strain_core(t, h, _f1(c, 0), _f2(c, 1), _f1(c, 2), _f1(c, 3), _f1(c, 4),
                           _f1(c, 5))
    except Exception:  # noqa: BLE001 - never reported as a success
        return INTERNAL


# ------------------------------------------------------------------------ top drive
@njit(cache=True)
def top_drive_core(t, dt, params, state, inputs, outputs):
    """:meth:`controller.TopDriveController.step` on the buffers (see the module docstring)."""
    if not (math.isfinite(t) and math.isfinite(dt) and dt >= 0.0):
        return REFUSED
    speed = inputs[0]
    torque = inputs[1]
    if not (math.isfinite(speed) and math.isfinite(torque)):
        return REFUSED
    if params[T_ENABLED] == 0.0:
        state[1] = 0.0
        outputs[0] = 0.0
        return OK
    ramp = params[T_RAMP]
    target = params[T_TARGET]
    if ramp == 0.0 or t >= ramp:
        reference = target
    else:
        reference = target * (0.0 if 0.0 > t else t) / ramp  # Python's max(t, 0.0)
    error = reference - speed
    x = state[0] + dt * error
    motor = params[T_P] * error + params[T_I] * x + params[T_KT] * torque
    state[0] = x
    state[1] = motor
    outputs[0] = motor
    return OK


def top_drive_step(context, t, h):
    """C entry point of the top-drive law: slots params, state, inputs, outputs."""
    c = carray(context, 4 * _WIDTH, dtype=np.int64)
    try:
        return top_drive_core(t, h, _f1(c, 0), _f1(c, 1), _f1(c, 2), _f1(c, 3))
    except Exception:  # noqa: BLE001 - never reported as a success
        return INTERNAL


# ------------------------------------------------------------------------ state space
@njit(cache=True)
def state_space_core(t, h, timing, matrix, w, scratch, lower, upper, law_outputs, inputs,
                     outputs):
    """:meth:`controller.StateSpaceController.step` on the views of its workspace: ``w = [x;
    y]`` (the state, then the inputs the law holds), ``matrix = [[C, D], [A, B]]``, one
    product per sample (``scratch = matrix w``)."""
    if not (math.isfinite(t) and math.isfinite(h) and h >= 0.0):
        return REFUSED
    ts = timing[S_PERIOD]
    k_float = h / ts
    k = int(k_float + 0.5)
    if abs(k_float - k) > timing[S_RTOL] * max(1.0, k_float):
        return REFUSED
    m = inputs.size
    p = law_outputs.size
    n = w.size - m
    for j in range(m):
        if not math.isfinite(inputs[j]):
            return REFUSED
    for j in range(m):
        w[n + j] = inputs[j]
    for _ in range(k):
        np.dot(matrix, w, scratch)                  # BLAS, no allocation
        for i in range(p):
            v = scratch[i]
            lo = lower[i]
            hi = upper[i]
            law_outputs[i] = lo if v < lo else (hi if v > hi else v)  # numpy's clip
        for i in range(n):
            w[i] = scratch[p + i]
        timing[S_COUNT] += 1.0
    for i in range(p):
        outputs[i] = law_outputs[i]
    return OK


def state_space_step(context, t, h):
    """C entry point of the state-space law: slots timing, matrix, w, scratch, lower, upper,
    law outputs, inputs, outputs."""
    c = carray(context, 9 * _WIDTH, dtype=np.int64)
    try:
        return state_space_core(t, h, _f1(c, 0), _f2(c, 1), _f1(c, 2), _f1(c, 3), _f1(c, 4),
                                _f1(c, 5), _f1(c, 6), _f1(c, 7), _f1(c, 8))
    except Exception:  # noqa: BLE001 - never reported as a success
        return INTERNAL


#: The C entry points (``int32 f(void *context, double t, double h)``), in image order.
ENTRIES: tuple[str, ...] = ("strain_step", "top_drive_step", "state_space_step")
_SIGNATURE = types.int32(types.voidptr, types.float64, types.float64)
_CFUNCS: dict[str, Any] = {}
_ADDRESSES: dict[str, int] = {}


def cfuncs() -> dict[str, Any]:
    """The entry points as numba ``cfunc`` objects (compiled, or loaded from numba's cache, at
    the first call: that sets numba up in the process)."""
    if not _CFUNCS:
        for name in ENTRIES:
            _CFUNCS[name] = cfunc(_SIGNATURE, nopython=True, cache=True)(globals()[name])
    return _CFUNCS


def use_addresses(addresses: Mapping[str, int]) -> None:
    """Take the entry points' addresses from elsewhere: a native image of this very module's
    cfuncs (``fmu_src/slave_support/native.py``), which needs no numba set-up."""
    _ADDRESSES.update({name: int(addresses[name]) for name in ENTRIES})


def addresses() -> dict[str, int]:
    """Entry point -> address of its C function (given by :func:`use_addresses`, else
    numba's)."""
    if not _ADDRESSES:
        _ADDRESSES.update({name: cf.address for name, cf in cfuncs().items()})
    return _ADDRESSES


_CALL = ctypes.CFUNCTYPE(ctypes.c_int32, ctypes.c_void_p, ctypes.c_double, ctypes.c_double)


# ------------------------------------------------------------------------ Python side
class CompiledLaw:
    """A law's compiled step with its input and output buffers.

    Parameters
    ----------
    function : int
        Address of an entry point (:func:`addresses`).
    pack : callable
        ``pack()`` -> ``(key, arrays)``: the context's arrays (float64, C-contiguous, 1-D or
        2-D) in the function's slot order, and what they depend on besides the law's arrays
        (the params object: a new one rebuilds the context, :meth:`refresh`).

    Attributes
    ----------
    function, context : int
        The C function and its context (valid while this object lives).
    """

    def __init__(self, function: int, pack: Any) -> None:
        self.function = function
        self._pack = pack
        self._key: object = None
        self._call = _CALL(function)
        self.refresh()

    def refresh(self) -> None:
        """Rebuild the context if the law's parameters changed."""
        key, arrays = self._pack()
        if key is self._key:
            return
        ctx = np.zeros(len(arrays) * _WIDTH, dtype=np.int64)
        for k, a in enumerate(arrays):
            if a.dtype != np.float64 or not a.flags.c_contiguous or a.ndim > 2:
                raise TypeError("compiled law: arrays must be C-contiguous float64, 1-D or 2-D")
            ctx[_WIDTH * k] = a.ctypes.data
            ctx[_WIDTH * k + 1:_WIDTH * k + 1 + a.ndim] = a.shape
        self._arrays = arrays  # kept alive with the context
        self._ctx = ctx
        self.context = ctx.ctypes.data
        self._key = key

    def step(self, t: float, h: float) -> int:
        """One compiled step (ctypes, GIL released); the code (:data:`OK` or not)."""
        return self._call(self.context, t, h)

    @staticmethod
    def check(code: int, t: float, h: float) -> None:
        """Before the law's Python step for a failed compiled one: ``RuntimeError`` for
        :data:`INTERNAL` (a bug; the law's state may be partly changed), else nothing."""
        if code not in (FALLBACK, REFUSED):
            raise RuntimeError(f"the compiled law step failed with code {code} at t = {t!r} s, "
                               f"h = {h!r} s (an exception inside its compiled code); run with "
                               f"DRILLCOSIM_COMPILED_STEP=0 to see it in Python")
