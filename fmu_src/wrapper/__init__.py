"""Native FMI 2.0 co-simulation wrapper (C) for pythonfmu ``Fmi2Slave`` classes.

The C sources beside this file (one job per file, see ``dcs_wrapper.h``) replace pythonfmu
0.7.0's prebuilt C++ binary, which can return only fmi2OK, fmi2Discard and fmi2Fatal, needs
libpython preloaded in a C host, and releases an instance's Python objects twice after an
exception. The build (``python -m drillcosim.fmu_src.build``) compiles them against the running
Python's headers with ``Py_LIMITED_API`` = 3.10 into ``binaries/linux64/<modelIdentifier>.so``
and, cross-compiled with mingw-w64, ``binaries/win64/<modelIdentifier>.dll``
(:mod:`drillcosim.fmu_src.platforms`): per platform one binary for CPython 3.10 to 3.13
(:func:`python_range`), every C-API function looked up at run time (``dlsym`` /
``GetProcAddress``), no structure whose layout differs per version; the rest of the FMU (slave
module, ``resources/``, modelDescription.xml) is pythonfmu's. The FMI 2.0 declarations come
from the official headers in ``fmi2/`` (BSD 2-Clause, see ``fmi2/LICENSE.txt``).

Which Python runs the slave
---------------------------
* In a Python host (fmpy, libcosimpy) the running interpreter; it must be CPython 3.10 to 3.13
  (else fmi2Instantiate fails with one message saying so).
* In a host without Python (a C/C++ tool), at fmi2Instantiate, the first that fits of:
  ``$DRILLCOSIM_PYTHON``; a config file ``drillcosim.conf`` with a line
  ``python = /path/to/python3``, in the FMU's unzip folder, then in
  ``$XDG_CONFIG_HOME/drillcosim/`` (``~/.config/drillcosim/``); on ``PATH``, folder by folder:
  ``python3``, ``python3.<building minor>``, then ``python3.13`` down to ``python3.10``; last,
  the interpreter that built the FMU. Each is checked in a child process (``python -E -X utf8``:
  version, shared libpython, ``import`` of the modules listed in
  ``resources/python_requires.txt``). None fits: fmi2Instantiate returns NULL with ONE message
  listing each candidate and what it lacked, and how to fix it. The chosen libpython is loaded
  and started through the stable ABI with the environment ignored (``Py_IgnoreEnvironmentFlag``),
  so a host's ``PYTHONHOME``/``PYTHONPATH`` change nothing, no signal handlers, and the host's
  ``LC_CTYPE`` restored after the start (``dcs_python.c``, ``dcs_discover.c``;
  ``docs/interop.md``). On Windows the same order with Windows' names
  (``%APPDATA%\\drillcosim\\drillcosim.conf``; ``python.exe``, ``python3.exe``, ``python3.X.exe`` on
  ``PATH``), then the Pythons CPython's installer registered (PEP 514), and no building
  interpreter (the win64 binary is cross-built). What the operating system is asked is one file
  per platform behind ``dcs_platform.h``. ``drillcosim doctor`` runs the same search without starting anything
  (the exported ``drillcosim_doctor``; :mod:`.doctor`).

The status protocol (what a slave method's outcome becomes)
-----------------------------------------------------------
=====================================  =============================================
Python outcome                         FMI status
=====================================  =============================================
exception                              fmi2Error; the formatted traceback is logged
                                       (category ``logStatusError``); the instance
                                       stays usable and can be freed safely
returns None or True                   fmi2OK
returns False                          ``do_step``: fmi2Discard; other methods:
                                       fmi2Error
returns an int 0..4 (not a bool)       that status
``do_step`` returns anything else      truthy -> fmi2OK, falsy -> fmi2Discard
=====================================  =============================================

After every call (get/set included) the wrapper reads ``slave._fmi2_status``: if it is an int
above the status found so far, it becomes the status; the wrapper then resets it to None.
Opt-in: the attribute must exist right after the slave is constructed (our adapters get it from
:class:`fmu_src.slave_support.DcsSlave`, which sets it through ``_error``). fmi2Fatal is returned
only when Python itself is unusable (an exception that cannot even be formatted).

Real buffers (the fast boundary)
--------------------------------
A slave that defines ``_fmi2_real_buffers()`` returns ``(input_vrs, inputs, output_vrs,
outputs)``: two float64 numpy arrays (C-contiguous, writable, one value per value reference)
that hold those Real variables for the slave's lifetime. The wrapper keeps a buffer view of
each; in step mode ``fmi2GetReal`` of those value references reads them and ``fmi2SetReal`` of
the inputs (also in initialization mode) writes them, without Python, and ``fmi2DoStep`` is
one Python call (none with a compiled step, below). Any other access goes through ``get_real``/``set_real``.

Compiled step (the accelerator a slave may carry)
-------------------------------------------------
A slave that defines ``_fmi2_compiled_step()`` is asked for it after construction and at the
end of every call that enters Python and may change it (all but the getters and the FMU-state
reads). It returns ``None`` (``fmi2DoStep`` calls ``do_step`` in Python) or ``(function,
context)``: the address of a C function ``int step(void *context, double t, double h)`` (a
numba ``@cfunc("int32(voidptr, float64, float64)")``) and the pointer it is given. The slave
keeps what the context points at alive and in place until its next Python call. In step mode
``fmi2DoStep`` calls ``step`` without the GIL and without entering Python; it reads the input
buffer and writes the output buffer itself. ``0`` is fmi2OK; any other code ``c`` makes the
wrapper take the GIL and call ``slave._fmi2_compiled_step_failed(c, t, h)``, whose outcome is
the step's status by the protocol above (the slave logs the message its ``do_step`` would
have), and the compiled step is taken anew. ``do_step`` in Python stays the fallback and the
reference (``tests/test_wrapper_compiled_step.py``).

Other behaviour
---------------
* ``fmi2Instantiate`` imports the module named in ``resources/slavemodule.txt`` with
  ``resources/`` first on ``sys.path`` during the import only (once per process; cached in
  ``sys.modules``), takes the class named in ``resources/slaveclass.txt`` and calls it with
  ``instance_name``, ``resources`` and ``visible``. Failure: NULL and the traceback logged.
* Messages of ``slave.log()`` are drained after every call; status != OK messages are always
  passed to the logger, OK messages only with debug logging on (and the category enabled by
  ``fmi2SetDebugLogging``, no categories = all).
* The FMI calling sequence is a state-mask table (``fmi2_functions.c``): a call in a state
  that does not allow it is fmi2Error naming the state; NULL/freed/foreign components and FMU
  states: fmi2Error (handles are looked up in registries of the live ones, ``dcs_registry.c``,
  never probed through a pointer that may be freed).
* ``fmi2Reset``: ``slave.reset()`` if it exists, else a new slave object replaces the old one.
* FMU state: the object of ``slave._get_fmu_state()`` is held by the C state with the phase
  (FMI state) it was taken in (freed by ``fmi2FreeFMUstate``); ``fmi2SetFMUstate`` refuses a
  state of another phase, else calls ``slave._set_fmu_state(obj)``. Serialized: the payload of
  ``_fmu_state_to_bytes(obj)`` sealed with the FMU's identity (the slave class = model
  identifier, ``build`` of ``resources/dcs_build.json``) and a SHA-256 (``dcs_state_format.h``;
  docs/reliability.md, "FMU state and call order"); ``fmi2DeSerializeFMUstate`` checks all of it
  in C, then ``_fmu_state_from_bytes(payload)`` makes the object (a status raised through
  ``_fmi2_status`` refuses it).
* Strings of ``fmi2GetString`` stay valid until the next ``fmi2GetString`` on the instance.
* Unsupported FMI 2.0 features (directional derivatives, input/output derivatives,
  ``fmi2CancelStep``) return fmi2Error; ``fmi2Get*Status`` returns fmi2Discard except
  ``fmi2GetRealStatus(fmi2LastSuccessfulTime)`` (the end of the last successful step).
"""

