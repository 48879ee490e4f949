"""Design a lateral controller on a scene's linearized plant and write it into a scene.

:func:`design_controller` linearizes the scene's plant with the chosen actuator sites
(:class:`.plant_model.LoopPlant`), designs at the scene's communication step (the controller's
sample period) and actuator delay, and returns a :class:`Design`: the controller as
:class:`controller.state_space.StateSpaceParams` (inputs ``strain<s>_<C|E>``, outputs
``actuator<s>_force_<C|E>``) and the closed loop's growth rate predicted on the design plant
(:func:`.closed_loop.growth_rate`). :func:`write_scene` writes the matrices (JSON,
:mod:`controller.state_space` format) and a scene that extends the base scene with the sites,
the step, the delay and ``[controller] kind = "state_space"``.

Kinds: ``"lqg"`` (:mod:`.lqg`) and ``"predictor"`` (the Smith predictor around the P law,
:mod:`.predictor`).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from drillcosim.controller.state_space import Signal, StateSpaceParams
from drillcosim.cosim.master.errors import UserError
from drillcosim.plant.scene import scenes_dir

from .closed_loop import growth_rate
from .lqg import LqgWeights, lqg_gains, lqg_matrices
from .plant_model import LoopPlant
from .predictor import gain_matrix, predictor_matrices

__all__ = ["KINDS", "MAX_FREQUENCY", "Design", "design_controller", "design_on_plant",
           "write_scene"]

KINDS = ("lqg", "predictor")
#: Modal truncation of the design model [rad/s] (:meth:`.plant_model.LoopPlant.truncated`):
#: every lateral bending mode of the paper's string, none of the shear modes above the gap.
MAX_FREQUENCY = 1000.0


@dataclass(frozen=True)
class Design:
    """A designed controller and what the design predicts.

    Attributes
    ----------
    kind : {"lqg", "predictor"}
    controller : StateSpaceParams
    delay : float
        Actuator delay designed for [s].
    joints : tuple of int
        Actuator joints (sites).
    scene : str
        The scene whose plant it was designed on (its source).
    settings : dict
        The design's parameters (weights, gain, truncation), for the record.
    growth_rate : float
        ln(rho) / H of the closed loop with the full linearized plant at ``delay`` [1/s]
        (< 0: stable); the design's verdict.
    design_growth_rate : float
        The same on the (truncated) design model.
    design_states : int
        States of the design model (the plant's modes kept, :data:`MAX_FREQUENCY`).
    """

    kind: str
    controller: StateSpaceParams
    delay: float
    joints: tuple[int, ...]
    scene: str
    settings: dict[str, Any] = field(default_factory=dict)
    growth_rate: float = math.nan
    design_growth_rate: float = math.nan
    design_states: int = 0

    @property
    def stable(self) -> bool:
        return self.growth_rate < 0

    def summary(self) -> str:
        c = self.controller
        return (f"{self.kind} controller for joints {list(self.joints)}: "
                f"{len(c.inputs)} strains -> {len(c.outputs)} forces, {c.n_states} states, "
                f"Ts = {c.sample_period:g} s, designed for an actuator delay of "
                f"{self.delay:g} s on a {self.design_states}-state model; closed loop with the "
                f"full linearized plant: growth {self.growth_rate:+.4g} 1/s "
                f"({'stable' if self.stable else 'UNSTABLE'}; design model "
                f"{self.design_growth_rate:+.4g} 1/s)")


def design_on_plant(kind: str, plant: LoopPlant, step: float, delay: float, *,
                    weights: LqgWeights | None = None, gain: float = 1e8,
                    relative_gains: Sequence[Sequence[float]] | None = None,
                    force_limit: float = math.inf,
                    max_frequency: float = MAX_FREQUENCY) -> Design:
    """Design on an already linearized plant (see :func:`design_controller`): on its modes
    up to ``max_frequency`` [rad/s] (``inf``: all), judged with all of them."""
    if kind not in KINDS:
        raise UserError(f"kind = {kind!r}; allowed: {', '.join(KINDS)}")
    for name, v in (("step", step), ("delay", delay)):
        if not (math.isfinite(v) and v >= 0) or (name == "step" and v == 0):
            raise UserError(f"{name} = {v!r} s; allowed: a finite number "
                             f"{'> 0' if name == 'step' else '>= 0'}")
    if not force_limit > 0:
        raise UserError(f"force_limit = {force_limit!r} N; allowed: > 0 (inf: none)")
    if not max_frequency > 0:
        raise UserError(f"max_frequency = {max_frequency!r} rad/s; allowed: > 0 (inf: no "
                        "truncation)")
    full = plant
    plant = full.truncated(max_frequency)
    strains, forces = plant.signals
    if kind == "lqg":
        weights = weights or LqgWeights()
        A, B, C, D = lqg_matrices(lqg_gains(plant, step, delay, weights))
        settings: dict[str, Any] = {k: getattr(weights, k) for k in weights.__dataclass_fields__}
        what = (f"LQG (LQR on the sampled plant with a {delay:g} s delay line, Kalman filter on "
                f"the strains; {settings})")
    else:
        if not (math.isfinite(gain) and gain >= 0):
            raise UserError(f"gain = {gain!r} N/strain; allowed: a finite number >= 0")
        K = gain_matrix(gain, plant.n_sites, relative_gains)
        A, B, C, D = predictor_matrices(plant, step, delay, K)
        settings = {"gain": gain, "relative_gains": None if relative_gains is None else
                    [list(map(float, r)) for r in relative_gains]}
        what = f"Smith predictor for a {delay:g} s delay around the P law, gain {gain:g} N/strain"
    settings["max_frequency"] = max_frequency
    ctrl = StateSpaceParams(
        A, B, C, D, tuple(Signal(s, "1") for s in strains),
        tuple(Signal(f, "N", -force_limit, force_limit) for f in forces), step,
        f"{what}; joints {list(plant.joints)}, designed on {Path(plant.source).name} "
        f"({plant.A.shape[0]} of its {full.A.shape[0]} states: modes up to "
        f"{max_frequency:g} rad/s)")
    return Design(kind, ctrl, float(delay), plant.joints, plant.source, settings,
                  growth_rate(full, ctrl, delay), growth_rate(plant, ctrl, delay),
                  plant.A.shape[0])


def design_controller(kind: str, scene: Any, *, per_span: int | None = None,
                      joints: Sequence[int] | None = None, delay: float | None = None,
                      step: float | None = None, overrides: Mapping[str, Any] | None = None,
                      **options: Any) -> Design:
    """Design a ``kind`` controller on a scene's linearized plant.

    Parameters
    ----------
    kind : {"lqg", "predictor"}
    scene : str or path
        Scene name or file.
    per_span : int, optional
        Sites per span, evenly spread (:func:`cosim.study.paper.conclusion.site_joints`).
    joints : sequence of int, optional
        Explicit actuator joints (instead of ``per_span``; default: the scene's).
    delay : float, optional
        Actuator delay to design for [s] (default: the scene's ``[cosim] actuator_delay``).
    step : float, optional
        Communication step = the controller's sample period [s] (default: the scene's).
    overrides : mapping, optional
        Scene keys by key path (e.g. ``{"bit.weight_on_bit": ...}``).
    **options
        ``weights`` (:class:`.lqg.LqgWeights`), ``gain``, ``relative_gains``, ``force_limit``,
        ``max_frequency`` (:func:`design_on_plant`).
    """
    from drillcosim.cosim.scenario.config import load_config
    from drillcosim.cosim.study.paper.conclusion import site_joints

    if per_span is not None and joints is not None:
        raise UserError("give per_span or joints, not both")
    ov = dict(overrides or {})
    if step is not None:
        ov["cosim.step"] = float(step)
    base = load_config(scene, ov)
    if per_span is not None:
        try:
            joints = site_joints(base.scene.plant, per_span)
        except ValueError as exc:
            raise UserError(f"--sites: {exc}") from None
    plant = LoopPlant.from_scene(scene, joints, ov)
    st = base.cosim
    return design_on_plant(kind, plant, st.step, st.actuator_delay if delay is None
                           else float(delay), **options)


def _toml_value(v: Any) -> str:
    if isinstance(v, str):
        return '"' + v.replace("\\", "\\\\").replace('"', '\\"') + '"'
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_toml_value(x) for x in v) + "]"
    return repr(float(v)) if isinstance(v, float) else str(v)


def write_scene(design: Design, out: str | Path, *, base: str | None = None,
                stop_time: float | None = None) -> tuple[Path, Path]:
    """Write ``out`` (a scene TOML) and ``<out stem>.json`` (the matrices) beside it.

    The scene extends ``base`` (default: the scene designed on), sets the actuator joints,
    the step and actuator delay designed for, and ``[controller] kind = "state_space"``,
    ``matrices = "<out stem>.json"`` (relative to the scene file).

    Returns
    -------
    (pathlib.Path, pathlib.Path)
        The scene and the matrices file.
    """
    out = Path(out)
    if out.suffix != ".toml":
        raise UserError(f"out = {str(out)!r}: a scene file name ending in .toml")
    matrices = out.with_suffix(".json")
    src = Path(design.scene)
    shipped = scenes_dir() / f"{src.stem}.toml"
    near = (shipped.is_file() and shipped.resolve() == src.resolve()) or (
        out.parent.resolve() == src.parent.resolve())
    extends = base or (src.stem if near else str(src.resolve()))
    c = design.controller
    what = {"lqg": "LQG", "predictor": "Smith predictor around the P law"}[design.kind]
    description = (f"{what} (drillcosim design {design.kind}) on joints "
                   f"{list(design.joints)}, designed for {design.delay * 1e3:g} ms of actuator "
                   f"delay at H = {c.sample_period * 1e3:g} ms: {c.n_states} states, closed loop "
                   f"with the linearized plant {design.growth_rate:+.3g} 1/s")
    settings = ", ".join(f"{k} = {v}" for k, v in design.settings.items() if v is not None)
    lines = [f"description = {_toml_value(description)}",
             f"extends = {_toml_value(extends)}",
             f"# written by drillcosim design {design.kind} from {src.name}: {settings}",
             f"# {design.summary()}", "", "[actuators]",
             f"joints = {_toml_value(list(design.joints))}", "", "[controller]",
             "enabled = true", 'kind = "state_space"',
             f"matrices = {_toml_value(matrices.name)}   # {c.n_states} states, "
             f"{len(c.inputs)} inputs, {len(c.outputs)} outputs", "", "[cosim]",
             f"step = {c.sample_period!r}", f"actuator_delay = {design.delay!r}"]
    if stop_time is not None:
        lines.append(f"stop_time = {float(stop_time)!r}")
    out.parent.mkdir(parents=True, exist_ok=True)
    c.save(matrices)
    out.write_text("\n".join(lines) + "\n")
    return out, matrices
