"""The linear-regime check of the comparison: does the co-simulation grow (or not) at the rate
the linear model predicts? (``drillcosim design compare --linear``, ``docs/control_design.md``.)

Each point is one law (:data:`.compare.FAMILIES`: the P law, the Smith predictor and LQG, the
designed ones designed for the point's delay) at one actuator delay, on the calibrated plant
with the paper's sites (1 per span) at H = 0.25 ms. The run starts at the rotary speed of the
linearization (``top_drive.ramp_time = 0``) and lasts :data:`STOP_TIME`: long enough for the
loop's unstable mode to dominate, short enough to stay linear. Only the run's **linear part**
is judged (:func:`linear_part`): up to the first wall contact or radial deflection beyond
:data:`LINEAR_FRACTION` of the clearance. Its growth rate is the slope of the log envelope of
the high-passed strains (:func:`cosim.study.point.metrics`, windows of :data:`WINDOW`) over the
last half of that part; the prediction is ``ln(rho) / H`` of the closed loop of the full
linearized plant (240 states) with the same controller at the same delay
(:func:`.closed_loop.growth_rate`).

What agrees: an unstable loop grows at the predicted rate (its one dominant mode); a stable
loop shows no growth. The decay rate of a stable loop is *not* comparable: the prediction's
slowest mode sits below the high-pass (a slow whirl), the fit sees the faster ones.
"""

from __future__ import annotations

import json
import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from drillcosim.cosim.master.files import atomic_write
from drillcosim.cosim.scenario.summary import span_info

from ..point import PointOptions, metrics, simulate_point
from .closed_loop import growth_rate
from .compare import FAMILIES, SCENE, STEP, _loop_plant, point_config

__all__ = ["DELAYS", "LAWS", "STOP_TIME", "linear_part", "linear_point", "linear_table",
           "markdown", "plot"]

LAWS = ("p1e9", "pred1e9", "lqg3e-6")
DELAYS = (0.0, 2.5e-4, 5e-4, 7.5e-4, 1e-3, 1.5e-3, 2e-3)   # s
STOP_TIME = 1.5                  # s
LINEAR_FRACTION = 0.25           # of the clearance
WINDOW = 0.05                    # s: envelope windows (the loop modes: 100s of rad/s)
DESIGN_DELAY = 5e-4              # s: the shipped scenes' design delay
MIN_LINEAR = 0.3                 # s: a shorter linear part gives no rate
LINEAR_FILE = "linear.json"
LABEL = {"p1e9": "P 1e9", "pred1e9": "predictor 1e9", "lqg3e-6": "LQG"}


def linear_part(data: np.ndarray, clearance: float) -> float:
    """End [s] of a run's linear part: the first sample with a wall contact force or a radial
    deflection above ``LINEAR_FRACTION * clearance`` [m] (the run's end if none)."""
    t = np.asarray(data["time"], dtype=float)
    hit = np.zeros(len(t), dtype=bool)
    for name in data.dtype.names:
        if name.endswith("_contact_force"):
            hit |= np.asarray(data[name]) != 0.0
        elif name.endswith("_radial_deflection"):
            hit |= np.asarray(data[name]) > LINEAR_FRACTION * clearance
    return float(t[np.argmax(hit)]) if hit.any() else float(t[-1]) if len(t) else 0.0


def linear_point(family: str, delay: float, design_dir: str | Path, *,
                 engine: str = "inprocess", fmu_dir: str | Path | None = None,
                 design_delay: float | None = None, per_span: int = 1, step: float = STEP,
                 stop_time: float = STOP_TIME) -> dict[str, Any]:
    """Predict and co-simulate one law at one actuator delay [s], designed for
    ``design_delay`` [s] (default: ``delay``, a known delay).

    Returns
    -------
    dict
        ``family``, ``delay`` [s], ``design_delay`` [s], ``engine``, ``predicted`` [1/s],
        ``simulated`` [1/s] and its standard error ``noise`` (NaN: linear part shorter
        than :data:`MIN_LINEAR`), ``linear_until`` [s], ``reason`` (why the run stopped
        early, "" if it did not),
        ``peak_force`` [N] over the linear part.
    """
    designed = delay if design_delay is None else design_delay
    config, controller, _ = point_config(family, per_span, designed, step, "nominal",
                                         stop_time, design_dir,
                                         {"top_drive.ramp_time": 0.0,
                                          "cosim.actuator_delay": delay})
    plant = _loop_plant(SCENE, tuple(config.scene.plant.actuator_joints), step, "{}")
    predicted = growth_rate(plant, controller, delay)
    opts = PointOptions(envelope_window=WINDOW, fit_fraction=0.5)
    data, reason = simulate_point(config, opts, engine, None if fmu_dir is None
                                  else str(fmu_dir))
    until = linear_part(data, config.scene.plant.contact.clearance)
    part = data[np.asarray(data["time"]) <= until]
    spans = {b: str(v["span"]) for b, v in span_info(config.scene).items()}
    m = metrics(part, spans, config.n_sites, opts, True)
    ok = until >= MIN_LINEAR
    return {"family": family, "delay": float(delay), "design_delay": float(designed),
            "engine": engine,
            "predicted": float(predicted),
            "simulated": m["growth_rate"] if ok else math.nan,
            "noise": m["growth_noise"] if ok else math.nan, "linear_until": until,
            "reason": reason, "peak_force": m["peak_force"]}


