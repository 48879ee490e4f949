"""Maps and tables of the conclusion study (:mod:`cosim.study.paper.conclusion`).

* ``conclusion_stability.png``: per sites-per-span panel, each (delay, gain) point's verdict
  from the simulation (:func:`cosim.study.verdict.judge` against the gain-0 run of the same
  system) as a marker, and the linear prediction's critical gain vs delay as a line;
* ``conclusion_benefit.png``: the long span's benefit ``1 - RMS / RMS_open`` (top row) and
  contact time (bottom row) per point, unstable points crossed out;
* ``conclusion.csv``: the rows with verdict, prediction and benefit.
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from drillcosim.cosim.master.files import atomic_write
from drillcosim.cosim.scenario.config import load_config

from ..ensemble import ensemble_stat
from ..table import rows_csv
from ..verdict import GROWTH_MARGIN, NOISE_FACTOR, judge
from .calibration import CalibrationTable, PlantChoice
from .conclusion import DELAYS, GAINS, PER_SPAN, SCENE, ConclusionTable

__all__ = ["answer", "conclusion_rows", "conclusion_markdown", "member_ensembles",
           "open_ensemble", "plot_benefit", "plot_stability", "report"]

#: The question's thresholds.
ANSWER_DELAY = 5e-4      # s
ANSWER_BENEFIT = 0.30    # 1 - RMS / RMS_open


def open_ensemble(confirm_rows: Sequence[Mapping[str, Any]], scene: str = SCENE
                  ) -> dict[str, float]:
    """The open-loop ensemble of the scene's calibrated set (the calibration's confirm stage):
    mean and sd over its members of the long/short span RMS [m] (sqrt(mean^2 + std^2) of the
    steady window) and the long span's contact time [s]; empty if the set is not there."""
    p = load_config(scene).scene.plant
    label = PlantChoice(p.bit.weight_on_bit, p.top_drive.axial_stiffness,
                        p.damping.lateral_ratio, p.unbalance.body, p.gravity).label
    ok = [r for r in confirm_rows if r["group"] == label and r["status"] == "ok"]
    if not ok:
        return {}
    out: dict[str, float] = {"members": float(len(ok))}
    for span in ("long", "short"):
        e = ensemble_stat([math.hypot(r[f"{span}_mean_m"], r[f"{span}_std_m"]) for r in ok])
        out[f"{span}_rms_m"], out[f"{span}_rms_sd_m"] = e.mean, e.sd
    e = ensemble_stat([r["long_contact_time_s"] for r in ok])
    out["long_contact_time_s"], out["long_contact_time_sd_s"] = e.mean, e.sd
    return out


def conclusion_rows(rows: Sequence[Mapping[str, Any]], prediction: Sequence[Mapping[str, Any]],
                    ensemble: Mapping[str, float] | None = None
                    ) -> tuple[list[dict[str, Any]], dict[str, Any] | None]:
    """Closed-loop rows with ``verdict``, ``excess``, ``predicted_growth_rate``,
    ``critical_gain``, ``predicted_stable``, ``benefit_long`` / ``benefit_short``
    (``1 - RMS / RMS_open`` against the gain-0 run), ``benefit_long_ensemble`` (against the
    open-loop ensemble's mean RMS, :func:`open_ensemble`) and ``contact_ratio_long``, sorted by
    (sites per span, gain, delay); and the reference row. Member 0 of each point only (the
    other members: :func:`member_ensembles`)."""
    rows = [r for r in rows if not r.get("member")]         # 0, or NaN in a table without it
    ref = next((r for r in rows if r["gain"] == 0.0), None)
    pred = {(p["per_span"], p["gain"], p["delay"]): p for p in prediction}
    out = []
    for r in rows:
        if r["gain"] == 0.0:
            continue
        d = dict(r)
        d["kind"] = "closed_loop"
        d["min_stop_time"] = math.nan
        d["verdict"], d["verdict_reason"], d["excess"] = judge(d, ref)
        noise = math.hypot(d["growth_noise"], ref["growth_noise"]) if ref else math.nan
        # completed, and the envelope's excess growth clearly below the instability margin
        # (the sweep's rule calls a significant excess below the margin "undecided")
        d["below_margin"] = float(d["status"] == "ok" and d["verdict"] != "unstable"
                                  and d["excess"] + NOISE_FACTOR * noise < GROWTH_MARGIN)
        p = pred.get((r["per_span"], r["gain"], r["delay"]), {})
        d["predicted_growth_rate"] = p.get("predicted_growth_rate", math.nan)
        d["critical_gain"] = p.get("critical_gain", math.nan)
        d["predicted_stable"] = float(d["predicted_growth_rate"] < 0)
        ok = ref is not None and ref["status"] == "ok" and d["status"] == "ok"
        d["benefit_long"] = 1.0 - d["long_rms_m"] / ref["long_rms_m"] if ok else math.nan
        d["benefit_short"] = 1.0 - d["short_rms_m"] / ref["short_rms_m"] if ok else math.nan
        d["contact_ratio_long"] = (d["long_contact_time_s"] / ref["long_contact_time_s"]
                                   if ok and ref["long_contact_time_s"] > 0 else math.nan)
        ens = (ensemble or {}).get("long_rms_m", math.nan)
        d["benefit_long_ensemble"] = (1.0 - d["long_rms_m"] / ens if d["status"] == "ok"
                                      else math.nan)
        out.append(d)
    out.sort(key=lambda d: (d["per_span"], d["gain"], d["delay"]))
    return out, ref


