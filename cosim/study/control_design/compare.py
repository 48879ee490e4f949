"""The comparison study: the P law, the Smith predictor and LQG at the same sites, over actuator
delay, co-simulated and predicted (``drillcosim design compare``, ``docs/control_design.md``).

Every point is one co-simulation of the calibrated closed loop (:data:`SCENE`, Gauss-Seidel,
controller first, 30 s from rest, the in-process slaves with the master's native loop:
:func:`cosim.scenario.build.build_system` with ``engine="inprocess"``) and its linear
prediction:

* the *family* (:data:`FAMILIES`) fixes the controller: the P law at a gain, the predictor
  around the P law at that gain, or LQG at a set of weights; a designed controller
  (:func:`.design.design_on_plant`, on the truncated linearized plant of the design scene with
  the point's sites and step) is designed **for the point's actuator delay** (a known delay)
  and kept in the study folder (``designs/``: designs do not change with the run plant);
* sites per span (:func:`cosim.study.paper.conclusion.site_joints`), actuator delay and step;
* the *variant* (:data:`VARIANTS`): the nominal run, or a robustness case - another run plant
  (the default plant, the weight on bit +-50 %, a 5 mm clearance so the wall contact stays
  active under control), a design on the default plant run on the calibrated one, or the
  actual delay 0.5x / 1.5x the delay designed for;
* the ensemble member (0: unperturbed; else the initial lateral positions perturbed by
  :func:`cosim.study.ensemble.lateral_perturbation`, as in the paper study).

Measured per point (:func:`measure_control`): status, the high-passed strain envelope's growth
rate (:func:`cosim.study.point.metrics`), the long/short span RMS radial deflection over the
last third, contact time, peak actuator force and power; predicted: the growth rate
``ln(rho) / H`` of the closed loop of the run plant's full linearization with the controller at
the run's delay (:func:`.closed_loop.growth_rate`; the P law as the static gain ``D = K``).
The open-loop points (family ``open``, one per run plant and step, 4 members) are the
references of the verdicts and the benefits (:mod:`.compare_report`).

The table is resumable (:class:`cosim.study.table.ResultTable`): a killed study resumes; the
rows do not depend on the order the points finished in.
"""

from __future__ import annotations

import functools
import json
import math
import os
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from drillcosim.controller.state_space import (
    Signal,
    StateSpaceParams,
    load_state_space,
)
from drillcosim.cosim.master.files import atomic_write
from drillcosim.cosim.scenario.config import SceneConfig, load_config

from ..paper.conclusion import measure_config, site_joints
from ..sweep import execute_points
from ..table import ResultTable, full_row
from .closed_loop import growth_rate
from .design import design_on_plant
from .lqg import LqgWeights
from .plant_model import LoopPlant
from .predictor import gain_matrix

__all__ = ["DELAYS", "DELAYS_1MS", "FAMILIES", "SCENE", "VARIANTS", "CompareTable", "Family",
           "ComparePoint", "compare_points", "measure_control", "run_compare"]

SCENE = "paper_calibrated_closed_loop"
DEFAULT_SCENE = "paper_closed_loop"     # the default (uncalibrated) plant, same loop settings
PER_SPAN = (1, 2, 3)
STEP = 2.5e-4                                   # s
STEP_1MS = 1e-3                                 # s
DELAYS = tuple(k * 2.5e-4 for k in range(9))    # s: 0 .. 2 ms at H = 0.25 ms
DELAYS_1MS = tuple(k * 5e-4 for k in range(5))  # s: 0 .. 2 ms at H = 1 ms
STOP_TIME = 30.0                                # s: the paper study's runs
STEADY_FRACTION = 1.0 / 3.0
MEMBERS = 4
WOB = 18277.5                                   # N: the calibrated weight on bit


@dataclass(frozen=True)
class Family:
    """A controller family: ``kind`` ``"p"`` (the P law), ``"predictor"``, ``"lqg"`` or
    ``"open"``; ``gain`` [N/strain] (P law, predictor); ``weights`` (LQG)."""

    kind: str
    gain: float = 0.0
    weights: LqgWeights | None = None

    def describe(self) -> str:
        if self.kind == "lqg":
            w = self.weights
            return (f"LQG (d0 = {w.deflection_scale:g} m, F0 = {w.force_scale:g} N, force noise "
                    f"{w.force_noise:g} N, strain noise {w.strain_noise:g})")
        return {"p": f"P law, gain {self.gain:.0e}", "open": "open loop",
                "predictor": f"Smith predictor around the P law, gain {self.gain:.0e}"
                }[self.kind]


