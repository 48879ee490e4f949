"""The platforms an FMU carries binaries for, and how each binary is compiled on this machine.

An FMI 2.0 FMU holds one binary per platform in ``binaries/<platform>/``; an importer loads the
one of its own operating system and bitness. The build compiles the native wrapper (and the C
controller) for every platform of a :class:`Selection`: ``linux64`` with the machine's C
compiler, ``win64`` cross-compiled with mingw-w64 (Debian ``gcc-mingw-w64-x86-64``). By default
every platform whose compiler is found is built; the others are named with the reason
(:func:`select`). 32-bit platforms (``win32``, ``linux32``) are not built: the plant needs a
64-bit Python with numba, and a 32-bit host cannot load a 64-bit library (its loader refuses
it: ``docs/interop.md``).

The wrapper's C code is the same for every platform; what differs is here: the compiler, its
flags and libraries, the library suffix, and the Python headers (the building interpreter's,
with a ``pyconfig.h`` for 64-bit Windows, ``fmu_src/wrapper/win64/pyconfig.h``, for the cross
build). A compiled wrapper is kept in the per-user cache under a key of everything it is made
of (:func:`cached_library`): mingw-w64 takes ~4x gcc's time on ``windows.h``, and every FMU of
a build carries the same wrapper.
"""

from __future__ import annotations

import hashlib
import os
import platform as _host
import shutil
import subprocess
import sys
import sysconfig
import tempfile
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path

from drillcosim._toolchain import user_cache

__all__ = ["PLATFORMS", "Platform", "Selection", "cached_library", "host_platform",
           "python_include", "select"]

WRAPPER_DIR = Path(__file__).resolve().parent / "wrapper"


@dataclass(frozen=True)
class Platform:
    """One FMI 2.0 binary platform and its toolchain on this machine.

    Attributes
    ----------
    name : str
        The folder under ``binaries/`` (FMI 2.0 names: ``linux64``, ``win64``).
    compiler : str
        Default C compiler (a name on PATH).
    compiler_env : str
        Environment variable that overrides it (``CC`` for the native one).
    install_hint : str
        How to get the compiler (for the message naming a skipped platform).
    suffix : str
        Shared library suffix.
    flags : tuple of str
        Compiler flags added to :data:`drillcosim._toolchain.CFLAGS`.
    libs : tuple of str
        Libraries the wrapper links (after its sources).
    c_libs : tuple of str
        Libraries the C controller links.
    """

    name: str
    compiler: str
    compiler_env: str
    install_hint: str
    suffix: str
    flags: tuple[str, ...] = ()
    libs: tuple[str, ...] = ()
    c_libs: tuple[str, ...] = ()

    @property
    def cc(self) -> str:
        """str: the compiler used: ``$<compiler_env>``, else :attr:`compiler`."""
        return os.environ.get(self.compiler_env) or self.compiler

    def missing(self) -> str:
        """Why this platform cannot be built here (one line), or ``""`` if it can."""
        if shutil.which(self.cc) is None:
            return f"{self.cc} not found ({self.install_hint}; or set ${self.compiler_env})"
        return ""

    def library_name(self, model_identifier: str) -> str:
        """``binaries/<name>/<model identifier><suffix>``: where the FMU holds the binary."""
        return f"binaries/{self.name}/{model_identifier}{self.suffix}"

    @property
    def cross(self) -> bool:
        """bool: whether binaries of this platform cannot run on this machine."""
        return self.name != host_platform()


#: The platforms the build knows, by name.
PLATFORMS: dict[str, Platform] = {
    "linux64": Platform(
        name="linux64", compiler="gcc", compiler_env="CC",
        install_hint="Debian: apt install gcc", suffix=".so",
        libs=("-ldl", "-lpthread"), c_libs=("-lm", "-lpthread")),
    "win64": Platform(
        name="win64", compiler="x86_64-w64-mingw32-gcc", compiler_env="DRILLCOSIM_CC_WIN64",
        install_hint="Debian: apt install gcc-mingw-w64-x86-64", suffix=".dll",
        # no libgcc DLL to ship; symbols stripped (the DLL exports what FMI needs by name)
        flags=("-static-libgcc", "-s"), libs=("-ladvapi32",), c_libs=()),
}


def host_platform() -> str | None:
    """The FMI 2.0 platform of this process (``linux64``, ``win64``), None for another one."""
    bits64 = sys.maxsize > 2**32
    machine = _host.machine().lower()
    if sys.platform == "win32" and bits64 and machine in ("amd64", "x86_64"):
        return "win64"
    if sys.platform.startswith("linux") and bits64 and machine in ("x86_64", "amd64"):
        return "linux64"
    return None