def member_ensembles(rows: Sequence[Mapping[str, Any]]) -> list[dict[str, Any]]:
    """Per configuration run with more than one member: member count, completed members,
    long-span RMS mean and sd [m] (over the completed), long contact time mean [s], the largest
    growth rate [1/s], and ``benefit_long`` = 1 - mean RMS / the gain-0 ensemble's mean RMS."""
    groups: dict[tuple[float, float, float], list[Mapping[str, Any]]] = {}
    for r in rows:
        groups.setdefault((r["per_span"], r["gain"], r["delay"]), []).append(r)
    out = []
    for (n, g, d), members in sorted(groups.items()):
        if len(members) < 2:
            continue
        ok = [m for m in members if m["status"] == "ok"]
        rms = ensemble_stat([m["long_rms_m"] for m in ok])
        out.append({"per_span": n, "gain": g, "delay": d, "members": len(members),
                    "completed": len(ok), "long_rms_m": rms.mean, "long_rms_sd_m": rms.sd,
                    "long_rms_min_m": min((m["long_rms_m"] for m in ok), default=math.nan),
                    "long_rms_max_m": max((m["long_rms_m"] for m in ok), default=math.nan),
                    "long_contact_time_s": ensemble_stat(
                        [m["long_contact_time_s"] for m in ok]).mean,
                    "max_growth_rate": max((m["growth_rate"] for m in members
                                            if math.isfinite(m["growth_rate"])),
                                           default=math.nan)})
    ref = next((e for e in out if e["gain"] == 0.0), None)
    for e in out:
        e["benefit_long"] = 1.0 - e["long_rms_m"] / ref["long_rms_m"] if ref else math.nan
    return out


def answer(rows: Sequence[Mapping[str, Any]]) -> list[dict[str, Any]]:
    """Configurations at :data:`ANSWER_DELAY` stable in simulation (``below_margin``) and
    prediction whose long
    span RMS deflection is at least :data:`ANSWER_BENEFIT` below the open loop's, against both
    references (the gain-0 run and the open-loop ensemble mean)."""
    return [r for r in rows if math.isclose(r["delay"], ANSWER_DELAY)
            and r["below_margin"] and r["predicted_stable"]
            and r["benefit_long"] >= ANSWER_BENEFIT
            and not r["benefit_long_ensemble"] < ANSWER_BENEFIT]


def _panels(n: int):
    import matplotlib.pyplot as plt

    return plt.subplots(1, n, figsize=(4.2 * n, 3.6), sharey=True, squeeze=False,
                        layout="constrained")


_MARK = {"stable": ("o", "C2"), "below margin": ("D", "C0"), "unstable": ("x", "C3"),
         "undecided": ("s", "C1"), "error": ("^", "k")}


def _category(r: Mapping[str, Any]) -> str:
    return "below margin" if r["verdict"] == "undecided" and r["below_margin"] else r["verdict"]


