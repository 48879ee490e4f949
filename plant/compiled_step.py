"""The plant's compiled step: one communication step of :class:`plant.simulator.PlantSimulator`
as a C function, called without the GIL and without entering Python.

:func:`plant_step` (a numba ``@cfunc``, ``int32 step(void *context, double t, double h)``) does
what ``PlantSimulator.do_step`` + ``outputs()`` do for a fixed-step method, bit for bit:

1. take the inputs from an input buffer (``u[in_index[j]] = inputs[j]``);
2. refuse, with the state unchanged, a step size that is not finite and > 0, a time that is
   not the simulator's own, a non-finite input, a step of more than ``MAX_SUBSTEPS`` internal
   steps (:data:`REFUSED`);
3. integrate over ``[t, t + h]``, split at the load switch times (breakpoints), with the
   simulator's method and internal step;
4. compute the outputs at the new time (into the model's scratch) and check the state
   (:func:`plant.guards.check_state`, reusing the output kernel's rotation matrices): a
   violation is :data:`DIVERGED` with the guard's code, index and value in the report array;
5. else put the outputs into an output buffer (``outputs[j] = out[out_index[j]]``).

It returns :data:`FALLBACK` (nothing changed but the inputs taken) when a step needs Python: an
exponential integrator's operator for another step size, or the automatic method choice for a
new communication step (``PlantSimulator`` picks per step size). :class:`CompiledStep` turns
every code into the :class:`plant.simulator.StepResult` Python would have given (the Python
``do_step`` for a fallback, the simulator's own refusal and divergence messages otherwise).

The context is one int64 array: per array ``(address, d0, d1, d2)`` (``_SLOTS``); the cfunc
views each array in place with ``numba.carray``. The arrays are the simulator's own (time, state,
inputs, parameters, scratch): state save/restore (``get_state`` / ``set_state``, which write in
place) sees and changes what the compiled step integrates. Both the plant FMU (through the C
wrapper, ``fmu_src/wrapper``) and the in-process plant slave (through ctypes) call this one
function. ``DRILLCOSIM_COMPILED_STEP=0`` switches it off (:func:`enabled`): every step then runs
``PlantSimulator.do_step`` in Python, the reference.
"""

from __future__ import annotations

import ctypes
import math
import os
from collections.abc import Mapping
from typing import Any

import numpy as np
from numba import carray, cfunc, njit, types
from numba.core import cgutils
from numba.extending import intrinsic

from .guards import OK as GUARD_OK
from .guards import check_state
from .integrators import (
    KERNEL_ERK,
    KERNEL_ETD2,
    KERNEL_EXPEULER,
    KERNEL_RK4,
    KERNEL_VERLET,
    advance_erk,
    advance_etd2,
    advance_expeuler,
    advance_rk4_span,
    advance_verlet,
    next_breakpoint,
)
from .kernels import MODEL_FULL3D
from .observables import outputs3d, outputs_at
from .step_result import StepResult

__all__ = ["DIVERGED", "ENTRIES", "FALLBACK", "INTERNAL", "OK", "REFUSED", "CompiledStep",
           "addresses", "cfuncs", "enabled", "plant_outputs", "plant_step", "use_addresses"]

#: Return codes of :func:`plant_step`.
OK = 0
FALLBACK = 1  # run this step in Python (nothing changed but the inputs taken)
REFUSED = 2  # bad step size, time, input or too many internal steps: state unchanged
DIVERGED = 3  # the state left its range: the report holds (guard code, index, value)
INTERNAL = 9  # an exception inside the compiled code (a bug): the state may be partly advanced

ENV = "DRILLCOSIM_COMPILED_STEP"

# Settings (float64) of the context.
S_MAX_STEP, S_ZBIT_REF, S_VERLET_LAMBDA = 0, 1, 2
S_MAX_LATERAL, S_MAX_TILT, S_MAX_SPEED, S_MAX_STRAIN = 3, 4, 5, 6
S_OP_DT, S_AUTO_H, S_MAX_SUBSTEPS = 7, 8, 9
N_SETTINGS = 10
# Meta (int64) of the context.
M_MODEL, M_KERNEL, M_AUTO = 0, 1, 2
N_META = 3

