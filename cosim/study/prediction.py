"""The linear prediction of a sweep: per point, and over the maps' (delay, gain) plane.

* :func:`point_prediction`: the predicted growth rate [1/s] of one point's configuration (its
  own plant, loop timing and lag: :class:`cosim.study.stability.LoopModel`), or NaN and why the
  linear model does not apply (a nonlinear or foreign controller, a multirate loop, a scene
  without the strain loop);
* :func:`predicted_boundary`: the critical gain vs actuator delay per step
  (:func:`cosim.study.boundary.critical_gains`);
* :func:`predicted_curves`: the growth rate vs actuator delay per gain and step.

What does not change between points is computed once: the plant's linearization per plant and
operating point (on disk by content: :func:`cosim.study.stability.coupled_plant`), its
discretization and frequency response per step (in the loop model, kept per process by
:func:`loop_model`); per gain and delay only the loop is closed (one eigenvalue problem).
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping, Sequence
from typing import Any

from threadpoolctl import threadpool_limits
from tqdm import tqdm

from drillcosim.cosim.scenario.config import ConfigError, SceneConfig, load_config
from drillcosim.plant.signals import CONTROLLER

from .boundary import critical_gains, growth_rates
from .stability import LoopModel

__all__ = ["loop_model", "point_prediction", "predicted_boundary", "predicted_curves",
           "prediction_progress", "unavailable"]


def unavailable(config: SceneConfig) -> str:
    """Why the linear prediction does not model ``config``'s strain loop ("" if it does)."""
    ctrl = config.controller
    if CONTROLLER in config.fmu_files:
        return "a controller FMU of the user's (the prediction models the project's P law)"
    if ctrl.kind != "proportional":
        return f"the {ctrl.kind!r} law (the prediction models the P law)"
    if ctrl.params.mode != "unrestricted":
        return f"actuator mode {ctrl.params.mode!r} is not linear"
    if ctrl.params.gain_matrix:
        return "a MIMO gain matrix (the prediction models the same gain on every channel)"
    if config.scene.model != "full3d":
        return f"model {config.scene.model!r} has no lateral strain loop"
    if config.cosim.controller_ticks != 1:
        return "a controller sampling slower than the step (only single-rate loops are modelled)"
    return ""


#: Loop models of this process by plant and loop timing (:func:`loop_model`).
_MODELS: dict[str, LoopModel] = {}


def loop_model(config: SceneConfig) -> LoopModel:
    """:meth:`LoopModel.from_scene` of ``config``, one per plant and loop timing in a process
    (its discretizations and frequency responses are kept with it)."""
    st = config.cosim
    key = json.dumps([repr(config.scene.plant), st.algorithm, list(st.order), st.coupling,
                      st.sensor_delay, config.controller.params.lag_time_constant])
    if key not in _MODELS:
        if len(_MODELS) >= 8:
            _MODELS.pop(next(iter(_MODELS)))
        _MODELS[key] = LoopModel.from_scene(config)
    return _MODELS[key]


def point_prediction(config: SceneConfig) -> tuple[float, str]:
    """Predicted growth rate [1/s] of a point's configuration at its own gain, actuator delay and
    step, and "" ; or NaN and why the prediction does not apply."""
    why = unavailable(config)
    if why:
        return math.nan, f"prediction unavailable: {why}"
    try:
        lm = loop_model(config)
    except ConfigError as exc:
        return math.nan, f"prediction unavailable: {exc}"
    st = config.cosim
    with threadpool_limits(1):       # ~250 states: one BLAS thread is fastest
        return lm.growth_rate(config.controller.params.gain, st.actuator_delay, st.step), ""


def prediction_progress(total: int, progress: bool | None) -> tqdm:
    """The progress bar of a prediction (``progress`` None: only on a terminal)."""
    return tqdm(total=total, desc="linear prediction", unit="point",
                disable=None if progress is None else not progress)


def _model(scene: str, overrides: Mapping[str, Any] | None) -> LoopModel:
    return loop_model(load_config(scene, overrides))


def predicted_boundary(scene: str, steps: Sequence[float], delays: Sequence[float],
                       gain_range: tuple[float, float], overrides: Mapping[str, Any] | None = None,
                       rtol: float = 0.02, progress: tqdm | None = None
                       ) -> dict[float, list[tuple[float, float]]]:
    """Critical gain [N/strain] vs actuator delay [s] for each step [s].

    Returns
    -------
    dict
        ``{step: [(delay, critical_gain), ...]}``; ``inf`` where stable over the range,
        ``0`` where unstable at its low end.
    """
    lm = _model(scene, overrides)
    lo, hi = gain_range
    with threadpool_limits(1):
        return {float(h): list(zip(map(float, delays),
                                   critical_gains(lm, float(h), delays, gain_min=lo,
                                                  gain_max=hi, per_decade=2, rtol=rtol,
                                                  progress=progress)))
                for h in steps}


def predicted_curves(scene: str, gains: Sequence[float], steps: Sequence[float],
                     delays: Sequence[float], overrides: Mapping[str, Any] | None = None,
                     progress: tqdm | None = None) -> dict[tuple[float, float], list[float]]:
    """Growth rate [1/s] vs actuator delay [s] per (gain [N/strain], step [s]).

    Returns
    -------
    dict
        ``{(gain, step): [rate at each delay]}``.
    """
    lm = _model(scene, overrides)
    return {(float(k), float(h)): growth_rates(lm, [(k, d, h) for d in delays], progress)
            for h in steps for k in gains}
