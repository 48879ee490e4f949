"""The plain C co-simulation host of the tests (``fmi2_cosim_host.c``): several FMUs connected,
Jacobi with a zero-order hold, no Python in the process; built with gcc for Linux and with
mingw-w64 for Windows (run under wine).

:func:`write_spec` turns a :class:`support.closed_loop.ClosedLoop` (our master's system) into the
host's SPEC file for FMUs unzipped in given folders, :func:`run` runs it and returns the rows.
"""

from __future__ import annotations

import subprocess
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np
from fmpy import read_model_description

from drillcosim.fmu_src.wrapper import HERE as WRAPPER_DIR

__all__ = ["SOURCE", "compile_host", "rows", "run", "run_to_file", "write_spec"]

SOURCE = Path(__file__).resolve().parent / "fmi2_cosim_host.c"


def compile_host(dest: Path, cc: str = "gcc") -> Path:
    """Compile the host into ``dest`` with ``cc`` (``gcc``, ``clang``, or
    ``x86_64-w64-mingw32-gcc`` for a Windows ``.exe``); warnings are errors."""
    exe = dest / ("fmi2_cosim_host.exe" if "mingw" in cc else "fmi2_cosim_host")
    libs = [] if "mingw" in cc else ["-ldl"]
    subprocess.run([cc, "-std=c99", "-O1", "-Wall", "-Wextra", "-Werror",
                    f"-I{WRAPPER_DIR / 'fmi2'}", "-o", str(exe), str(SOURCE), *libs],
                   check=True, capture_output=True, text=True)
    return exe


def _value(value: object) -> tuple[str, str]:
    if isinstance(value, bool):
        return "bool", str(int(value))
    if isinstance(value, int):
        return "int", str(value)
    if isinstance(value, float):
        return "real", repr(value)
    return "string", str(value)


def write_spec(loop, unzipped: Mapping[str, str], path: Path,
               outputs: Sequence[str] | None = None) -> Path:
    """The SPEC of ``loop`` (a ClosedLoop) for its FMUs unzipped at ``unzipped`` (instance ->
    folder as the host sees it: a Linux path, or ``Z:\\...`` under wine); ``outputs``
    (``'inst.var'``) default to the loop's."""
    refs = {}
    lines = [f"step {loop.step!r}", f"stop {loop.stop!r}"]
    for spec in loop.system.fmus:
        md = read_model_description(str(spec.path))
        refs[spec.name] = {v.name: v.valueReference for v in md.modelVariables}
        lines.append(f"fmu {spec.name} {md.coSimulation.modelIdentifier} "
                     f"{unzipped[spec.name]}")
    for spec in loop.system.fmus:
        for name, value in spec.parameters.items():
            kind, text = _value(value)
            lines.append(f"{kind} {spec.name} {refs[spec.name][name]} {text}")
    for c in loop.system.connections:
        (si, sv), (ti, tv) = c.source.split(".", 1), c.target.split(".", 1)
        lines.append(f"connect {si} {refs[si][sv]} {ti} {refs[ti][tv]}")
    for out in outputs or loop.outputs:
        inst, var = out.split(".", 1)
        lines.append(f"output {inst} {refs[inst][var]}")
    path.write_text("\n".join(lines) + "\n")
    return path


def rows(stdout: str) -> np.ndarray:
    """The printed rows (time, outputs...) as an array."""
    return np.array([[float(x) for x in line.split(",")] for line in stdout.splitlines()
                     if line.strip()])


def run(cmd: Sequence[str], env: Mapping[str, str], cwd: Path,
        timeout: float = 900) -> subprocess.CompletedProcess:
    """Run the host command (``[host, spec]``, or under wine) with stdin the null device."""
    return subprocess.run(list(cmd), env=dict(env), cwd=cwd, capture_output=True, text=True,
                          timeout=timeout, stdin=subprocess.DEVNULL)


def run_to_file(cmd: Sequence[str], out: Path, env: Mapping[str, str], cwd: Path,
                timeout: float = 3600) -> tuple[int, str, str]:
    """Run the host with its rows written to ``out`` and its log to ``out.log`` (the last
    argument of ``cmd`` is ``out`` as the host sees it) and the standard handles on the null
    device: a wineserver the run starts keeps no pipe of ours open. Returns (exit status,
    rows text, log text)."""
    proc = subprocess.run(list(cmd), env=dict(env), cwd=cwd, stdin=subprocess.DEVNULL,
                          stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                          timeout=timeout)
    log = Path(f"{out}.log")
    return (proc.returncode, out.read_text() if out.is_file() else "",
            log.read_text(errors="replace") if log.is_file() else "")
