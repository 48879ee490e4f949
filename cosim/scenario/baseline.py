"""The open-loop baseline of a closed-loop run: the same scene with the strain controller off.

A run's figures show the controller against what the string does without it (the paper's
Fig. 11 is such a comparison). The baseline is the scene's reference run of the sweeps
(:func:`cosim.study.point.point_config` with ``open_loop``): the configuration with
``controller.enabled = false`` and everything else as the run's (plant, step, stop time, delays,
top-drive controller). It runs in process (the plant FMU's own numbers, bit for bit, without
the FMI boundary) unless the run uses a plant FMU of its own, and is kept on disk by content
(:func:`cosim.scenario.cache.cached_file`, kind ``baselines``): the configuration, the sources
of the plant, the master and the FMU adapters, a user's plant FMU's bytes, numpy's and scipy's
versions. The first closed-loop run of a scene and its settings pays one open-loop run; the
next ones read it.
"""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

import numpy as np

from drillcosim.plant.signals import CONTROLLER, PLANT

from .cache import cached_file, is_cached, load_arrays, source_hash
from .config import SceneConfig, derive_config

__all__ = ["baseline_cached", "baseline_config", "baseline_path", "load_baseline"]


def baseline_config(config: SceneConfig) -> SceneConfig | None:
    """``config`` with the strain controller off; None when it is off already."""
    if not config.controller.enabled:
        return None
    return derive_config(config, {f"{CONTROLLER}.enabled": False}, controller_fmu=False)


def _code(config: SceneConfig) -> str:
    import drillcosim.cosim.master as master
    import drillcosim.fmu_src as fmu_src
    import drillcosim.plant as plant

    code = source_hash(*(str(Path(m.__file__).parent) for m in (plant, master, fmu_src)),
                       str(Path(__file__).parent))
    fmu = config.fmu_files.get(PLANT)
    if fmu is not None:
        code += hashlib.sha256(Path(fmu).read_bytes()).hexdigest()
    return code


def baseline_path(config: SceneConfig, progress: bool | None = False) -> Path | None:
    """The file of ``config``'s open-loop baseline (run now if not cached); None for a run
    without the strain controller.

    Parameters
    ----------
    config : SceneConfig
        The closed-loop run's configuration.
    progress : bool or None
        Progress bar of the baseline run, when it runs (None: only on a terminal).

    Returns
    -------
    Path or None
        An ``.npz`` file (:func:`load_baseline`).
    """
    base = baseline_config(config)
    if base is None:
        return None

    def run() -> dict[str, np.ndarray]:
        from .build import build_system
        from .simulate import simulate

        engine = "fmu" if PLANT in base.fmu_files else "inprocess"
        res = simulate(build_system(base, engine), progress=progress)
        return {"data": res.data, "units": np.array(json.dumps(res.units)),
                "end_time": np.float64(res.end_time)}

    return cached_file("baselines", _ident(base), run)


def _ident(base: SceneConfig) -> dict[str, str]:
    return {"config": repr(base), "code": _code(base)}


def baseline_cached(config: SceneConfig) -> bool:
    """Is ``config``'s baseline in the cache (or not needed: no strain controller)?"""
    base = baseline_config(config)
    return base is None or is_cached("baselines", _ident(base))


def load_baseline(path: str | Path) -> np.ndarray:
    """The recorded rows of a baseline file (structured array: ``time`` [s], ``'plant.*'``)."""
    return load_arrays(path)["data"]
