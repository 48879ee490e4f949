"""Shared test fixtures."""

from __future__ import annotations

import ctypes

import pytest
from fmpy.fmi1 import printLogMessage
from fmpy.fmi2 import fmi2CallbackFunctions, fmi2CallbackLoggerTYPE
from fmpy.logging import addLoggerProxy

# fmpy's native logger proxy (logging.so) keeps ONE global target for every FMU in the process:
# the last addLoggerProxy() call wins. Tests that install a recording logger re-point it at their
# own ctypes callback; once that callback is garbage-collected, the next FMU that logs jumps into
# freed memory (a segfault or heap corruption in a later, unrelated test). After every test the
# target goes back to fmpy's printing logger, through a callback kept alive for the whole session.
_DEFAULT = fmi2CallbackFunctions()
_DEFAULT.logger = fmi2CallbackLoggerTYPE(printLogMessage)
_KEEP = _DEFAULT.logger


@pytest.fixture(autouse=True)
def _restore_fmpy_logger_proxy():
    yield
    cb = fmi2CallbackFunctions()
    cb.logger = _KEEP
    addLoggerProxy(ctypes.byref(cb))