from __future__ import annotations

import os
import sys
import sysconfig
import tempfile
import zipfile
from collections.abc import Mapping, Sequence
from pathlib import Path

# the one place the project runs a C compiler (shared with the master's native loop)
from drillcosim._toolchain import CFLAGS, compile_shared

__all__ = ["CFLAGS", "HEADERS", "SOURCES", "compile_shared", "compile_wrapper",
           "install_native_wrapper", "python_range", "sources", "wrapper_library"]

HERE = Path(__file__).resolve().parent
#: The C sources of the wrapper, compiled together. Named, not globbed: an installed copy can
#: carry stray files (setuptools reuses a checkout's ``build/lib``, where a file deleted from
#: the sources stays), and a stray ``.c`` would be linked in.
SOURCES: tuple[Path, ...] = tuple(HERE / n for n in (
    "dcs_discover.c", "dcs_instance.c", "dcs_platform_posix.c", "dcs_platform_win32.c",
    "dcs_python.c", "dcs_registry.c", "dcs_runtime.c", "dcs_sha256.c", "dcs_slave.c",
    "dcs_state.c", "dcs_state_format.c", "fmi2_functions.c"))
#: The official FMI 2.0.5 headers and our internal ones.
HEADERS: tuple[Path, ...] = tuple(HERE / n for n in (
    "dcs_discover.h", "dcs_lock.h", "dcs_platform.h", "dcs_python.h", "dcs_registry.h",
    "dcs_runtime.h", "dcs_sha256.h", "dcs_state_format.h", "dcs_wrapper.h",
    "fmi2/fmi2FunctionTypes.h", "fmi2/fmi2Functions.h", "fmi2/fmi2TypesPlatform.h"))


