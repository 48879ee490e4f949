"""Checkpoint files of scene runs: what identifies the run, and reading one for a resume.

The master's :class:`~cosim.master.checkpoint.Checkpoint` carries each component's build (an
FMU's model identifier, GUID and file SHA-256) and start values; this layer adds the run's own
identity (:func:`run_identity`): the scene's name, the SHA-256 of its validated settings (plant,
controllers, co-simulation settings other than the stop time), the engine and the drillcosim
version. A checkpoint is resumed only by a run of the same identity (:func:`load_for`), else
refused with one line naming what differs.
"""

from __future__ import annotations

import hashlib
import sys
from importlib import metadata
from pathlib import Path
from typing import Any

import numpy as np

from drillcosim.cosim.master.checkpoint import Checkpoint, CheckpointError, read_checkpoint

from .config import SceneConfig

__all__ = ["load_for", "run_identity"]


def _version() -> str:
    try:
        return metadata.version("drillcosim")
    except metadata.PackageNotFoundError:   # a source tree that is not installed
        return "unknown"


def settings_digest(config: SceneConfig, leave_out: tuple[str, ...] = ("stop_time",)) -> str:
    """SHA-256 (hex) of the validated settings, the co-simulation keys ``leave_out`` left out.

    Every number is written in full (``repr``; arrays without summarization), so two settings
    that differ in the last bit differ here.
    """
    cosim = {k: v for k, v in config.cosim.as_dict().items() if k not in leave_out
             and not any(k.startswith(f"{o}_") or k == o for o in leave_out)}
    with np.printoptions(threshold=sys.maxsize, floatmode="unique"):
        text = repr((config.scene, sorted(config.controllers.items()),
                     sorted(config.plant_parameters.items()), sorted(cosim.items())))
    return hashlib.sha256(text.encode()).hexdigest()


def run_identity(config: SceneConfig, engine: str) -> dict[str, Any]:
    """What a checkpoint of a run of ``config`` on ``engine`` belongs to (JSON-ready)."""
    return {"scene": config.name, "settings_sha256": settings_digest(config),
            "engine": engine, "drillcosim": _version()}


def load_for(path: str | Path, config: SceneConfig, engine: str, stop: float) -> Checkpoint:
    """Read checkpoint ``path`` for a run of ``config`` on ``engine`` to ``stop`` [s].

    Raises
    ------
    CheckpointError
        One line naming the file: unreadable, damaged, or of another scene, settings, engine or
        drillcosim version (the components' builds are checked when the run restores it).
    """
    checkpoint = read_checkpoint(path)
    now = run_identity(config, engine)
    saved = checkpoint.identity
    what = {"scene": "scene", "settings_sha256": "settings (plant, controllers, co-simulation)",
            "engine": "engine", "drillcosim": "drillcosim version"}
    for key, name in what.items():
        if saved.get(key) != now[key]:
            show = (lambda v: str(v)[:12]) if key == "settings_sha256" else repr
            raise CheckpointError(f"checkpoint '{path}' is of another {name}: "
                                  f"{show(saved.get(key))}, this run {show(now[key])}")
    if stop <= checkpoint.time:
        raise CheckpointError(f"checkpoint '{path}' is at {checkpoint.time!r} s; the stop time "
                              f"{stop!r} s must be later")
    return checkpoint