@dataclass(frozen=True)
class Selection:
    """The platforms a build writes binaries for.

    Attributes
    ----------
    platforms : tuple of Platform
        In the order given (the native one first by default).
    skipped : tuple of str
        One line per platform left out by default, naming why.
    """

    platforms: tuple[Platform, ...]
    skipped: tuple[str, ...] = ()

    @property
    def names(self) -> tuple[str, ...]:
        """tuple of str: the platform names."""
        return tuple(p.name for p in self.platforms)

    def note(self) -> str:
        """One line naming what was skipped and why (``""`` if nothing was)."""
        if not self.skipped:
            return ""
        return "note: FMU binaries not built for " + "; ".join(self.skipped)


def select(names: str | Sequence[str] | None = None) -> Selection:
    """The platforms to build: ``names`` (a comma-separated string or a sequence), or by
    default this machine's platform and every other one whose compiler is found.

    Raises
    ------
    ValueError
        A name that is not in :data:`PLATFORMS`, a platform named explicitly whose compiler
        is missing, or by default no compiler for this machine's platform (one line each).
    """
    if names is None:
        chosen, skipped = [], []
        for p in PLATFORMS.values():
            why = p.missing()
            if why and p.name == host_platform():  # the FMUs must run where they are built
                raise ValueError(f"{p.name} (this machine): {why}")
            if why:
                skipped.append(f"{p.name}: {why}")
            else:
                chosen.append(p)
        if not chosen:
            raise ValueError("no C compiler for any platform: " + "; ".join(skipped))
        return Selection(tuple(chosen), tuple(skipped))
    wanted = [n.strip() for n in (names.split(",") if isinstance(names, str) else names)]
    unknown = [n for n in wanted if n not in PLATFORMS]
    if unknown or not wanted or "" in wanted:
        raise ValueError(f"platforms: {', '.join(unknown) or repr(names)} unknown; allowed: "
                         f"{', '.join(PLATFORMS)} (comma-separated)")
    missing = [f"{n}: {PLATFORMS[n].missing()}" for n in wanted if PLATFORMS[n].missing()]
    if missing:
        raise ValueError("cannot build for " + "; ".join(missing))
    return Selection(tuple(PLATFORMS[n] for n in dict.fromkeys(wanted)))


def python_include(platform: Platform, workdir: Path) -> Path:
    """Python headers to compile the wrapper for ``platform`` against.

    The running interpreter's (limited API 3.10 declarations: the same on every platform); for
    a Windows target a copy of them in ``workdir`` with ``wrapper/win64/pyconfig.h`` in place of
    this system's ``pyconfig.h`` (sizes of C types, the DLL import declarations).
    """
    include = Path(sysconfig.get_paths()["include"])
    if platform.name != "win64":
        return include
    dest = workdir / "python-include-win64"
    if not (dest / "Python.h").is_file():
        shutil.copytree(include, dest, dirs_exist_ok=True)
        shutil.copyfile(WRAPPER_DIR / "win64" / "pyconfig.h", dest / "pyconfig.h")
    return dest


def _compiler_identity(cc: str) -> str:
    """``cc --version`` (first line) and the compiler's path: part of a cached library's key."""
    path = shutil.which(cc) or cc
    proc = subprocess.run([path, "--version"], capture_output=True, text=True)
    return f"{os.path.realpath(path)}|{proc.stdout.splitlines()[0] if proc.stdout else ''}"


def cached_library(what: str, platform: Platform, inputs: Iterable[Path], key_text: str,
                   compile_to: Callable[[Path], Path]) -> Path:
    """A library compiled once per content and kept in ``<user cache>/binaries/``.

    Parameters
    ----------
    what : str
        Its name in the cache (``wrapper``, ``StrainControllerC``).
    platform : Platform
    inputs : iterable of Path
        Every file it is compiled from (bytes hashed).
    key_text : str
        Everything else it depends on (flags, defines, the Python headers' identity).
    compile_to : callable
        ``compile_to(path)`` compiles it to ``path`` (a temporary name beside the cache entry).

    Returns
    -------
    pathlib.Path
        The cached library (written atomically; a concurrent writer writes the same bytes).
    """
    digest = hashlib.sha256()
    for path in inputs:
        digest.update(path.name.encode() + b"\0" + path.read_bytes() + b"\0")
    digest.update(f"{key_text}|{_compiler_identity(platform.cc)}".encode())
    folder = user_cache() / "binaries"
    final = folder / f"{what}-{platform.name}-{digest.hexdigest()[:20]}{platform.suffix}"
    if not final.is_file():
        folder.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(prefix=f".{final.stem}-", suffix=platform.suffix,
                                   dir=folder)
        os.close(fd)
        try:
            compile_to(Path(tmp))
            os.replace(tmp, final)
        finally:
            if os.path.exists(tmp):
                os.unlink(tmp)
    return final