#: The families compared. The P law and the predictor at the conclusion study's gains (1e9:
#: the paper's; 1e8: the conclusion's 3-site answer); LQG with the regulator of Bryson's
#: scaling d0 = 1 mm, F0 = 100 kN and two Kalman filters: strain noise 3e-6 (robust to the
#: rotary speed and the axial load) and 1e-6 (faster, less robust).
FAMILIES: dict[str, Family] = {
    "open": Family("open"),
    "p1e8": Family("p", 1e8),
    "p1e9": Family("p", 1e9),
    "pred1e8": Family("predictor", 1e8),
    "pred1e9": Family("predictor", 1e9),
    "lqg3e-6": Family("lqg", weights=LqgWeights(1e-3, 1e5, 1.0, 3e-6)),
    "lqg1e-6": Family("lqg", weights=LqgWeights(1e-3, 1e5, 1.0, 1e-6)),
}

#: Robustness variants: (run-plant overrides, design scene, run delay / design delay).
VARIANTS: dict[str, tuple[dict[str, Any], str, float]] = {
    "nominal": ({}, SCENE, 1.0),
    "default_plant": ({}, SCENE, 1.0),          # run on DEFAULT_SCENE (see run_scene)
    "wob-50": ({"bit.weight_on_bit": 0.5 * WOB}, SCENE, 1.0),
    "wob+50": ({"bit.weight_on_bit": 1.5 * WOB}, SCENE, 1.0),
    "clearance5mm": ({"contact.clearance": 0.005}, SCENE, 1.0),
    "design_default": ({}, DEFAULT_SCENE, 1.0),
    "delay_x0.5": ({}, SCENE, 0.5),
    "delay_x1.5": ({}, SCENE, 1.5),
}
#: Variants that change the run plant (they have their own open-loop reference).
PLANT_VARIANTS = ("nominal", "default_plant", "wob-50", "wob+50", "clearance5mm")


def run_scene(variant: str) -> str:
    """The scene a variant runs."""
    return DEFAULT_SCENE if variant == "default_plant" else SCENE


def reference_variant(variant: str) -> str:
    """The variant whose open loop is ``variant``'s reference (the same run plant)."""
    return variant if variant in PLANT_VARIANTS else "nominal"


@dataclass(frozen=True)
class ComparePoint:
    """One point: family, sites per span, the delay designed for [s], step [s], variant,
    member, stop time [s]."""

    family: str
    per_span: int
    delay: float
    step: float = STEP
    variant: str = "nominal"
    member: int = 0
    stop_time: float = STOP_TIME

    @property
    def run_delay(self) -> float:
        """The actual actuator delay of the run [s]."""
        return self.delay * VARIANTS[self.variant][2]

    @property
    def key(self) -> str:
        return (f"{self.family}|{self.per_span}|{self.delay:.6g}|{self.step:.6g}|"
                f"{self.variant}|{self.stop_time:.6g}" + (f"|m{self.member}" if self.member
                                                          else ""))

    def kwargs(self) -> dict[str, Any]:
        return {"family": self.family, "per_span": self.per_span, "delay": self.delay,
                "step": self.step, "variant": self.variant, "member": self.member,
                "stop_time": self.stop_time}

    def identity(self) -> dict[str, Any]:
        return {"key": self.key, "family": self.family, "kind": FAMILIES[self.family].kind,
                "per_span": float(self.per_span), "delay": self.delay,
                "run_delay": self.run_delay, "step": self.step, "variant": self.variant,
                "member": float(self.member), "stop_time": self.stop_time}


ID_COLUMNS = ("key", "family", "kind", "per_span", "delay", "run_delay", "step", "variant",
              "member", "stop_time")
RESULT_COLUMNS = ("status", "reason", "end_time", "wall_time", "joints", "growth_rate",
                  "growth_noise", "peak_force", "peak_power", "long_rms_m", "short_rms_m",
                  "long_peak_m", "long_contact_time_s", "short_contact_time_s",
                  "predicted_growth_rate", "design_growth_rate", "controller_states")


class CompareTable(ResultTable):
    """Results of :class:`ComparePoint` rows (no derived columns: :mod:`.compare_report`)."""

    columns = (*ID_COLUMNS, *RESULT_COLUMNS)
    text_columns = frozenset({"key", "family", "kind", "variant", "status", "reason", "joints"})

    def derive(self, rows: Sequence[Mapping[str, Any]]) -> list[dict[str, Any]]:
        return [full_row(r, self.columns, self.text_columns) for r in rows]


