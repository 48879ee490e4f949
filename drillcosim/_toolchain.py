"""The C toolchain and the per-user cache, shared by the FMU build (:mod:`drillcosim.fmu_src`)
and the master's native stepping loop (:mod:`drillcosim.cosim.master.native`).

The one place the project runs a C compiler: every C library it makes (the FMI wrapper, the
C-coded FMUs, the master's stepping loop) is compiled by :func:`compile_shared` with
:data:`CFLAGS`, and a compiler warning is an error.
"""

from __future__ import annotations

import os
import shutil
import subprocess
from collections.abc import Sequence
from pathlib import Path

__all__ = ["CFLAGS", "compile_shared", "user_cache"]

CFLAGS = ("-std=c99", "-O2", "-DNDEBUG", "-Wall", "-Wextra", "-Werror", "-shared", "-fPIC",
          "-fvisibility=hidden")


def user_cache() -> Path:
    """Per-user cache folder: ``$DRILLCOSIM_CACHE``, else ``$XDG_CACHE_HOME/drillcosim``."""
    env = os.environ.get("DRILLCOSIM_CACHE")
    if env:
        return Path(env)
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(base) / "drillcosim"


def compile_shared(what: str, sources: Sequence[Path], out: Path | str, *,
                   flags: Sequence[str] = (), libs: Sequence[str] = (),
                   cc: str | None = None) -> Path:
    """Compile C ``sources`` into the shared library ``out`` with :data:`CFLAGS`.

    Parameters
    ----------
    what : str
        What is compiled, for messages (e.g. "the native wrapper").
    sources : sequence of Path
        C files.
    out : path-like
        Target ``.so``.
    flags, libs : sequence of str
        Extra compiler flags (before the sources) and libraries (after them).
    cc : str, optional
        C compiler (default ``$CC`` or ``gcc``).

    Raises
    ------
    RuntimeError
        No compiler, or it failed or printed a warning (its command and output included).
    """
    out = Path(out)
    cc = cc or os.environ.get("CC") or "gcc"
    if shutil.which(cc) is None:
        raise RuntimeError(f"C compiler {cc!r} not found: building {what} needs one "
                           f"(Debian: apt install gcc; or set $CC)")
    cmd = [cc, *CFLAGS, *flags, *map(str, sources), "-o", str(out), *libs]
    proc = subprocess.run(cmd, capture_output=True, text=True)
    if proc.returncode != 0 or proc.stderr.strip():
        raise RuntimeError(f"compiling {what} failed:\n{' '.join(cmd)}\n"
                           f"{proc.stdout}{proc.stderr}")
    return out
