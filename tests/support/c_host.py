"""The plain C FMI host of the tests (``fmi2_host.c``): compile it, run an FMU in it.

The host has no Python in its process, so our wrapper must find one itself (the discovery order
of ``fmu_src/wrapper/dcs_discover.c``). It is compiled against the official FMI 2.0 headers
shipped beside our wrapper.
"""

from __future__ import annotations

import subprocess
import zipfile
from pathlib import Path

from drillcosim.fmu_src.wrapper import HERE as WRAPPER_DIR

SOURCE = Path(__file__).resolve().parent / "fmi2_host.c"
OK, WARNING, DISCARD, ERROR, FATAL = 0, 1, 2, 3, 4


def compile_host(dest: Path) -> Path:
    """Compile the host into ``dest/fmi2_host``; warnings are errors."""
    exe = dest / "fmi2_host"
    subprocess.run(["gcc", "-std=c99", "-O1", "-Wall", "-Wextra", "-Werror",
                    f"-I{WRAPPER_DIR / 'fmi2'}", "-o", str(exe), str(SOURCE), "-ldl"],
                   check=True, capture_output=True, text=True)
    return exe


def unzip(fmu: Path, dest: Path) -> Path:
    """Extract ``fmu`` into ``dest`` (created) and return it."""
    dest.mkdir(parents=True, exist_ok=True)
    with zipfile.ZipFile(fmu) as zf:
        zf.extractall(dest)
    return dest


def run_host(host: Path, unzipped: Path, model: str, stop: float, step: float,
             sets: list[str], outputs: list[int], env: dict[str, str], cwd: Path,
             timeout: float = 600) -> subprocess.CompletedProcess:
    """Run one FMU in the C host: ``sets`` like ``"r:VR=VALUE"``, ``outputs`` value references."""
    cmd = [str(host), str(unzipped), model, repr(stop), repr(step), *sets, "--",
           *map(str, outputs)]
    return subprocess.run(cmd, env=env, cwd=cwd, capture_output=True, text=True,
                          timeout=timeout)


def rows(stdout: str) -> list[list[float]]:
    """The result rows (time, outputs...) of a host run, without the ``BAD`` line."""
    return [[float(x) for x in line.split(",")] for line in stdout.splitlines()
            if line and not line.startswith("BAD")]


def log_lines(stderr: str, status: int | None = None) -> list[str]:
    """The logged messages (first line of each) with ``status`` (all if None)."""
    out = []
    for line in stderr.splitlines():
        if line.startswith("[chost "):
            st = int(line.split()[1])
            if status is None or st == status:
                out.append(line)
    return out
