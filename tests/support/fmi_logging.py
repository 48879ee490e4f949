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


class RecordingInstance:
    """An fmpy ``FMU2Slave``, instantiated with logging on and its messages recorded.

    Parameters
    ----------
    md : fmpy ModelDescription
    unzipdir : str
        Extracted FMU.
    prefix : str
        Instance names are ``<prefix><count>``.
    """

    _count = 0

    def __init__(self, md, unzipdir: str, prefix: str) -> None:
        from fmpy.fmi2 import FMU2Slave

        RecordingInstance._count += 1
        self._recording = RecordingCallbacks()
        self.messages = self._recording.messages
        self._callbacks = self._recording.callbacks
        self.fmu = FMU2Slave(guid=md.guid, unzipDirectory=unzipdir,
                             modelIdentifier=md.coSimulation.modelIdentifier,
                             instanceName=f"{prefix}{RecordingInstance._count}")
        self.fmu.instantiate(callbacks=self._callbacks, loggingOn=True)

    def text(self) -> str:
        """All recorded messages, one a line."""
        return "\n".join(m for _, m in self.messages)


def fmu_fixtures(spec):
    """Session fixtures ``fmu_path``, ``md``, ``vr``, ``unzipdir`` for one FMU of the registry.

    ``fmu_path`` is the shared session build of ``conftest.project_fmus``.

    Assign them to module names of the same name in a test module.
    """
    import pytest
    from fmpy import extract, read_model_description

    @pytest.fixture(scope="session", name="fmu_path")
    def fmu_path(project_fmus):
        return project_fmus[spec.name]

    @pytest.fixture(scope="session", name="md")
    def md(fmu_path):
        return read_model_description(str(fmu_path))

    @pytest.fixture(scope="session", name="vr")
    def vr(md):
        return {v.name: v.valueReference for v in md.modelVariables}

    @pytest.fixture(scope="session", name="unzipdir")
    def unzipdir(fmu_path, tmp_path_factory):
        return extract(str(fmu_path), unzipdir=str(tmp_path_factory.mktemp("unzipped")))

    return fmu_path, md, vr, unzipdir
