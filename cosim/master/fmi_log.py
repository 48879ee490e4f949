"""FMU log messages through the FMI logger callback.

Every FMU instance the master creates gets its own ``fmi2CallbackFunctions`` whose
``componentEnvironment`` identifies its :class:`LogBook`; the FMU's ``logger`` calls arrive
here with that environment and are kept in the book (the newest :data:`KEEP` messages) and
passed to Python's :mod:`logging` (logger ``drillcosim.cosim.master.fmi_log``, level from the
status: OK -> DEBUG, Warning/Discard -> WARNING, Error -> ERROR, Fatal -> CRITICAL). Nothing is
printed: an error raised by the master carries the FMU's own message
(:meth:`LogBook.take_problem`), nothing scrapes stdout.

fmpy formats the variadic message in native code (``fmpy.logging.addLoggerProxy``), whose
target is ONE global of the process: the last ``addLoggerProxy`` call wins for every FMU.
:func:`claim` points it at this module's router (the master does so before it instantiates an
FMU and before it steps). Messages of FMUs that are not the master's (another environment) are
printed as fmpy's own logger prints them, so code that relies on fmpy's default keeps working.
The router's ctypes callback lives as long as the process.
"""

from __future__ import annotations

import ctypes
import itertools
import logging
import weakref
from collections import deque

import fmpy
from fmpy.fmi2 import (
    fmi2CallbackAllocateMemoryTYPE,
    fmi2CallbackFreeMemoryTYPE,
    fmi2CallbackFunctions,
    fmi2CallbackLoggerTYPE,
)
from fmpy.logging import addLoggerProxy

__all__ = ["KEEP", "LogBook", "claim", "one_line"]

#: Messages kept per instance.
KEEP = 200
_LABELS = ("OK", "WARNING", "DISCARD", "ERROR", "FATAL", "PENDING")
_LEVELS = (logging.DEBUG, logging.WARNING, logging.WARNING, logging.ERROR, logging.CRITICAL,
           logging.INFO)
_TRACEBACK = "Traceback (most recent call last):"
_log = logging.getLogger(__name__)
_log.addHandler(logging.NullHandler())
_books: weakref.WeakValueDictionary[int, LogBook] = weakref.WeakValueDictionary()
_ids = itertools.count(1)


def one_line(text: str) -> str:
    """A message on one line; a Python traceback becomes its head and its last line."""
    if _TRACEBACK in text:
        head, _, tail = text.partition(_TRACEBACK)
        last = [ln.strip() for ln in tail.splitlines() if ln.strip() and not ln.startswith(" ")]
        text = head + (last[-1] if last else "")
    return " ".join(text.split())


def _route(env, instance, status, category, message) -> None:
    text = (message or b"").decode("utf-8", errors="replace")
    book = _books.get(env or 0)
    if book is None:   # an FMU of someone else, on fmpy's default callbacks: as fmpy prints it
        label = _LABELS[status] if 0 <= status < len(_LABELS) else str(status)
        print(f"[{label}] {text}")
        return
    book.add(int(status), (category or b"").decode("utf-8", errors="replace"), text)


_ROUTER = fmi2CallbackLoggerTYPE(_route)
_CLAIM = fmi2CallbackFunctions()


def claim() -> None:
    """Point fmpy's global logger proxy at this module's router (cheap; call before FMI work)."""
    _CLAIM.logger = _ROUTER       # addLoggerProxy takes the target from a non-proxy logger
    addLoggerProxy(ctypes.byref(_CLAIM))


class LogBook:
    """The log of one FMU instance, and the callbacks to instantiate it with.

    Parameters
    ----------
    name : str
        Instance name (for Python logging).

    Attributes
    ----------
    callbacks : fmi2CallbackFunctions
        Pass ``ctypes.byref(book.callbacks)`` to ``fmi2Instantiate``; keep the book alive
        while the instance lives.
    messages : collections.deque of (status, category, text)
        The newest :data:`KEEP` messages.
    """

    def __init__(self, name: str):
        self.name = name
        self.messages: deque[tuple[int, str, str]] = deque(maxlen=KEEP)
        self._problem: str | None = None
        self.env = next(_ids)
        _books[self.env] = self
        cb = self.callbacks = fmi2CallbackFunctions()
        cb.logger = _ROUTER
        cb.allocateMemory = fmi2CallbackAllocateMemoryTYPE(fmpy.calloc)
        cb.freeMemory = fmi2CallbackFreeMemoryTYPE(fmpy.free)
        cb.componentEnvironment = ctypes.c_void_p(self.env)
        addLoggerProxy(ctypes.byref(cb))     # cb.logger becomes the native proxy

    def add(self, status: int, category: str, text: str) -> None:
        """Keep a message (and the newest problem: status Discard or worse)."""
        self.messages.append((status, category, text))
        if status >= 2:
            self._problem = one_line(text)
        level = _LEVELS[status] if 0 <= status < len(_LEVELS) else logging.ERROR
        if _log.isEnabledFor(level):
            _log.log(level, "%s [%s] %s", self.name, category, text)

    def take_problem(self) -> str | None:
        """The newest problem message not taken yet (one line), or None."""
        problem, self._problem = self._problem, None
        return problem
