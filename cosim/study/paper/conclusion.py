"""The paper's conclusion tested: more actuation sites, lower gains, with actuator delay.

The paper concludes that more actuation sites per span with lower gains would control the
whirl better, and that delay limits the gain. This study runs the calibrated closed loop
(``paper_calibrated_closed_loop``) with 1, 2 or 3 sites per span (:func:`site_joints`), gains
:data:`GAINS` and actuator delays :data:`DELAYS` (0 to 2 ms at the 0.25 ms communication
step), through the one builder with its in-process engine
(:func:`cosim.scenario.build.build_system`, ``engine="inprocess"``: the FMUs built for a
layout give the same numbers, ``tests/test_conclusion_fmus.py``, at the cost of the FMI
boundary), and measures per point

* stability: ``status`` (diverged or not), the strain envelope's ``growth_rate`` [1/s]
  (:func:`cosim.study.point.metrics`), next to the linear prediction of the sampled loop
  (:class:`cosim.study.stability.LoopModel`, computed by :func:`predictions`);
* benefit: the long and short span's RMS radial deflection [m] over the steady window (last
  third of the run: :func:`cosim.study.scene_stats.run_statistics`, RMS = sqrt(mean^2 +
  std^2)) and contact time [s], against the gain-0 run of the same system (the first point)
  and the open loop's 12-member ensemble of the calibration's confirm stage
  (:mod:`cosim.study.paper.conclusion_report`).

Each point is one run (member 0, unperturbed); the open-loop ensemble gives the spread one
run has.
"""

from __future__ import annotations

import json
import math
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from drillcosim.cosim.master.files import atomic_write
from drillcosim.cosim.scenario.config import SceneConfig, load_config
from drillcosim.cosim.scenario.summary import span_info
from drillcosim.plant.model import DrillstringModel

from ..ensemble import lateral_perturbation
from ..point import PointOptions, metrics, simulate_point
from ..scene_stats import run_statistics
from ..stability import LoopModel
from ..sweep import execute_points
from ..table import ResultTable, full_row

__all__ = ["DELAYS", "ENSEMBLES", "EXTRA", "GAINS", "MEMBERS", "PER_SPAN", "SCENE",
           "ConclusionTable", "SitePoint", "conclusion_points", "measure_sites", "predictions",
           "run_conclusion", "site_config", "site_joints"]

SCENE = "paper_calibrated_closed_loop"
PER_SPAN = (1, 2, 3)
GAINS = (1e7, 1e8, 1e9)                             # N per unit strain
DELAYS = tuple(k * 2.5e-4 for k in range(9))        # s: 0 .. 2 ms
#: Extra (gain, delay) points: the question's 0.5 ms delay just below the predicted critical
#: gain of every site count (2.7e8 .. 3.7e8 N/strain), between the grid's 1e8 and 1e9.
EXTRA = ((2e8, 5e-4),)
#: Configurations (sites per span, gain, delay) run as ensembles of :data:`MEMBERS` (member 0
#: is the grid's run): the open-loop reference, the paper's layout at its gain without delay,
#: and the candidates of the question (0.5 ms).
ENSEMBLES = ((1, 0.0, 0.0), (1, 1e9, 0.0), (1, 2e8, 5e-4), (2, 1e8, 5e-4), (2, 2e8, 5e-4),
             (3, 1e8, 5e-4), (3, 2e8, 5e-4))
MEMBERS = 4
STEP = 2.5e-4                                       # s
STOP_TIME = 30.0                                    # s: the calibration's runs
STEADY_FRACTION = 1.0 / 3.0

RESULT_COLUMNS = ("status", "reason", "end_time", "wall_time", "joints", "growth_rate",
                  "growth_noise", "peak_force", "peak_power", "long_rms_m", "short_rms_m",
                  "long_peak_m", "long_contact_time_s", "short_contact_time_s")
ID_COLUMNS = ("key", "scene", "per_span", "gain", "delay", "step", "stop_time", "member")
EPS = 1e-6      # m: the calibration's ensemble perturbation
SEED = 2024