def python_range() -> tuple[int, int]:
    """(oldest, newest) minor version of CPython 3 the wrapper runs on, read from
    ``dcs_python.h`` (``DCS_PY_MINOR_MIN`` / ``DCS_PY_MINOR_MAX``: the one place they are set)."""
    import re

    text = (HERE / "dcs_python.h").read_text()
    low, high = (int(re.search(rf"#define DCS_PY_MINOR_{k} (\d+)", text).group(1))
                 for k in ("MIN", "MAX"))
    return low, high


def sources() -> list[Path]:
    """Every file the compiled wrapper depends on (C sources and headers)."""
    return [*SOURCES, *HEADERS]


def _c_string(text: str) -> str:
    """``text`` as the body of a C string literal for a -D define (quotes and backslashes)."""
    return text.replace("\\", "\\\\").replace('"', '\\"')


def compile_wrapper(out: Path | str, cc: str | None = None, flags: Sequence[str] = (),
                    include: Path | str | None = None, platform: str = "linux64") -> Path:
    """Compile the wrapper into the shared library ``out``: one binary for CPython 3.10-3.13.

    The running Python's headers are used with ``Py_LIMITED_API`` = 3.10 (the compiler refuses
    anything outside the stable ABI); the running interpreter is recorded as the last Python
    candidate and its minor version as the preferred one among a PATH folder's names (see the
    module docstring); nothing else of this machine is compiled in. A binary for another
    system (``platform="win64"``, cross-compiled) records no interpreter: the building one's
    path means nothing there.

    Parameters
    ----------
    out : path-like
        Target library (its name is irrelevant; FMUs copy it to ``<id>.so`` / ``<id>.dll``).
    cc : str, optional
        C compiler (default: the platform's, :mod:`drillcosim.fmu_src.platforms`).
    flags : sequence of str
        Extra compiler flags (e.g. sanitizers), after :data:`CFLAGS` and the platform's.
    include : path-like, optional
        Python headers to compile against (default: the running Python's, for ``win64`` with
        the Windows ``pyconfig.h``).
    platform : str
        ``linux64`` (default) or ``win64``.

    Returns
    -------
    pathlib.Path
        ``out``.

    Raises
    ------
    RuntimeError
        If there is no compiler, or it fails or prints a warning (its output is included).
    """
    from drillcosim.fmu_src.platforms import PLATFORMS, python_include

    target = PLATFORMS[platform]
    with tempfile.TemporaryDirectory(prefix="dcs-wrapper-") as tmp:
        include = include or python_include(target, Path(tmp))
        build_python = "" if target.cross else sys.executable
        return compile_shared(
            f"the native wrapper ({platform})", SOURCES, out,
            flags=(*target.flags, f"-I{include}", f"-I{HERE}",
                   f"-DDCS_BUILD_PYTHON=\"{_c_string(build_python)}\"",
                   f"-DDCS_BUILD_MINOR={sys.version_info.minor}", *flags),
            libs=target.libs, cc=cc or target.cc)


