"""Callback functions whose logger records the FMU's messages (used by the FMU tests).

fmpy formats the variadic log message in native code (``fmpy.logging.addLoggerProxy``), whose
target is ONE global per process: keep a :class:`RecordingCallbacks` alive while its FMUs may
log. ``tests/conftest.py`` points the proxy back to fmpy's printing logger after every test.
"""

from __future__ import annotations

import ctypes

import fmpy
from fmpy.fmi2 import (
    fmi2CallbackAllocateMemoryTYPE,
    fmi2CallbackFreeMemoryTYPE,
    fmi2CallbackFunctions,
    fmi2CallbackLoggerTYPE,
)
from fmpy.logging import addLoggerProxy


class RecordingCallbacks:
    """``fmi2CallbackFunctions`` for ``FMU2Slave.instantiate(callbacks=...)``.

    Parameters
    ----------
    keep_last : int, optional
        Keep only this many messages (long fuzz campaigns).

    Attributes
    ----------
    callbacks : fmi2CallbackFunctions
    messages : list of (status, message)
    """

    def __init__(self, keep_last: int | None = None) -> None:
        self.messages: list[tuple[int, str]] = []
        self._keep_last = keep_last
        self.callbacks = fmi2CallbackFunctions()
        self.callbacks.logger = fmi2CallbackLoggerTYPE(self._log)
        self.callbacks.allocateMemory = fmi2CallbackAllocateMemoryTYPE(fmpy.calloc)
        self.callbacks.freeMemory = fmi2CallbackFreeMemoryTYPE(fmpy.free)
        addLoggerProxy(ctypes.byref(self.callbacks))

    def _log(self, env, instance, status, category, message) -> None:
        self.messages.append((int(status), message.decode(errors="replace")))
        if self._keep_last is not None:
            del self.messages[:-self._keep_last]