# The arrays of the context, in slot order (name, dtype).
_SLOTS: tuple[tuple[str, type], ...] = (
    ("meta", np.int64), ("settings", np.float64), ("clock", np.float64), ("y", np.float64),
    ("p", np.float64), ("ip", np.int64), ("fp", np.float64), ("u", np.float64),
    ("wR", np.float64), ("wF", np.float64), ("wM", np.float64), ("work", np.float64),
    ("breakpoints", np.float64), ("inputs", np.float64), ("in_index", np.int64),
    ("outputs", np.float64), ("out_index", np.int64), ("out", np.float64),
    ("report", np.float64), ("tab_a", np.float64), ("tab_b", np.float64),
    ("tab_c", np.float64), ("op_idx", np.int64), ("op_sizes", np.int64),
    ("op_blocks", np.float64), ("P1", np.float64), ("P2", np.float64), ("Q", np.float64),
    ("op_ramp", np.float64),
)
_SLOT = {name: k for k, (name, _dtype) in enumerate(_SLOTS)}
_WIDTH = 4  # address, d0, d1, d2


def enabled() -> bool:
    """Whether compiled steps are on: ``$DRILLCOSIM_COMPILED_STEP`` is not ``0`` (default on)."""
    return os.environ.get(ENV, "1").strip() != "0"


# ------------------------------------------------------------------------------ the kernel
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
def _i1(c, k):
    return carray(_pointer(c[_WIDTH * k]), c[_WIDTH * k + 1], dtype=np.int64)


@njit(cache=True, inline="always")
def _f2(c, k):
    return carray(_pointer(c[_WIDTH * k]), (c[_WIDTH * k + 1], c[_WIDTH * k + 2]),
                  dtype=np.float64)


@njit(cache=True, inline="always")
def _i2(c, k):
    return carray(_pointer(c[_WIDTH * k]), (c[_WIDTH * k + 1], c[_WIDTH * k + 2]),
                  dtype=np.int64)


@njit(cache=True, inline="always")
def _f3(c, k):
    return carray(_pointer(c[_WIDTH * k]),
                  (c[_WIDTH * k + 1], c[_WIDTH * k + 2], c[_WIDTH * k + 3]), dtype=np.float64)


@njit(cache=True)
def _segments_need_operator(t, h, max_step, breakpoints, op_dt):
    """Whether a segment of the step ``[t, t + h]`` has an internal step other than ``op_dt``."""
    t_start = t
    t1 = t + h
    while t < t1:
        te = next_breakpoint(t, t1, breakpoints)
        length = h if (t == t_start and te == t1) else te - t
        n_sub = max(1, math.ceil(length / max_step - 1e-9))
        if length / n_sub != op_dt:
            return True
        t = te
    return False


