"""The compiled steps of the controller laws: one step as a C function, without the GIL.

Every registered law with a compiled core (``controller/law.py``, rule 4; ``COMPILED = (core,
array dimensions)``) gets a C entry point here, ``int32 step(void *context, double t, double
h)`` (a numba ``cfunc``, :func:`cfuncs`): it unpacks the context into the law's arrays and
calls the core, which does what the law's Python step does, bit for bit (the state-space law
to rounding: its matrix-vector product is a call of numba's BLAS, numpy's of numpy's), reading
the inputs from an input buffer and writing the outputs into an output buffer. A core changes
nothing and returns :data:`REFUSED` for a step the Python law refuses (non-finite time, step or
input; negative step; a step that is not a whole number of the state-space law's samples) and
:data:`FALLBACK` for one it leaves to Python (e.g. the lag's decay factor for a new step size,
which the Python law computes and keeps); the caller then runs the law's Python step, which
gives the same result or error message.

The context is an int64 array of ``(address, d0, d1)`` per array (:class:`CompiledLaw`); the
arrays are the law's own (its state, its decay cache), so state save/restore sees what the
compiled step changes. The entry point of a law is made from a template at the first request
(:func:`cfuncs`), named ``<kind>_step_<hash of this package's sources>`` so that numba's cache
of it (kept beside this file, keyed on this file only) is never one of an older core. This
module needs numba; the laws import it only when a compiled step is asked for, and only where
numba is loaded anyway (``acceleration.py``; the controller FMUs also run in a Python with only
numpy). ``DRILLCOSIM_COMPILED_STEP=0`` switches compiled steps off.
"""

from __future__ import annotations

import ctypes
import hashlib
import sys
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np
from numba import carray, cfunc, njit, types
from numba.core import cgutils
from numba.extending import intrinsic

from .acceleration import FALLBACK, INTERNAL, OK, REFUSED
from .registry import LAWS

__all__ = ["ENTRIES", "FALLBACK", "INTERNAL", "OK", "REFUSED", "CompiledLaw", "addresses",
           "cfuncs", "use_addresses"]

_WIDTH = 3  # address, d0, d1


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


# ------------------------------------------------------------------------ entry points
#: The registered laws with a compiled core, by kind (= the entry point's name).
_CORES = {law.KIND: law for law in LAWS if law.COMPILED is not None}
#: The C entry points (``int32 f(void *context, double t, double h)``), in image order.
ENTRIES: tuple[str, ...] = tuple(_CORES)

_TEMPLATE = """
def {name}(context, t, h):
    c = carray(context, {count} * _WIDTH, dtype=np.int64)
    try:
        return core(t, h, {arrays})
    except Exception:  # never reported as a success
        return INTERNAL
"""


def _sources_key() -> str:
    """12 hex digits of SHA-256 over this package's sources (names and bytes)."""
    digest = hashlib.sha256()
    for src in sorted(Path(__file__).resolve().parent.glob("*.py")):
        digest.update(src.name.encode() + b"\0" + src.read_bytes() + b"\0")
    return digest.hexdigest()[:12]


def _entry(kind: str, key: str) -> Any:
    """The Python function of ``kind``'s entry point: the template with the law's arrays,
    compiled under this file's name (numba's cache locates it here) and a name unique to the
    package's sources."""
    law = _CORES[kind]
    core_name, dims = law.COMPILED
    core = njit(getattr(sys.modules[law.__module__], core_name))
    name = f"{kind}_step_{key}"
    arrays = ", ".join(f"_f{d}(c, {k})" for k, d in enumerate(dims))
    namespace = {"__name__": __name__, "carray": carray, "np": np, "_WIDTH": _WIDTH,
                 "_f1": _f1, "_f2": _f2, "core": core, "INTERNAL": INTERNAL}
    # blank lines ahead put the function's lines where the template's text is in this file, so
    # inspect.getsource reads the template (numba does, for the type annotations it writes with
    # its cache; elsewhere in this file Python 3.12's tokenizer stops with a TokenError)
    source = "\n" * _template_offset() + _TEMPLATE.format(name=name, count=len(dims),
                                                         arrays=arrays)
    exec(compile(source, __file__, "exec"), namespace)
    return namespace[name]


def _template_offset() -> int:
    """The lines of this file before the template's first line (its ``_TEMPLATE`` line)."""
    lines = Path(__file__).read_text(encoding="utf-8").splitlines()
    return lines.index('_TEMPLATE = """')


_SIGNATURE = types.int32(types.voidptr, types.float64, types.float64)
_CFUNCS: dict[str, Any] = {}
_ADDRESSES: dict[str, int] = {}


def cfuncs() -> dict[str, Any]:
    """The entry points as numba ``cfunc`` objects (compiled, or loaded from numba's cache, at
    the first call: that sets numba up in the process)."""
    if not _CFUNCS:
        key = _sources_key()
        for kind in ENTRIES:
            _CFUNCS[kind] = cfunc(_SIGNATURE, nopython=True, cache=True)(_entry(kind, key))
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
