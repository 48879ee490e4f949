"""Earlier commits' physics packages, taken from this clone's git history (not tests).

The "nothing moves" tests compare today's plant and controllers with those of a commit before a
change: :func:`baseline_packages` extracts that commit's ``plant/``, ``controller/`` and
``scenes/`` with ``git archive`` into the user cache (``<cache>/baselines/<sha12>/``, once: the
folder is filled in a temporary folder and renamed into place; nothing there is ever deleted
while complete, other sessions on the machine may use it) and imports the packages under
other names (``plant_<sha12>``, ``controller_<sha12>``: they are self-contained, as the FMUs
vendor them, so nothing of today's tree is mixed in). numba's cache of the extracted plant sits
beside it, so a second session compiles nothing.
"""

from __future__ import annotations

import importlib
import os
import shutil
import subprocess
import sys
import tarfile
import tempfile
from pathlib import Path
from types import ModuleType

from drillcosim._toolchain import user_cache

__all__ = ["ROOT", "Baseline", "baseline_packages", "have_commit", "scenes_at"]

ROOT = Path(__file__).resolve().parents[2]
#: The folders taken from a commit; the two packages are imported under ``<name>_<sha12>``.
FOLDERS = ("plant", "controller", "scenes")
PACKAGES = ("plant", "controller")
#: Written last into a complete extraction.
COMPLETE = "complete.txt"


def _git(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run(["git", "-C", str(ROOT), *args], capture_output=True)


def have_commit(commit: str) -> bool:
    """Whether ``commit`` is in this clone's history (a shallow or exported copy has none)."""
    return shutil.which("git") is not None and _git(
        "cat-file", "-e", f"{commit}^{{commit}}").returncode == 0


def scenes_at(commit: str) -> list[str]:
    """Names of the scenes shipped at ``commit`` (``scenes/*.toml``), sorted."""
    out = _git("ls-tree", "--name-only", commit, "scenes/").stdout.decode().split()
    return sorted(Path(p).stem for p in out if p.endswith(".toml"))


class Baseline:
    """A commit's packages, imported under their own names.

    Attributes
    ----------
    commit : str
    home : Path
        The extracted folder (``plant_<sha12>/``, ``controller_<sha12>/``, ``scenes/``).
    scenes : Path
        Its scenes folder.
    """

    def __init__(self, commit: str, home: Path) -> None:
        self.commit = commit
        self.home = home
        self.scenes = home / "scenes"

    def module(self, package: str, name: str = "") -> ModuleType:
        """``<package>_<sha12>[.name]`` (e.g. ``module("plant", "simulator")``)."""
        full = f"{package}_{self.commit[:12]}" + (f".{name}" if name else "")
        sys.path.insert(0, str(self.home))
        try:
            return importlib.import_module(full)
        finally:
            sys.path.remove(str(self.home))


def baseline_packages(commit: str) -> Baseline:
    """The packages of ``commit`` (extracted once into the user cache; see the module
    docstring). The caller checks :func:`have_commit` first."""
    sha = commit[:12]
    home = user_cache() / "baselines" / sha
    if not (home / COMPLETE).exists():
        home.parent.mkdir(parents=True, exist_ok=True)
        tmp = Path(tempfile.mkdtemp(dir=home.parent, prefix="tmp"))
        arc = _git("archive", "--format=tar", commit, *FOLDERS)
        if arc.returncode != 0:
            raise RuntimeError(arc.stderr.decode())
        tar = tmp / "base.tar"
        tar.write_bytes(arc.stdout)
        with tarfile.open(tar) as tf:
            # our own history: trusted; the "data" filter where this Python has it
            tf.extractall(tmp, **({"filter": "data"} if hasattr(tarfile, "data_filter") else {}))
        tar.unlink()
        for package in PACKAGES:
            (tmp / package).rename(tmp / f"{package}_{sha}")
        (tmp / COMPLETE).write_text(commit + "\n")
        if home.exists():  # left incomplete by a killed run
            shutil.rmtree(home, ignore_errors=True)
        try:
            os.replace(tmp, home)  # atomic: a concurrent run finds all or nothing
        except OSError:  # another run put it there first
            shutil.rmtree(tmp, ignore_errors=True)
    return Baseline(commit, home)