@njit(cache=True)
def step_core(t, h, meta, settings, clock, y, p, ip, fp, u, wR, wF, wM, work, breakpoints,
              inputs, in_index, outputs, out_index, out, report, tab_a, tab_b, tab_c,
              expeuler_op, etd2_op):
    """One step of ``PlantSimulator.do_step`` (see the module docstring); returns a code.

    ``expeuler_op``: the exponential Euler operator ``(op_idx, op_sizes, op_blocks, op_ramp)``
    (``DrillstringModel.expeuler_operator``); ``etd2_op``: ``(P1, P2, Q)``.
    """
    for j in range(in_index.size):
        u[in_index[j]] = inputs[j]
    if not (h > 0.0 and math.isfinite(h)):
        return REFUSED
    model = meta[M_MODEL]
    kernel = meta[M_KERNEL]
    if meta[M_AUTO] != 0 and h != settings[S_AUTO_H]:
        return FALLBACK  # the automatic method for this step size is chosen in Python
    time = clock[0]
    if not (math.isfinite(t) and abs(t - time) <= 1e-9 * max(1.0, abs(t))):
        return REFUSED
    for j in range(u.size):
        if not math.isfinite(u[j]):
            return REFUSED
    max_step = settings[S_MAX_STEP]
    if h / max_step > settings[S_MAX_SUBSTEPS]:  # ceil(h / max_step) > MAX_SUBSTEPS
        return REFUSED
    k1 = work[0]
    k2 = work[1]
    k3 = work[2]
    k4 = work[3]
    yt = work[4]
    if kernel == KERNEL_RK4:
        clock[0] = advance_rk4_span(model, t, t + h, max_step, breakpoints, y, p, ip, fp, u,
                                    wR, wF, wM, k1, k2, k3, k4, yt)
    else:
        if (kernel == KERNEL_EXPEULER or kernel == KERNEL_ETD2) and _segments_need_operator(
                t, h, max_step, breakpoints, settings[S_OP_DT]):
            return FALLBACK
        half = y.size // 2
        t_start = t
        t1 = t + h
        while t < t1:  # segments between the load switch times, as PlantSimulator.do_step
            te = next_breakpoint(t, t1, breakpoints)
            length = h if (t == t_start and te == t1) else te - t
            n_sub = max(1, math.ceil(length / max_step - 1e-9))
            dt = length / n_sub
            if kernel == KERNEL_ERK:
                done = advance_erk(model, t, y, n_sub, dt, tab_a, tab_b, tab_c, work[:4], yt, p,
                                   ip, fp, u, wR, wF, wM)
            elif kernel == KERNEL_VERLET:
                done = advance_verlet(model, t, y, n_sub, dt, settings[S_VERLET_LAMBDA], p, ip,
                                      fp, u, wR, wF, wM, k1, k2, k3[:half], k4[:half])
            elif kernel == KERNEL_EXPEULER:
                op_idx, op_sizes, op_blocks, op_ramp = expeuler_op
                done = advance_expeuler(model, t, y, n_sub, dt, op_idx, op_sizes, op_blocks,
                                        op_ramp, p, ip, fp, u, wR, wF, wM, k1, k2)
            else:
                P1, P2, Q = etd2_op
                done = advance_etd2(model, t, y, n_sub, dt, P1, P2, Q, p, ip, fp, u, wR, wF,
                                    wM, k1, k2, k3)
            clock[0] = te if done == n_sub else t + done * dt
            if done < n_sub:
                break
            t = te
    full3d = model == MODEL_FULL3D
    # the outputs first (into the model's scratch): the 3D output kernel leaves the bodies'
    # rotation matrices in wR, which the check then reuses (the same cardan, the same bits)
    if full3d:
        outputs3d(clock[0], y, p, ip, fp, u, wR, settings[S_ZBIT_REF], out)
    else:
        outputs_at(clock[0], y, p, ip, fp, u, wR, settings[S_ZBIT_REF], out)
    code, i, val = check_state(full3d, ip[0], y, settings[S_MAX_LATERAL], settings[S_MAX_TILT],
                               settings[S_MAX_SPEED], settings[S_MAX_STRAIN], wR, p, ip, True)
    if code != GUARD_OK:
        report[0] = code
        report[1] = i
        report[2] = val
        return DIVERGED
    for j in range(out_index.size):
        outputs[j] = out[out_index[j]]
    return OK


def plant_step(context, t, h):
    """The C entry point of a step: ``context`` is the int64 slot array of :class:`CompiledStep`.

    An exception inside (a bug: nopython code raises e.g. on a division by an exact zero) is
    :data:`INTERNAL`, never a success: numba's cfunc wrapper would print it and return 0.
    """
    c = carray(context, len(_SLOTS) * _WIDTH, dtype=np.int64)
    try:
        return step_core(
            t, h, _i1(c, 0), _f1(c, 1), _f1(c, 2), _f1(c, 3), _f1(c, 4), _i1(c, 5), _f1(c, 6),
            _f1(c, 7), _f3(c, 8), _f2(c, 9), _f2(c, 10), _f2(c, 11), _f1(c, 12), _f1(c, 13),
            _i1(c, 14), _f1(c, 15), _i1(c, 16), _f1(c, 17), _f1(c, 18), _f2(c, 19),
            _f1(c, 20), _f1(c, 21), (_i2(c, 22), _i1(c, 23), _f3(c, 24), _f2(c, 28)),
            (_f2(c, 25), _f2(c, 26), _f2(c, 27)))
    except Exception:  # noqa: BLE001 - reported as INTERNAL (see the docstring)
        return INTERNAL


@njit(cache=True)
def outputs_core(meta, settings, clock, y, p, ip, fp, u, wR, outputs, out_index, out):
    """The outputs at the simulator's time, as ``PlantSimulator.outputs()`` gives them (into
    the model's scratch ``out``), put into the output buffer."""
    if meta[M_MODEL] == MODEL_FULL3D:
        outputs3d(clock[0], y, p, ip, fp, u, wR, settings[S_ZBIT_REF], out)
    else:
        outputs_at(clock[0], y, p, ip, fp, u, wR, settings[S_ZBIT_REF], out)
    for j in range(out_index.size):
        outputs[j] = out[out_index[j]]
    return OK