def site_joints(plant: Any, per_span: int) -> tuple[int, ...]:
    """``per_span`` actuator joints per span, evenly spread: at ``a + (b - a) k / (n + 1)``
    of each span ``(a, b)`` [m from the top], the joint below the body whose top is nearest
    (the scenes' rule for one site: below the span's middle body, 11 and 26 in the paper).

    Parameters
    ----------
    plant : plant.params.PlantParams
    per_span : int
        >= 1.

    Returns
    -------
    tuple of int
        1-based joints, top to bottom (e.g. 1: (11, 26); 2: (8, 14, 24, 28)).
    """
    if isinstance(per_span, bool) or not isinstance(per_span, int) or per_span < 1:
        raise ValueError(f"per_span = {per_span!r}: an integer >= 1")
    dx = plant.pipe.segment_length
    n = plant.pipe.n_segments
    out = []
    for a, b in plant.spans():
        for k in range(1, per_span + 1):
            z = a + (b - a) * k / (per_span + 1)
            out.append(min(max(int(round(z / dx)) + 1, 1), n - 1))
    if len(set(out)) != len(out):
        raise ValueError(f"per_span = {per_span}: two sites on one joint ({out}); the pipe "
                         f"has {n} segments")
    return tuple(out)


@dataclass(frozen=True)
class SitePoint:
    """One point: sites per span, gain [N/strain], actuator delay [s], step [s], and the
    ensemble member (0: unperturbed; else the initial lateral positions perturbed by
    :func:`cosim.study.ensemble.lateral_perturbation` with :data:`EPS`, :data:`SEED`)."""

    per_span: int
    gain: float
    delay: float
    step: float = STEP
    stop_time: float = STOP_TIME
    scene: str = SCENE
    member: int = 0

    @property
    def key(self) -> str:
        """Identity in the table."""
        return (f"{self.scene}|{self.per_span}|{self.gain:.6g}|{self.delay:.6g}|"
                f"{self.step:.6g}|{self.stop_time:.6g}"
                + (f"|m{self.member}" if self.member else ""))

    def kwargs(self) -> dict[str, Any]:
        """Arguments of :func:`measure_sites`."""
        return {"scene": self.scene, "per_span": self.per_span, "gain": self.gain,
                "delay": self.delay, "step": self.step, "stop_time": self.stop_time,
                "member": self.member}

    def identity(self) -> dict[str, Any]:
        """Identity columns of the row."""
        return {"key": self.key, "scene": self.scene, "per_span": float(self.per_span),
                "gain": self.gain, "delay": self.delay, "step": self.step,
                "stop_time": self.stop_time, "member": float(self.member)}


class ConclusionTable(ResultTable):
    """Results table of :class:`SitePoint` rows (no derived columns)."""

    columns = (*ID_COLUMNS, *RESULT_COLUMNS)
    text_columns = frozenset({"key", "scene", "status", "reason", "joints"})

    def derive(self, rows: Sequence[Mapping[str, Any]]) -> list[dict[str, Any]]:
        """Full rows (every column present)."""
        return [full_row(r, self.columns, self.text_columns) for r in rows]


def site_config(scene: str, per_span: int, gain: float, delay: float, step: float,
                stop_time: float) -> SceneConfig:
    """The configuration of a point (``actuators.joints`` from :func:`site_joints`, the
    controller on at ``gain``)."""
    plant = load_config(scene).scene.plant
    joints = site_joints(plant, per_span)
    over = {"controller.enabled": True, "controller.gain": float(gain), "cosim.step": float(step),
            "cosim.stop_time": float(stop_time), "cosim.actuator_delay": float(delay)}
    if joints != plant.actuator_joints:  # the scene's own layout needs no override (its FMUs)
        over["actuators.joints"] = list(joints)
    return load_config(scene, over)


def measure_sites(scene: str, per_span: int, gain: float, delay: float, step: float,
                  stop_time: float, member: int = 0) -> dict[str, Any]:
    """Run one point in process and measure it (module docstring; columns
    :data:`RESULT_COLUMNS`)."""
    wall0 = time.perf_counter()
    row = measure_config(site_config(scene, per_span, gain, delay, step, stop_time), member)
    row["wall_time"] = time.perf_counter() - wall0
    return row