# -- the controller of a point ---------------------------------------------------------------
@functools.lru_cache(maxsize=16)
def _loop_plant(scene: str, joints: tuple[int, ...], step: float, overrides: str) -> LoopPlant:
    """The linearized plant (cached per process: a linearization takes ~1 s)."""
    return LoopPlant.from_scene(scene, joints, {**json.loads(overrides), "cosim.step": step})


def _p_law(joints: Sequence[int], gain: float, step: float) -> StateSpaceParams:
    """The P law as a static state-space law (``D = gain I``), for the prediction."""
    from .plant_model import site_signals

    strains, forces = site_signals(len(joints))
    return StateSpaceParams([], [], [], gain_matrix(gain, len(joints)),
                            [Signal(s) for s in strains], [Signal(f, "N") for f in forces],
                            step, f"P law, gain {gain:g}")


def _design(family: Family, scene: str, joints: tuple[int, ...], step: float, delay: float,
            folder: Path) -> tuple[Path, float]:
    """The family's controller designed on ``scene`` for ``delay`` (kept in ``folder``): its
    file and its growth rate on the design model [1/s]."""
    w = family.weights
    tuning = f"{family.gain:.6g}" if w is None else (
        f"{w.deflection_scale:g}_{w.force_scale:g}_{w.force_noise:g}_{w.strain_noise:g}")
    name = (f"{family.kind}_{tuning}_{scene}_{'-'.join(map(str, joints))}_{step:.6g}_"
            f"{delay:.6g}")
    path = folder / f"{name}.json"
    meta = folder / f"{name}.meta.json"
    if path.is_file() and meta.is_file():
        return path, json.loads(meta.read_text())["design_growth_rate"]
    plant = _loop_plant(scene, joints, step, "{}")
    options = ({"weights": family.weights} if family.kind == "lqg" else {"gain": family.gain})
    d = design_on_plant(family.kind, plant, step, delay, **options)
    folder.mkdir(parents=True, exist_ok=True)
    atomic_write(path, json.dumps(d.controller.to_mapping(), separators=(",", ":")) + "\n")
    atomic_write(meta, json.dumps({"design_growth_rate": d.design_growth_rate,
                                   "full_growth_rate": d.growth_rate}) + "\n")
    return path, d.design_growth_rate


def point_config(family: str, per_span: int, delay: float, step: float, variant: str,
                 stop_time: float, design_dir: str | Path,
                 extra: Mapping[str, Any] | None = None
                 ) -> tuple[SceneConfig, StateSpaceParams | None, float]:
    """The configuration of a point (``extra``: further scene keys by key path), its
    controller as a state-space law (None: open loop) and the design model's growth rate
    (NaN: none)."""
    fam = FAMILIES[family]
    overrides, design_scene, _ratio = VARIANTS[variant]
    scene = run_scene(variant)
    plant = load_config(SCENE).scene.plant
    joints = site_joints(plant, per_span)
    run_delay = delay * VARIANTS[variant][2]
    over = {**overrides, "cosim.step": step, "cosim.stop_time": stop_time,
            "cosim.actuator_delay": run_delay, **(extra or {})}
    if tuple(joints) != tuple(plant.actuator_joints):  # (the FMU engine takes scalars only)
        over["actuators.joints"] = list(joints)
    controller, design_rate = None, math.nan
    if fam.kind == "open":
        over["controller.enabled"] = False
    elif fam.kind == "p":
        over.update({"controller.enabled": True, "controller.gain": fam.gain})
        controller = _p_law(joints, fam.gain, step)
    else:
        path, design_rate = _design(fam, design_scene, joints, step, delay,
                                    Path(design_dir).resolve())
        over.update({"controller.enabled": True, "controller.kind": "state_space",
                     "controller.matrices": str(path)})
        controller = load_state_space(path)
    return load_config(scene, over), controller, design_rate


def measure_control(family: str, per_span: int, delay: float, step: float, variant: str,
                    member: int, stop_time: float, design_dir: str) -> dict[str, Any]:
    """Design (or take the kept design), predict, run and measure one point (columns
    :data:`RESULT_COLUMNS`)."""
    wall0 = time.perf_counter()
    config, controller, design_rate = point_config(family, per_span, delay, step, variant,
                                                   stop_time, design_dir)
    predicted = math.nan
    if controller is not None:
        joints = tuple(config.scene.plant.actuator_joints)
        plant = _loop_plant(run_scene(variant), joints, step,
                            json.dumps(VARIANTS[variant][0], sort_keys=True))
        predicted = growth_rate(plant, controller, config.cosim.actuator_delay)
    row = measure_config(config, member)
    row.update({"predicted_growth_rate": predicted, "design_growth_rate": design_rate,
                "controller_states": float(controller.n_states) if controller is not None
                else 0.0})
    row["wall_time"] = time.perf_counter() - wall0
    return row