def plant_outputs(context, t, h):
    """The C entry point of the outputs (``t`` and ``h`` unused: the simulator's own time)."""
    c = carray(context, len(_SLOTS) * _WIDTH, dtype=np.int64)
    try:
        return outputs_core(_i1(c, 0), _f1(c, 1), _f1(c, 2), _f1(c, 3), _f1(c, 4), _i1(c, 5),
                            _f1(c, 6), _f1(c, 7), _f3(c, 8), _f1(c, 15), _i1(c, 16),
                            _f1(c, 17))
    except Exception:  # noqa: BLE001 - reported as INTERNAL
        return INTERNAL


#: The C entry points (``int32 f(void *context, double t, double h)``), in image order.
ENTRIES: tuple[str, ...] = ("plant_step", "plant_outputs")
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


# ------------------------------------------------------------------------------ Python side
class CompiledStep:
    """A :class:`PlantSimulator`'s compiled step with its input and output buffers.

    Parameters
    ----------
    sim : plant.simulator.PlantSimulator
        The simulator stepped (its method must be a fixed-step one: ``sim.compiled_step()``
        decides). Typed ``Any`` here: this module does not import the simulator, which
        imports it (one direction, no cycle).
    inputs : numpy.ndarray, shape (k,)
        Input buffer: ``sim.u[in_index[j]] = inputs[j]`` at every step.
    in_index : numpy.ndarray of int, shape (k,)
    outputs : numpy.ndarray, shape (m,)
        Output buffer: ``outputs[j] = model output out_index[j]`` after every step.
    out_index : numpy.ndarray of int, shape (m,)

    Attributes
    ----------
    function : int
        Address of :func:`plant_step` (:func:`addresses`).
    context : int
        Address of the slot array (valid while this object lives and :meth:`refresh` has not
        rebuilt it).
    """

    def __init__(self, sim: Any, inputs: np.ndarray, in_index: np.ndarray,
                 outputs: np.ndarray, out_index: np.ndarray) -> None:
        self.sim = sim
        self._io = (inputs, np.ascontiguousarray(in_index, dtype=np.int64), outputs,
                    np.ascontiguousarray(out_index, dtype=np.int64))
        for buf in (inputs, outputs):
            if buf.dtype != np.float64 or not buf.flags.c_contiguous or not buf.flags.writeable:
                raise ValueError("the input and output buffers must be writable C-contiguous "
                                 "float64 arrays")
        self.report = np.zeros(3)
        self._key: tuple | None = None
        entry = addresses()
        self.function = entry["plant_step"]
        self._call = _CALL(self.function)
        self._outputs_call = _CALL(entry["plant_outputs"])
        self.refresh()

    def refresh(self) -> None:
        """Rebuild the context if the simulator's method, internal step or operator changed."""
        sim = self.sim
        key = sim.compiled_key()
        if key == self._key:
            return
        m = sim.model
        meta = np.zeros(3, dtype=np.int64)
        method = sim.method_spec
        meta[M_MODEL] = m.model_id
        meta[M_KERNEL] = method.kernel
        meta[M_AUTO] = int(sim.automatic)
        settings = np.zeros(N_SETTINGS)
        limits = sim.limits()
        settings[S_MAX_STEP] = sim.max_step
        settings[S_ZBIT_REF] = m._zbit_ref
        settings[S_VERLET_LAMBDA] = m.verlet_lambda
        settings[S_MAX_LATERAL:S_MAX_STRAIN + 1] = limits
        settings[S_OP_DT] = math.nan
        settings[S_AUTO_H] = sim.automatic_step
        settings[S_MAX_SUBSTEPS] = sim.max_substeps
        empty_i2 = np.zeros((0, 0), dtype=np.int64)
        empty_f2 = np.zeros((0, 0))
        tab = method.tableau or (empty_f2, np.zeros(0), np.zeros(0))
        op_idx, op_sizes, op_blocks = empty_i2, np.zeros(0, dtype=np.int64), np.zeros((0, 0, 0))
        op_ramp = empty_f2
        P1 = P2 = Q = empty_f2
        if sim.operator_dt is not None:
            settings[S_OP_DT] = sim.operator_dt
            if method.kernel == KERNEL_EXPEULER:
                op_idx, op_sizes, op_blocks, op_ramp = m.expeuler_operator(sim.operator_dt)
            else:
                P1, P2, Q = m.exponential_matrices(sim.operator_dt)
        inputs, in_index, outputs, out_index = self._io
        arrays = {
            "meta": meta, "settings": settings, "clock": sim.clock, "y": sim.y, "p": m.p,
            "ip": m.ip, "fp": m.fp, "u": sim.u, "wR": m.wR, "wF": m.wF, "wM": m.wM,
            "work": m.work, "breakpoints": m.breakpoints, "inputs": inputs,
            "in_index": in_index, "outputs": outputs, "out_index": out_index, "out": m._out,
            "report": self.report, "tab_a": tab[0], "tab_b": tab[1], "tab_c": tab[2],
            "op_idx": op_idx, "op_sizes": op_sizes, "op_blocks": op_blocks, "P1": P1,
            "P2": P2, "Q": Q, "op_ramp": op_ramp,
        }
        ctx = np.zeros(len(_SLOTS) * _WIDTH, dtype=np.int64)
        for k, (name, dtype) in enumerate(_SLOTS):
            a = arrays[name]
            if a.dtype != dtype or not a.flags.c_contiguous or a.ndim > 3:
                raise TypeError(f"compiled step: array {name} must be C-contiguous {dtype}")
            ctx[_WIDTH * k] = a.ctypes.data
            ctx[_WIDTH * k + 1:_WIDTH * k + 1 + a.ndim] = a.shape
        self._arrays = arrays  # kept alive with the context
        self._ctx = ctx
        self.context = ctx.ctypes.data
        self._key = key

    def write_outputs(self) -> None:
        """Put the outputs at the simulator's time into the output buffer (compiled: what
        ``sim.outputs().take(out_index, out=outputs)`` does, bit for bit)."""
        self.refresh()
        code = self._outputs_call(self.context, 0.0, 0.0)
        if code != OK:
            raise RuntimeError(f"the compiled plant outputs raised an exception inside their "
                               f"compiled code at t = {self.sim.time!r} s; run with "
                               f"DRILLCOSIM_COMPILED_STEP=0 to see it in Python")

    def step(self, t: float, h: float) -> StepResult:
        """One step through the compiled function (ctypes; the GIL is released)."""
        code = self._call(self.context, t, h)
        if code == OK:
            return self.sim.ok
        return self.finish(code, t, h)

    def finish(self, code: int, t: float, h: float) -> StepResult:
        """The result of a step whose compiled call returned ``code`` (not OK).

        :data:`FALLBACK`: for the automatic method's first step of a step size, the method is
        chosen for it (``PlantSimulator.refusal`` does the same) and the step runs compiled;
        otherwise (an exponential operator for a new step size) it runs in Python now
        (``PlantSimulator.do_step``; outputs put into the buffer on success) and the context
        follows the simulator's new method or operator. :data:`REFUSED` / :data:`DIVERGED`:
        the simulator's own message.

        Raises
        ------
        RuntimeError
            :data:`INTERNAL` (an exception inside the compiled code: an internal error, the
            state may be partly advanced; the Python step, ``DRILLCOSIM_COMPILED_STEP=0``,
            names the exception), or a code this module does not know.
        """
        sim = self.sim
        if code == FALLBACK and sim.automatic and h != sim.automatic_step and h > 0.0 \
                and math.isfinite(h):
            sim.choose_method(h)
            self.refresh()
            code = self._call(self.context, t, h)
            if code == OK:
                return sim.ok
        if code == FALLBACK:
            res = sim.do_step(t, h)
            if res.ok:
                inputs, in_index, outputs, out_index = self._io
                sim.outputs().take(out_index, out=outputs)
            self.refresh()
            return res
        if code == REFUSED:
            res = sim.refusal(t, h)
            if res is None:
                raise RuntimeError(f"compiled plant step refused t = {t!r}, h = {h!r}, but the "
                                   f"Python checks accept it")
            return res
        if code == DIVERGED:
            guard, i, val = self.report
            return sim.report(int(guard), int(i), float(val))
        if code == INTERNAL:
            raise RuntimeError(f"the compiled plant step raised an exception inside its compiled "
                               f"code at t = {t!r} s, h = {h!r} s (the state may be partly "
                               f"advanced); run with DRILLCOSIM_COMPILED_STEP=0 to see it in "
                               f"Python")
        raise RuntimeError(f"compiled plant step returned the unknown code {code}")