def wrapper_library(platform: str = "linux64") -> Path:
    """The wrapper compiled for ``platform`` by :func:`compile_wrapper`, from the per-user
    cache (:func:`drillcosim.fmu_src.platforms.cached_library`: compiled once per content of
    its sources, compiler, flags and this interpreter)."""
    from drillcosim.fmu_src.platforms import PLATFORMS, cached_library

    target = PLATFORMS[platform]
    key = (f"{sys.executable}|{sys.version}|{sysconfig.get_paths()['include']}|"
           f"{(HERE / 'win64' / 'pyconfig.h').read_bytes().hex() if target.cross else ''}")
    return cached_library("wrapper", target, sources(), key,
                          lambda path: compile_wrapper(path, platform=platform))


def install_native_wrapper(fmu: Path | str, class_name: str,
                           library: Path | str | Mapping[str, Path | str],
                           requires: tuple[str, ...] = ()) -> None:
    """Make a pythonfmu-built FMU run on our wrapper.

    Writes each platform's library as ``binaries/<platform>/<modelIdentifier><suffix>``, removes
    every other ``binaries/`` member (pythonfmu's prebuilt binaries cannot report errors), and
    writes ``resources/slaveclass.txt`` (the class the wrapper instantiates) and
    ``resources/python_requires.txt`` (the modules a Python must import to run the FMU).

    Parameters
    ----------
    fmu : path-like
        The ``.fmu`` (rewritten in place).
    class_name : str
        The ``Fmi2Slave`` subclass in the slave module.
    library : path-like or mapping of str to path-like
        Output of :func:`compile_wrapper`: one path (the ``linux64`` library) or ``{platform:
        path}``.
    requires : tuple of str
        Import names checked in each Python candidate of a host without Python.
    """
    from drillcosim.fmu_src.platforms import PLATFORMS

    libraries = (dict(library) if isinstance(library, Mapping) else {"linux64": library})
    fmu = Path(fmu)
    tmp = fmu.with_suffix(".native.tmp")
    ours = {"resources/slaveclass.txt", "resources/python_requires.txt"}
    with zipfile.ZipFile(fmu) as src:
        md = src.read("modelDescription.xml").decode()
        ident = md.split('modelIdentifier="', 1)[1].split('"', 1)[0]
        with zipfile.ZipFile(tmp, "w", zipfile.ZIP_DEFLATED) as dst:
            for info in src.infolist():
                if info.filename.startswith("binaries/") or info.filename in ours:
                    continue
                dst.writestr(info, src.read(info.filename), compress_type=zipfile.ZIP_DEFLATED)
            for name, path in libraries.items():
                dst.write(path, PLATFORMS[name].library_name(ident))
            dst.writestr("resources/slaveclass.txt", class_name + "\n")
            dst.writestr("resources/python_requires.txt", " ".join(requires) + "\n")
    os.replace(tmp, fmu)