@dataclass(frozen=True)
class _Bound:
    """A point bound to the study folder (the design cache): what the executor runs."""

    point: ComparePoint
    design_dir: str

    @property
    def key(self) -> str:
        return self.point.key

    def kwargs(self) -> dict[str, Any]:
        return {**self.point.kwargs(), "design_dir": self.design_dir}

    def identity(self) -> dict[str, Any]:
        return self.point.identity()


# -- the study's points ----------------------------------------------------------------------
#: Configurations (family, sites per span, delay) run as ensembles of :data:`MEMBERS` at
#: H = 0.25 ms (member 0 is the grid's run): the candidates of the answer.
ENSEMBLES = (("p1e9", 1, 0.0), ("p1e8", 3, 5e-4), ("p1e8", 3, 1.5e-3),
             ("pred1e9", 1, 5e-4), ("pred1e9", 1, 2e-3), ("pred1e8", 3, 5e-4),
             ("pred1e8", 3, 2e-3), ("lqg3e-6", 1, 5e-4), ("lqg3e-6", 1, 2e-3),
             ("lqg1e-6", 1, 5e-4))
#: Robustness: sites per span and delays designed for, at H = 0.25 ms.
ROBUST_SITES = (1, 3)
ROBUST_DELAYS = (5e-4, 2e-3)


def compare_points(*, families: Sequence[str] | None = None,
                   per_span: Sequence[int] = PER_SPAN, members: int = MEMBERS,
                   stop_time: float = STOP_TIME, robustness: bool = True,
                   step_1ms: bool = True) -> list[ComparePoint]:
    """The study's points: the open-loop references, the nominal grid (every family x sites x
    delay at H = 0.25 ms and at H = 1 ms), the robustness variants, the ensembles."""
    fams = [f for f in (families or FAMILIES) if f != "open"]
    steps = [(STEP, DELAYS)] + ([(STEP_1MS, DELAYS_1MS)] if step_1ms else [])
    pts: list[ComparePoint] = []
    ref_variants = PLANT_VARIANTS if robustness else ("nominal",)
    for step, _ in steps:
        for v in (ref_variants if step == STEP else ("nominal",)):
            pts += [ComparePoint("open", 1, 0.0, step, v, k, stop_time) for k in range(members)]
    for step, delays in steps:
        pts += [ComparePoint(f, n, d, step, "nominal", 0, stop_time)
                for d in delays for f in fams for n in per_span]
    if robustness:
        for f in fams:
            kind = FAMILIES[f].kind
            variants = [v for v in VARIANTS if v != "nominal"
                        and (kind != "p" or v in PLANT_VARIANTS)]
            pts += [ComparePoint(f, n, d, STEP, v, 0, stop_time)
                    for v in variants for n in ROBUST_SITES if n in per_span
                    for d in ROBUST_DELAYS]
    pts += [ComparePoint(f, n, d, STEP, "nominal", k, stop_time)
            for f, n, d in ENSEMBLES if f in fams and n in per_span
            for k in range(1, members)]
    return pts


def run_compare(out_dir: str | Path, *, workers: int | None = 1, scheduler: Any = None,
                progress: bool | None = None, points: Sequence[ComparePoint] | None = None
                ) -> list[dict[str, Any]]:
    """Run (or resume) the study into ``out_dir`` (``results.csv``, ``designs/``); returns
    the rows of ``points`` (default :func:`compare_points`)."""
    pts = list(points) if points is not None else compare_points()
    out = Path(out_dir)
    table = CompareTable(out)
    design_dir = str((out / "designs").resolve())
    meta = {"scene": SCENE, "default_scene": DEFAULT_SCENE,
            "engine": "inprocess (cosim.scenario.build.build_system)",
            "families": {k: v.describe() for k, v in FAMILIES.items()},
            "variants": {k: {"overrides": v[0], "design_scene": v[1], "delay_ratio": v[2]}
                         for k, v in VARIANTS.items()},
            "stop_time_s": STOP_TIME, "steady_fraction": STEADY_FRACTION,
            "cpu_count": os.cpu_count()}
    execute_points([_Bound(p, design_dir) for p in pts], table, measure_control,
                   workers=workers, scheduler=scheduler, progress=progress, desc="compare",
                   meta={"compare.json": meta})
    keys = {p.key for p in pts}
    return [r for r in table.rows if r["key"] in keys]
