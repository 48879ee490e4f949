"""Build the tiny master-test FMUs once per session into a cache directory.

The FMUs are rebuilt only when their script changes (a hash of the script is
part of the file name), so repeated test sessions reuse them.
"""

from __future__ import annotations

import hashlib
import os
import tempfile
from pathlib import Path

HERE = Path(__file__).resolve().parent
SCRIPTS = ("mt_integrator", "mt_gain", "mt_source", "mt_mass")


def cache_dir() -> Path:
    """Directory holding built test FMUs (``DRILLCOSIM_TEST_FMU_DIR`` or a tmp dir)."""
    root = os.environ.get("DRILLCOSIM_TEST_FMU_DIR")
    path = Path(root) if root else Path(tempfile.gettempdir()) / "drillcosim_master_fmus"
    path.mkdir(parents=True, exist_ok=True)
    return path


def build_fmu(name: str, dest: Path | None = None) -> Path:
    """Build (or reuse) the FMU of ``tests/master_fmus/<name>.py``; return its path."""
    from pythonfmu.builder import FmuBuilder

    script = HERE / f"{name}.py"
    digest = hashlib.sha1(script.read_bytes()).hexdigest()[:12]
    dest = dest or cache_dir()
    target = dest / f"{name}-{digest}.fmu"
    if not target.exists():
        tmp_dir = Path(tempfile.mkdtemp(dir=dest))
        built = FmuBuilder.build_FMU(
            script, dest=tmp_dir, canGetAndSetFMUstate=True, canSerializeFMUstate=True
        )
        os.replace(built, target)
        tmp_dir.rmdir()
    return target


def build_all(dest: Path | None = None) -> dict[str, Path]:
    """Build every test FMU; return ``{script name: fmu path}``."""
    return {name: build_fmu(name, dest) for name in SCRIPTS}