def linear_table(out_dir: str | Path, *, laws: Sequence[str] = LAWS,
                 delays: Sequence[float] = DELAYS,
                 design_delays: Sequence[float | None] = (None, DESIGN_DELAY),
                 engines: Sequence[str] = ("inprocess", "fmu"),
                 fmu_dir: str | Path | None = None, progress: bool | None = None
                 ) -> list[dict[str, Any]]:
    """Every law x delay x design delay (None: the run's) x engine (:func:`linear_point`;
    the P law has no design: once per delay); written to ``out_dir/linear.json``. The
    ``fmu`` engine runs the designs for a fixed delay only (a design per delay would build an
    FMU per point)."""
    from tqdm import tqdm

    out = Path(out_dir)
    design_dir = out / "designs"
    jobs: list[tuple[str, float, float, str]] = []
    for e in engines:
        for f in laws:
            p = FAMILIES[f].kind == "p"
            for dd in (None,) if p else design_delays:
                if e == "fmu" and dd is None and not p:
                    continue
                jobs += [(f, d, d if dd is None else dd, e) for d in delays
                         if (f, d, d if dd is None else dd, e) not in jobs]
    rows = [linear_point(f, d, design_dir, engine=e, design_delay=dd, fmu_dir=fmu_dir)
            for f, d, dd, e in tqdm(jobs, desc="linear", disable=progress is False)]
    out.mkdir(parents=True, exist_ok=True)
    atomic_write(out / LINEAR_FILE, json.dumps(rows, indent=1) + "\n")
    return rows


def load_linear(out_dir: str | Path) -> list[dict[str, Any]]:
    """The rows :func:`linear_table` wrote (empty: none yet)."""
    path = Path(out_dir) / LINEAR_FILE
    return json.loads(path.read_text()) if path.is_file() else []


def _series(rows: Sequence[dict[str, Any]], family: str, engine: str, fixed: bool
            ) -> list[dict[str, Any]]:
    """One law's rows of one engine, by delay: designed for the run's delay (``fixed``
    False) or for :data:`DESIGN_DELAY` (True; the P law: both)."""
    p = FAMILIES[family].kind == "p"
    sel = [r for r in rows if r["family"] == family and r["engine"] == engine and (
        p or math.isclose(r["design_delay"], DESIGN_DELAY if fixed else r["delay"]))]
    return sorted(sel, key=lambda r: r["delay"])


def _rate(x: float, noise: float = math.nan) -> str:
    if not math.isfinite(x):
        return "-"
    return f"{x:+.2f}" + (f" +- {noise:.2f}" if math.isfinite(noise) else "")


def markdown(rows: Sequence[dict[str, Any]]) -> str:
    """The table: per delay and law, the predicted and co-simulated growth rate [1/s]."""
    lines = []
    for fixed in (False, True):
        what = (f"designed for {DESIGN_DELAY * 1e3:g} ms, run at the delay shown" if fixed
                else "designed for the delay shown (a known delay)")
        lines += [f"Growth rate [1/s], predicted / co-simulated in process (+- the fit's "
                  f"standard error) / through the FMUs; predictor and LQG {what}:", "",
                  "| delay [ms] | " + " | ".join(f"{LABEL[f]} pred. | sim. | FMU"
                                                 for f in LAWS) + " |",
                  "|---|" + "---|---|---|" * len(LAWS)]
        series = {(f, e): {round(r["delay"], 9): r for r in _series(rows, f, e, fixed)}
                  for f in LAWS for e in ("inprocess", "fmu")}
        for d in sorted({round(r["delay"], 9) for r in rows}):
            cells = []
            for f in LAWS:
                r, q = series[(f, "inprocess")].get(d), series[(f, "fmu")].get(d)
                cells += [_rate(r["predicted"]) if r else "",
                          _rate(r["simulated"], r["noise"]) if r else "",
                          ("=" if q and r and q["simulated"] == r["simulated"] else
                           _rate(q["simulated"])) if q else ""]
            lines.append(f"| {d * 1e3:g} | " + " | ".join(cells) + " |")
        lines.append("")
    return "\n".join(lines)


def plot(rows: Sequence[dict[str, Any]], path: str | Path) -> Path:
    """Predicted (lines) and co-simulated (markers) growth rate vs delay, one panel per
    design mode."""
    import matplotlib.pyplot as plt

    from drillcosim.cosim.scenario.plots import save_figure

    fig, axes = plt.subplots(1, 2, figsize=(9.0, 3.6), sharey=True, layout="constrained")
    for ax, fixed in zip(axes, (False, True)):
        for f, c in zip(LAWS, ("C3", "C0", "C2")):
            s = _series(rows, f, "inprocess", fixed)
            x = [r["delay"] * 1e3 for r in s]
            ax.plot(x, [r["predicted"] for r in s], color=c, lw=1.2,
                    label=f"{LABEL[f]}: linear model")
            ax.plot(x, [r["simulated"] for r in s], "o", color=c, mfc="none",
                    label=f"{LABEL[f]}: co-simulation")
        ax.axhline(0.0, color="k", lw=0.6)
        ax.set_xlabel("actuator delay [ms]")
        ax.set_title("predictor, LQG designed for " + (f"{DESIGN_DELAY * 1e3:g} ms" if fixed
                                                      else "the delay (known)"), fontsize=9)
    axes[0].set_ylabel("growth rate of the strain envelope [1/s]")
    axes[0].legend(fontsize=7)
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    return save_figure(fig, Path(path))