def measure_config(config: SceneConfig, member: int = 0) -> dict[str, Any]:
    """Run a configuration in process (ensemble ``member``: 0 unperturbed) and measure it:
    status, reason, end time, joints, growth rate and noise, peak force and power, long/short
    RMS radial deflection over the last third, long-span peak, contact times (no wall time)."""
    offset = None
    if member:
        model = DrillstringModel(config.scene.plant, "full3d")
        offset = lateral_perturbation(model, EPS, SEED, member)
    opts = PointOptions(rms_fraction=STEADY_FRACTION)
    data, reason = simulate_point(config, opts, "inprocess", None, offset)
    t = data["time"]
    diverged = bool(reason)
    spans = {b: str(v["span"]) for b, v in span_info(config.scene).items()}
    m = metrics(data, spans, config.n_sites, opts, diverged)
    st = run_statistics(data, config) if not diverged else {}
    row: dict[str, Any] = {
        "status": "diverged" if diverged else "ok", "reason": reason,
        "end_time": float(t[-1]) if len(t) else 0.0,
        "joints": " ".join(str(j) for j in config.scene.plant.actuator_joints),
        "growth_rate": m["growth_rate"], "growth_noise": m["growth_noise"],
        "peak_force": m["peak_force"], "peak_power": m["peak_power"]}
    for span in ("long", "short"):
        mean, std = st.get(f"{span}_mean_m", math.nan), st.get(f"{span}_std_m", math.nan)
        row[f"{span}_rms_m"] = math.hypot(mean, std)
    row["long_peak_m"] = m["peak_deflection_long"]
    row["long_contact_time_s"] = st.get("long_contact_time_s", math.nan)
    row["short_contact_time_s"] = st.get("short_contact_time_s", math.nan)
    return row


def conclusion_points(per_span: Sequence[int] = PER_SPAN, gains: Sequence[float] = GAINS,
                      delays: Sequence[float] = DELAYS, *, step: float = STEP,
                      stop_time: float = STOP_TIME, scene: str = SCENE,
                      members: int = MEMBERS) -> list[SitePoint]:
    """The open-loop reference (gain 0: the same system, forces zero), the grid by delay then
    gain (the unstable corner last), then members 1..members-1 of :data:`ENSEMBLES`."""
    grid = [(g, d) for d in delays for g in gains] + [e for e in EXTRA if e[1] in delays]
    pts = [SitePoint(1, 0.0, 0.0, step, stop_time, scene)] + [
        SitePoint(n, float(g), float(d), step, stop_time, scene)
        for g, d in grid for n in per_span]
    return pts + [SitePoint(n, float(g), float(d), step, stop_time, scene, k)
                  for n, g, d in ENSEMBLES if n in per_span and d in delays
                  for k in range(1, members)]


def predictions(per_span: Sequence[int] = PER_SPAN, gains: Sequence[float] = GAINS,
                delays: Sequence[float] = DELAYS, *, step: float = STEP, scene: str = SCENE
                ) -> list[dict[str, float]]:
    """The linear prediction of the sampled loop per point: ``growth_rate`` [1/s]
    (``ln(rho) / H``) and the critical gain [N/strain] at each delay."""
    pairs = [(g, d) for d in delays for g in gains] + [e for e in EXTRA if e[1] in delays]
    out = []
    for n in per_span:
        lm = LoopModel.from_scene(site_config(scene, n, 1.0, 0.0, step, STOP_TIME))
        kc = {d: lm.critical_gain(step, float(d), gain_min=1e5, gain_max=1e11, per_decade=4)
              for d in delays}
        for g, d in pairs:
            out.append({"per_span": float(n), "gain": float(g), "delay": float(d),
                        "predicted_growth_rate": lm.growth_rate(float(g), float(d), step),
                        "critical_gain": kc[d]})
    return out


def run_conclusion(out_dir: str | Path, *, workers: int | None = None, scheduler: Any = None,
                   progress: bool | None = None, points: Sequence[SitePoint] | None = None
                   ) -> list[dict[str, Any]]:
    """Run (or resume) the grid into ``out_dir`` and write ``prediction.json``; returns rows."""
    pts = list(points) if points is not None else conclusion_points()
    table = ConclusionTable(out_dir)
    meta = {"scene": SCENE, "engine": "inprocess (cosim.scenario.build.build_system)",
            "per_span": list(PER_SPAN),
            "gains": list(GAINS), "delays_s": list(DELAYS), "step_s": STEP,
            "stop_time_s": STOP_TIME, "steady_fraction": STEADY_FRACTION}
    execute_points(pts, table, measure_sites, workers=workers, scheduler=scheduler,
                   progress=progress, desc="conclusion", meta={"conclusion.json": meta})
    pred = Path(out_dir) / "prediction.json"
    need = {(float(p.per_span), p.gain, p.delay) for p in pts if p.gain > 0}
    have = {(r["per_span"], r["gain"], r["delay"]) for r in json.loads(pred.read_text())} \
        if pred.exists() else set()
    if not need <= have:
        spans = sorted({p.per_span for p in pts if p.gain > 0})
        gains = sorted({p.gain for p in pts if p.gain > 0})
        delays = sorted({p.delay for p in pts})
        atomic_write(pred, json.dumps(predictions(spans, gains, delays), indent=1) + "\n")
    keys = {p.key for p in pts}
    return [r for r in table.rows if r["key"] in keys]