def plot_stability(rows: Sequence[Mapping[str, Any]], path: Path) -> Path:
    """Verdict markers over (delay, gain) per sites-per-span, predicted boundary overlaid
    ("below margin": the sweep's "undecided" with an excess growth clearly below
    :data:`cosim.study.verdict.GROWTH_MARGIN`)."""
    from drillcosim.cosim.scenario.plots import save_figure

    fig, axes = _panels(len(PER_SPAN))
    for ax, n in zip(axes[0], PER_SPAN):
        sel = [r for r in rows if r["per_span"] == n]
        for v, (m, c) in _MARK.items():
            pts = [(r["delay"] * 1e3, r["gain"]) for r in sel if _category(r) == v]
            if pts:
                ax.scatter(*zip(*pts), marker=m, color=c, label=f"simulation: {v}", zorder=3)
        bound = sorted({(r["delay"], r["critical_gain"]) for r in sel})
        ax.plot([d * 1e3 for d, _ in bound], [min(max(k, 1e6), 1e10) for _, k in bound],
                "k-", lw=1, label="predicted critical gain")
        ax.set_yscale("log")
        ax.set_ylim(3e6, 3e9)
        ax.set_xlabel("actuator delay [ms]")
        ax.set_title(f"{n} site(s) per span ({2 * n} in all)", fontsize=9)
    axes[0, 0].set_ylabel("gain [N per unit strain]")
    axes[0, -1].legend(fontsize=7, loc="upper right")
    return save_figure(fig, path)


def plot_benefit(rows: Sequence[Mapping[str, Any]], path: Path) -> Path:
    """Long-span benefit (colour, value written) per sites-per-span; unstable crossed out."""

    from drillcosim.cosim.scenario.plots import save_figure

    fig, axes = _panels(len(PER_SPAN))
    d_idx = {round(d, 9): i for i, d in enumerate(DELAYS)}
    g_idx = {g: i for i, g in enumerate(GAINS)}
    im = None
    for ax, n in zip(axes[0], PER_SPAN):
        grid = np.full((len(GAINS), len(DELAYS)), np.nan)
        for r in rows:
            if r["per_span"] == n and r["gain"] in g_idx:
                i, j = g_idx[r["gain"]], d_idx[round(r["delay"], 9)]
                grid[i, j] = r["benefit_long"] * 100
                txt = "x" if r["verdict"] == "unstable" else (
                    f"{r['benefit_long'] * 100:.0f}" if math.isfinite(r["benefit_long"])
                    else "-")
                ax.text(j, i, txt, ha="center", va="center", fontsize=7)
        im = ax.imshow(grid, origin="lower", aspect="auto", cmap="RdYlGn", vmin=-60, vmax=60)
        ax.set_xticks(range(len(DELAYS)), [f"{d * 1e3:g}" for d in DELAYS], fontsize=7)
        ax.set_yticks(range(len(GAINS)), [f"{g:.0e}" for g in GAINS], fontsize=7)
        ax.set_xlabel("actuator delay [ms]")
        ax.set_title(f"{n} site(s) per span: long-span RMS benefit [%]", fontsize=9)
    axes[0, 0].set_ylabel("gain [N per unit strain]")
    if im is not None:
        fig.colorbar(im, ax=axes[0, -1], label="1 - RMS/RMS_open [%] (x: unstable)")
    return save_figure(fig, path)


def _fmt(x: float, spec: str) -> str:
    return format(x, spec) if isinstance(x, float) and math.isfinite(x) else "-"


