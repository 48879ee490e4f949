"""Native FMI 2.0 co-simulation wrapper (C) for pythonfmu ``Fmi2Slave`` classes.

pythonfmu 0.7.0's prebuilt C++ wrapper can return only fmi2OK, fmi2Discard
(``do_step`` returned False) and fmi2Fatal (any Python exception, after which it
releases the instance's Python objects twice). ``dcs_fmi2_native.c`` beside this
file replaces ``binaries/linux64/<modelIdentifier>.so`` of a pythonfmu-built FMU
(``python -m drillcosim.fmu_src.build``: the default, ``--wrapper native``); the rest of the
FMU (script, ``resources/``, modelDescription.xml) is unchanged. It is compiled on the build
machine against the running Python's headers and records the path of its libpython
and executable; the FMU therefore runs with this machine's Python (the same
requirement as the pythonfmu build, which ships no interpreter either).

Status convention (what a slave method's outcome becomes)
---------------------------------------------------------
=====================================  =============================================
Python outcome                         FMI status
=====================================  =============================================
exception                              fmi2Error; the formatted traceback is logged
                                       (category ``logStatusError``); the instance
                                       stays usable and can be freed safely
returns None or True                   fmi2OK
returns False                          ``do_step``: fmi2Discard; other methods:
                                       fmi2Error
returns an int 0..4 (not a bool),      that status (``Fmi2Status.error`` -> fmi2Error)
e.g. ``Fmi2Status.error``
``do_step`` returns anything else      truthy -> fmi2OK, falsy -> fmi2Discard
                                       (pythonfmu's rule)
=====================================  =============================================

After every call (get/set included) the wrapper reads ``slave._fmi2_status``: if it
is an int above the status found so far, it becomes the status; the wrapper then
resets it to None (opt-in: the attribute must exist right after the slave is
constructed, e.g. ``self._fmi2_status = None`` in ``__init__``; otherwise it is never
read, which saves a failed attribute lookup per call). This lets a ``get_real`` that
meets an unknown value reference, or a ``do_step`` that must keep returning a bool for
pythonfmu, report fmi2Error. Right
after constructing the slave the wrapper sets ``slave._fmi2_wrapper = "native"``,
so an adapter can tell which wrapper runs it (pythonfmu never sets it).

Do not return an int from ``do_step`` for pythonfmu-wrapped FMUs: pythonfmu maps
the return value through truthiness, so ``Fmi2Status.ok`` (0) would be a discard and
``Fmi2Status.error`` (3) would be OK. Use ``_fmi2_status`` instead.

fmi2Fatal is returned only when Python itself is unusable (it cannot be loaded or
initialised, or an exception cannot even be formatted).

Other behaviour
---------------
* ``fmi2Instantiate`` imports the module named in ``resources/slavemodule.txt`` with
  ``resources/`` first on ``sys.path`` during the import only (the module is
  imported once per process and cached in ``sys.modules``, unlike pythonfmu
  0.7.0, which re-executes it at every instantiation), takes the class named in
  ``resources/slaveclass.txt`` (default: the modelIdentifier) and calls it with
  ``instance_name``, ``resources`` and ``visible`` keyword arguments. Failure:
  NULL and the traceback logged.
* Messages of ``slave.log()`` are drained after every call; status != OK messages
  are always passed to the logger, OK messages only with debug logging on (and the
  category enabled by ``fmi2SetDebugLogging``, no categories = all).
* The FMI state machine is checked: ``fmi2DoStep`` before
  ``fmi2ExitInitializationMode`` or after ``fmi2Terminate``, initialization calls out
  of order: fmi2Error and a message; calls on NULL/freed components: fmi2Error.
* ``fmi2Reset``: ``slave.reset()`` if it exists, else a new slave object replaces the
  old one (as pythonfmu does).
* FMU state: the object of ``slave._get_fmu_state()`` is held by the C state (freed
  by ``fmi2FreeFMUstate``); serialisation through ``_fmu_state_to_bytes`` /
  ``_fmu_state_from_bytes``.
* Strings of ``fmi2GetString`` stay valid until the next ``fmi2GetString`` call on
  the instance (or its release).
* Unsupported FMI 2.0 features: directional derivatives, input/output derivatives and
  ``fmi2CancelStep`` return fmi2Error; ``fmi2Get*Status`` returns fmi2Discard except
  ``fmi2GetRealStatus(fmi2LastSuccessfulTime)`` (the end of the last successful step).
* Host without Python (a C/C++ tool): libpython (recorded at build time, override
  with ``$DRILLCOSIM_LIBPYTHON``) is loaded with ``RTLD_GLOBAL`` and initialised
  with the recorded executable as program name (override ``$DRILLCOSIM_PYTHON``; a
  venv is honoured), then the GIL is released. The interpreter is never finalised.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import sysconfig
import zipfile
from pathlib import Path

__all__ = ["SOURCE", "compile_wrapper", "install_native_wrapper", "libpython_path"]

#: The C source of the wrapper.
SOURCE = Path(__file__).resolve().parent / "dcs_fmi2_native.c"
CFLAGS = ("-std=c99", "-O2", "-Wall", "-Wextra", "-Werror", "-shared", "-fPIC",
          "-fvisibility=hidden")


def libpython_path() -> str:
    """Path of the running Python's shared libpython (LIBDIR/INSTSONAME or LDLIBRARY).

    Raises
    ------
    RuntimeError
        If this Python has no shared libpython (built without --enable-shared).
    """
    libdir = sysconfig.get_config_var("LIBDIR") or ""
    for key in ("INSTSONAME", "LDLIBRARY"):
        name = sysconfig.get_config_var(key) or ""
        path = Path(libdir) / name
        if name.endswith((".so", ".dylib")) or ".so." in name:
            if path.is_file():
                return str(path)
    raise RuntimeError(f"Python {sys.version.split()[0]} at {sys.executable} has no shared "
                       f"libpython in {libdir!r}: the native wrapper needs one")


def compile_wrapper(out: Path | str, cc: str | None = None) -> Path:
    """Compile the wrapper for the running Python into the shared library ``out``.

    Parameters
    ----------
    out : path-like
        Target ``.so`` (its name is irrelevant; FMUs copy it to ``<id>.so``).
    cc : str, optional
        C compiler (default ``$CC`` or ``gcc``).

    Returns
    -------
    pathlib.Path
        ``out``.

    Raises
    ------
    RuntimeError
        If the compiler fails or prints a warning (its output is included).
    """
    out = Path(out)
    cc = cc or os.environ.get("CC") or "gcc"
    if shutil.which(cc) is None:
        raise RuntimeError(f"C compiler {cc!r} not found: the native wrapper needs one")
    include = sysconfig.get_paths()["include"]
    defines = [f"-DDCS_LIBPYTHON=\"{libpython_path()}\"",
               f"-DDCS_PYTHON_EXE=\"{sys.executable}\""]
    cmd = [cc, *CFLAGS, f"-I{include}", *defines, str(SOURCE), "-o", str(out),
           "-ldl", "-lpthread"]
    proc = subprocess.run(cmd, capture_output=True, text=True)
    if proc.returncode != 0 or proc.stderr.strip():
        raise RuntimeError(f"compiling the native wrapper failed:\n{' '.join(cmd)}\n"
                           f"{proc.stdout}{proc.stderr}")
    return out


def install_native_wrapper(fmu: Path | str, class_name: str, library: Path | str) -> None:
    """Replace the linux64 binary of a pythonfmu-built FMU by the native wrapper.

    Also writes ``resources/slaveclass.txt`` (the class the wrapper instantiates).
    The ``win64`` binary, if any, stays pythonfmu's.

    Parameters
    ----------
    fmu : path-like
        The ``.fmu`` (rewritten in place).
    class_name : str
        The ``Fmi2Slave`` subclass in the slave module.
    library : path-like
        Output of :func:`compile_wrapper`.
    """
    fmu = Path(fmu)
    tmp = fmu.with_suffix(".native.tmp")
    with zipfile.ZipFile(fmu) as src:
        md = src.read("modelDescription.xml").decode()
        ident = md.split('modelIdentifier="', 1)[1].split('"', 1)[0]
        member = f"binaries/linux64/{ident}.so"
        with zipfile.ZipFile(tmp, "w", zipfile.ZIP_DEFLATED) as dst:
            for info in src.infolist():
                if info.filename in (member, "resources/slaveclass.txt"):
                    continue
                dst.writestr(info, src.read(info.filename), compress_type=zipfile.ZIP_DEFLATED)
            dst.write(library, member)
            dst.writestr("resources/slaveclass.txt", class_name + "\n")
    os.replace(tmp, fmu)
