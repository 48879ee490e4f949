"""The Butterworth high-pass of the sweep's growth fit, without importing ``scipy.signal`` in
every worker.

``scipy.signal`` costs ~1.4 s of CPU to import (it imports ``scipy.stats``, ``scipy.interpolate``
and more): most of a sweep worker's start-up (BENCHMARKS.md). Its filter design
(:func:`scipy.signal.butter`) is a pure function of the order and the cut-off: its second-order
sections are kept on disk by content (:func:`cosim.scenario.cache.cached_arrays`: computed, and
``scipy.signal`` imported, once per machine and scipy version). Its filter
(:func:`scipy.signal.sosfilt`: cascaded biquads in transposed direct form II, zero initial state)
is the loop of ``highpass.c``, operation for operation, so both give the same numbers bit for
bit (tests/test_prediction.py checks it against scipy). The C file is compiled at first use into
the user cache (:func:`drillcosim._toolchain.compile_shared`, named by a hash of its source and
flags, like the master's native loop); without a C compiler ``scipy.signal.sosfilt`` runs.
"""

from __future__ import annotations

import ctypes
import hashlib
import os
import tempfile
from pathlib import Path

import numpy as np

from drillcosim._toolchain import CFLAGS, compile_shared, user_cache
from drillcosim.cosim.scenario.cache import cached_arrays

__all__ = ["butter_highpass", "sosfilt"]

SOURCE = Path(__file__).resolve().with_name("highpass.c")
FLAGS = ("-ffp-contract=off",)     # no fused multiply-add: rounds as scipy's loop
_F64P = ctypes.POINTER(ctypes.c_double)
_library: list = []                # [ctypes function or None], once per process


def butter_highpass(order: int, cutoff: float) -> np.ndarray:
    """``scipy.signal.butter(order, cutoff, "highpass", output="sos")``, cached.

    Parameters
    ----------
    order : int
    cutoff : float
        Cut-off over the Nyquist frequency, in (0, 1).

    Returns
    -------
    numpy.ndarray, shape (ceil(order / 2), 6)
    """
    def design() -> dict[str, np.ndarray]:
        from scipy.signal import butter

        return {"sos": butter(order, cutoff, "highpass", output="sos")}

    return cached_arrays("filters", {"butter": int(order), "cutoff": repr(float(cutoff)),
                                     "btype": "highpass"}, design)["sos"]


def _compiled():
    """``dcs_sosfilt`` of the compiled ``highpass.c`` (built at first use), or None."""
    if not _library:
        digest = hashlib.sha256(SOURCE.read_bytes())
        digest.update("\0".join((*CFLAGS, *FLAGS, os.environ.get("CC") or "gcc")).encode())
        path = user_cache() / "study" / f"dcs_sosfilt-{digest.hexdigest()[:16]}.so"
        func = None
        try:
            if not path.is_file():
                path.parent.mkdir(parents=True, exist_ok=True)
                fd, tmp = tempfile.mkstemp(prefix=".dcs_sosfilt-", suffix=".so",
                                           dir=path.parent)
                os.close(fd)
                try:
                    compile_shared("the sweep's high-pass filter", [SOURCE], tmp, flags=FLAGS)
                    os.replace(tmp, path)
                finally:
                    if os.path.exists(tmp):
                        os.unlink(tmp)
            func = ctypes.CDLL(str(path)).dcs_sosfilt
            func.argtypes = (_F64P, ctypes.c_int32, _F64P, _F64P, ctypes.c_int64, _F64P)
            func.restype = None
        except (OSError, RuntimeError):
            func = None                # no compiler: scipy.signal.sosfilt
        _library.append(func)
    return _library[0]


def sosfilt(sos: np.ndarray, x: np.ndarray) -> np.ndarray:
    """``scipy.signal.sosfilt(sos, x)`` of a 1-D float signal (zero initial state).

    Parameters
    ----------
    sos : numpy.ndarray, shape (n_sections, 6)
        Second-order sections, ``a0 = 1``.
    x : numpy.ndarray, shape (n,)

    Returns
    -------
    numpy.ndarray, shape (n,)
    """
    func = _compiled()
    sos = np.ascontiguousarray(sos, dtype=np.float64)
    x = np.ascontiguousarray(x, dtype=np.float64)
    if func is None:
        from scipy.signal import sosfilt as scipy_sosfilt

        return scipy_sosfilt(sos, x)
    y = np.empty_like(x)
    zi = np.empty(2 * len(sos))
    func(sos.ctypes.data_as(_F64P), len(sos), x.ctypes.data_as(_F64P), y.ctypes.data_as(_F64P),
         len(x), zi.ctypes.data_as(_F64P))
    return y