def conclusion_markdown(rows: Sequence[Mapping[str, Any]], ref: Mapping[str, Any] | None,
                        ensemble: Mapping[str, float] | None = None) -> str:
    """Markdown: the references and one line per point."""
    lines = []
    if ensemble:
        lines += [f"Open-loop ensemble (calibration confirm stage, {ensemble['members']:.0f} "
                  f"members, 1 ms step): long-span RMS {ensemble['long_rms_m'] * 1e3:.2f} +- "
                  f"{ensemble['long_rms_sd_m'] * 1e3:.2f} mm (sd), short-span RMS "
                  f"{ensemble['short_rms_m'] * 1e3:.2f} +- {ensemble['short_rms_sd_m'] * 1e3:.2f}"
                  f" mm, long-span contact {ensemble['long_contact_time_s']:.2f} +- "
                  f"{ensemble['long_contact_time_sd_s']:.2f} s.", ""]
    if ref is not None:
        lines += [f"Open-loop reference (gain 0, same system and step): long-span RMS "
                  f"{_fmt(ref['long_rms_m'] * 1e3, '.2f')} mm, short-span RMS "
                  f"{_fmt(ref['short_rms_m'] * 1e3, '.2f')} mm, long-span contact "
                  f"{_fmt(ref['long_contact_time_s'], '.2f')} s, strain growth "
                  f"{_fmt(ref['growth_rate'], '.3f')} 1/s.", ""]
    lines += ["| sites/span | gain [N/strain] | delay [ms] | simulation | excess growth [1/s] | "
              "predicted growth [1/s] | predicted K_c [N/strain] | long RMS [mm] | benefit "
              "long [%] (vs gain 0 / vs ensemble) | benefit short [%] | long contact [s] | "
              "peak force [kN] | peak power [W] |", "|" + "---|" * 13]
    for r in rows:
        div = f" (diverged at {r['end_time']:.3g} s)" if r["status"] == "diverged" else ""
        lines.append(
            f"| {r['per_span']:.0f} | {r['gain']:.0e} | {r['delay'] * 1e3:g} | {_category(r)}"
            f"{div} | "
            f"{_fmt(r['excess'], '.3g')} | {_fmt(r['predicted_growth_rate'], '.3g')} | "
            f"{_fmt(r['critical_gain'], '.3g')} | {_fmt(r['long_rms_m'] * 1e3, '.2f')} | "
            f"{_fmt(r['benefit_long'] * 100, '.0f')} / "
            f"{_fmt(r['benefit_long_ensemble'] * 100, '.0f')} | "
            f"{_fmt(r['benefit_short'] * 100, '.0f')}"
            f" | {_fmt(r['long_contact_time_s'], '.2f')} | "
            f"{_fmt(r['peak_force'] / 1e3, '.3g')} | {_fmt(r['peak_power'], '.3g')} |")
    return "\n".join(lines) + "\n"


def report(out_dir: str | Path, figures: str | Path | None = None) -> str:
    """Write the CSV and the two maps into ``figures`` (default ``out_dir/report``); return
    the markdown (table and the answer). The open-loop ensemble is read from the sibling
    ``confirm`` table of the calibration, if there."""
    out = Path(out_dir)
    fig_dir = Path(figures) if figures is not None else out / "report"
    fig_dir.mkdir(parents=True, exist_ok=True)
    prediction = json.loads((out / "prediction.json").read_text())
    confirm = out.parent / "confirm"
    ensemble = open_ensemble(CalibrationTable(confirm).rows) \
        if (confirm / "results.csv").exists() else {}
    rows, ref = conclusion_rows(ConclusionTable(out).rows, prediction, ensemble)
    atomic_write(fig_dir / "conclusion.csv", rows_csv(rows))
    s = plot_stability(rows, fig_dir / "conclusion_stability.png")
    b = plot_benefit(rows, fig_dir / "conclusion_benefit.png")
    yes = answer(rows)
    ens = member_ensembles(ConclusionTable(out).rows)
    text = [conclusion_markdown(rows, ref, ensemble), f"![]({s})", f"![]({b})", ""]
    if ens:
        text += ["Ensembles (member 0 = the grid's run; members differ by a 1 um lateral "
                 "perturbation):", "",
                 "| sites/span | gain | delay [ms] | members (completed) | long RMS [mm] mean "
                 "+- sd (min-max) | benefit vs gain-0 ensemble [%] | long contact [s] | "
                 "max growth [1/s] |", "|" + "---|" * 8]
        text += [f"| {e['per_span']:.0f} | {e['gain']:.0e} | {e['delay'] * 1e3:g} | "
                 f"{e['members']} ({e['completed']}) | {_fmt(e['long_rms_m'] * 1e3, '.2f')} +- "
                 f"{_fmt(e['long_rms_sd_m'] * 1e3, '.2f')} ({_fmt(e['long_rms_min_m'] * 1e3, '.2f')}"
                 f"-{_fmt(e['long_rms_max_m'] * 1e3, '.2f')}) | "
                 f"{_fmt(e['benefit_long'] * 100, '.0f')} | "
                 f"{_fmt(e['long_contact_time_s'], '.2f')} | {_fmt(e['max_growth_rate'], '.3g')} |"
                 for e in ens]
        text.append("")
    text.append(f"Stable at {ANSWER_DELAY * 1e3:g} ms (simulation and prediction) with a "
                f"long-span RMS cut >= {ANSWER_BENEFIT:.0%} (member 0): "
                + (", ".join(f"{r['per_span']:.0f} site(s)/span at gain {r['gain']:.0e} "
                             f"({r['benefit_long']:.0%})" for r in yes) or "none"))
    return "\n".join(text) + "\n"
