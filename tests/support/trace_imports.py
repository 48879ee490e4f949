"""Trace which package folders the FMUs' slaves import: ``python tests/support/trace_imports.py
[--write]`` (from a checkout).

Runs the regular plant and controller FMUs (built into a temporary folder) in the plain C
co-simulation host of the tests (``tests/support/fmi2_cosim_host.c``: no Python in the process
but the one the wrapper starts) under ``strace -f -e trace=openat``, twice (numba's cache cold,
then warm: the compiling and the cached paths import different modules), and a Python process
that makes the plant's lazy scipy imports (its exponential integrators: ``scipy.linalg``,
``scipy.sparse.csgraph``). Every file opened below the building interpreter's site-packages
names a package folder; the sorted folders are printed, or written to
``fmu_src/standalone/imported_packages.txt`` with ``--write`` (what
``drillcosim.fmu_src.standalone.selection`` ships). A maintainer's tool, to run when numpy,
scipy, numba or the FMUs' imports change: needs ``strace`` (Debian: apt install strace) and a C
compiler.
"""

from __future__ import annotations

import argparse
import os
import re
import shutil
import subprocess
import sys
import sysconfig
import tempfile
import zipfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
sys.path[:0] = [str(ROOT), str(ROOT / "tests")]

from drillcosim.fmu_src.build import REGISTRY, build_one  # noqa: E402
from drillcosim.fmu_src.standalone.selection import IMPORTED  # noqa: E402
from support import cosim_host  # noqa: E402
from support.closed_loop import closed_loop  # noqa: E402

LAZY_SCIPY = ("import numpy as np\nfrom scipy.linalg import expm\nfrom scipy.sparse import "
              "csr_matrix\nfrom scipy.sparse.csgraph import connected_components\n"
              "expm(np.eye(3)); connected_components(csr_matrix(np.eye(3)))\n")


def _opened(trace: Path) -> set[str]:
    found = set()
    for line in trace.read_text(errors="replace").splitlines():
        m = re.search(r'openat\([^"]*"([^"]+)".*\)\s+=\s+(\d+)', line)
        if m:
            found.add(os.path.normpath(m.group(1)))
    return found


def packages_of(files: set[str], site: Path) -> list[str]:
    """Dotted package folders of the opened files below ``site`` (not .libs, .dist-info)."""
    folders = set()
    prefix = str(site) + os.sep
    for f in files:
        if not f.startswith(prefix) or not os.path.isfile(f):
            continue
        parts = Path(f[len(prefix):]).parent.parts
        parts = tuple(p for p in parts if p != "__pycache__")
        if parts and not parts[0].endswith((".libs", ".dist-info", ".pth")) and \
                all(p.isidentifier() for p in parts):
            folders.add(".".join(parts))
    return sorted(folders)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--write", action="store_true", help=f"write {IMPORTED.name}")
    args = parser.parse_args(argv)
    if shutil.which("strace") is None:
        print("trace_imports: needs strace (Debian: apt install strace)", file=sys.stderr)
        return 2
    site = Path(sysconfig.get_paths()["purelib"]).resolve()
    work = Path(tempfile.mkdtemp(prefix="dcs_trace_"))
    try:
        recipes = {r.name: r for r in REGISTRY}
        fmus = {n: build_one(recipes[n], work / "fmus")
                for n in ("DrillstringPlant", "StrainController")}
        loop = closed_loop(fmus["DrillstringPlant"], fmus["StrainController"], work,
                           stop=0.01)
        dirs = {}
        for inst, name in (("plant", "DrillstringPlant"), ("controller", "StrainController")):
            with zipfile.ZipFile(fmus[name]) as zf:
                zf.extractall(work / inst)
            dirs[inst] = str(work / inst)
        spec = cosim_host.write_spec(loop, dirs, work / "loop.spec")
        host = cosim_host.compile_host(work)
        opened: set[str] = set()
        env = {"HOME": str(work / "home"), "PATH": "/usr/bin:/bin",
               "DRILLCOSIM_PYTHON": sys.executable, "DRILLCOSIM_CACHE": str(work / "cache"),
               "NUMBA_CACHE_DIR": str(work / "cache" / "numba")}
        for run in ("cold", "warm"):
            trace = work / f"{run}.trace"
            subprocess.run(["strace", "-f", "-e", "trace=openat", "-o", str(trace),
                            str(host), str(spec)], env=env, check=True, capture_output=True)
            opened |= _opened(trace)
        trace = work / "scipy.trace"
        subprocess.run(["strace", "-f", "-e", "trace=openat", "-o", str(trace), sys.executable,
                        "-c", LAZY_SCIPY], check=True, capture_output=True)
        opened |= _opened(trace)
        found = packages_of(opened, site)
    finally:
        shutil.rmtree(work, ignore_errors=True)
    text = "\n".join(found)
    if args.write:
        head = [ln for ln in IMPORTED.read_text().splitlines() if ln.startswith("#")]
        IMPORTED.write_text("\n".join(head) + "\n" + text + "\n")
    print(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
