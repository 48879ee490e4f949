"""``drillcosim calibrate``: run the calibration stages and the paper's experiments, and write
the report (markdown tables on stdout, PNG figures and CSV tables in a folder).

Stages: :mod:`cosim.study.paper.calibration` (``coarse``, ``refine``, ``confirm``; ``all`` runs the
three) and :mod:`cosim.study.paper.experiments` (``experiments``). ``report`` reads the tables of a
study folder and writes

* ``calibration_<stage>.csv`` - per parameter set: the ensemble mean, sd and se of every
  statistic and of the objective, ranked (best first);
* ``experiments.csv`` - per experiment and scene family, the same;
* ``calibration_grid.png`` - mean objective over the coarse grid;
* ``calibration_sensitivity.png`` - one-at-a-time objective and long-span statistics around
  the coarse best (the refine stage);
* ``calibration_traces.png`` - radial deflection of ensemble members, today's scene and the
  calibrated one;
* ``experiments.png`` - member 0 of every experiment, today's scenes and the calibrated ones,

and prints the markdown tables of ``docs/paper_comparison.md``.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from drillcosim.cosim.master.files import atomic_write
from drillcosim.plant.signals import PLANT, body_signal, ref

from ..scene_stats import SceneTable, simulate_member
from ..table import rows_csv
from .calibration import (
    BASE_SCENE,
    KNOB_COLUMNS,
    RANGES,
    STAGES,
    STOP_TIME,
    TARGETS,
    TODAY,
    CalibrationTable,
    PlantChoice,
    hanging_weight_on_bit,
    rank,
)
from .experiments import EXPERIMENTS, FAMILIES, comparison_rows, markdown_table

__all__ = ["report"]

MM = 1e3


# -- tables ---------------------------------------------------------------------------------
def _f(x: float, digits: int = 3) -> str:
    return f"{x:.{digits}g}" if isinstance(x, float) and math.isfinite(x) else "-"


def ranges_markdown() -> str:
    """The searched quantities, their ranges and why."""
    lines = ["| quantity | range | why |", "|---|---|---|"]
    for name, (lo, hi, unit, why) in RANGES.items():
        lines.append(f"| `{name}` | {lo:g} .. {hi:g} {unit} | {why} |")
    return "\n".join(lines) + "\n"


def ranking_markdown(ranked: Sequence[Mapping[str, Any]], n: int = 10) -> str:
    """The ``n`` best sets: quantities, mean objective +- se and the long/short statistics."""
    lines = ["| set | WOB [kN] | top spring [N/m] | zeta_lat | unbalance body | g [m/s^2] | "
             "members (completed) | J mean +- se | long peak [mm] | long mean [mm] | "
             "long half-band [mm] | long contact [s] | short mean [mm] |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for a in ranked[:n]:
        lines.append(
            f"| {a['group']} | {a['weight_on_bit'] / 1e3:.3g} | {a['top_axial_stiffness']:.3g}"
            f" | {a['lateral_ratio']:.3g} | {int(a['unbalance_body'])} | {a['gravity']:g} | "
            f"{a['members']} ({a['completed']}) | {_f(a['objective'])} +- "
            f"{_f(a['objective_se'], 2)} | {_f(a['long_peak_m'] * MM)} | "
            f"{_f(a['long_mean_m'] * MM)} | {_f(a['long_band_m'] * MM)} | "
            f"{_f(a['long_contact_time_s'])} | {_f(a['short_mean_m'] * MM)} |")
    return "\n".join(lines) + "\n"


def oat_markdown(ranked: Sequence[Mapping[str, Any]], best: PlantChoice) -> str:
    """One-at-a-time table around ``best``: per varied quantity, J mean +- se and the long
    span's statistics."""
    lines = ["| varied | value | J mean +- se | long peak [mm] | long mean [mm] | "
             "long half-band [mm] | long contact [s] | short mean [mm] |",
             "|---|---|---|---|---|---|---|---|"]
    panels = [(k, lab, sc, _oat_sets(ranked, best, k)) for k, lab, sc, _ in _OAT]
    panels.append(("gravity", "gravity [m/s^2]", 1.0, _oat_sets(ranked, best, "gravity")))
    panels.append(("top_axial_stiffness", "top spring, hanging-string WOB [N/m]", 1.0,
                   hanging_family(ranked, best)))
    for knob, label, scale, sets in panels:
        for a in sets:
            mark = " (centre)" if math.isclose(a[knob], getattr(best, knob)) and knob != \
                "top_axial_stiffness" or a["group"] == best.label else ""
            value = a[knob] * scale
            extra = (f", WOB {a['weight_on_bit'] / 1e3:.3g} kN"
                     if label.startswith("top spring, hanging") else "")
            lines.append(f"| {label} | {value:.4g}{extra}{mark} | {_f(a['objective'])} +- "
                         f"{_f(a['objective_se'], 2)} | {_f(a['long_peak_m'] * MM)} | "
                         f"{_f(a['long_mean_m'] * MM)} | {_f(a['long_band_m'] * MM)} | "
                         f"{_f(a['long_contact_time_s'])} | {_f(a['short_mean_m'] * MM)} |")
    return "\n".join(lines) + "\n"


# -- figures --------------------------------------------------------------------------------
def plot_grid(ranked: Sequence[Mapping[str, Any]], path: Path) -> Path:
    """Mean objective of the coarse grid: WOB x damping ratio per top spring (columns) and
    gravity (rows), the better unbalance body per cell; the best cell circled."""
    import matplotlib.pyplot as plt
    from matplotlib.colors import LogNorm

    from drillcosim.cosim.scenario.plots import save_figure

    wobs = sorted({a["weight_on_bit"] for a in ranked})
    zetas = sorted({a["lateral_ratio"] for a in ranked})
    kts = sorted({a["top_axial_stiffness"] for a in ranked})
    gs = sorted({a["gravity"] for a in ranked}, reverse=True)
    best = ranked[0]
    fig, axes = plt.subplots(len(gs), len(kts), figsize=(4.2 * len(kts), 3.4 * len(gs)),
                             layout="constrained", squeeze=False)
    norm = LogNorm(vmin=max(min(a["objective"] for a in ranked), 1e-2),
                   vmax=max(a["objective"] for a in ranked if math.isfinite(a["objective"])))
    im = None
    for i, g in enumerate(gs):
        for j, kt in enumerate(kts):
            ax = axes[i, j]
            grid = np.full((len(zetas), len(wobs)), np.nan)
            for a in ranked:
                if a["gravity"] == g and a["top_axial_stiffness"] == kt:
                    y, x = zetas.index(a["lateral_ratio"]), wobs.index(a["weight_on_bit"])
                    if not grid[y, x] <= a["objective"]:
                        grid[y, x] = a["objective"]
            im = ax.imshow(grid, origin="lower", aspect="auto", norm=norm, cmap="viridis_r")
            for (y, x), v in np.ndenumerate(grid):
                if math.isfinite(v):
                    ax.text(x, y, f"{v:.2g}", ha="center", va="center", fontsize=7,
                            color="w" if v > 1 else "k")
            if best["gravity"] == g and best["top_axial_stiffness"] == kt:
                ax.plot(wobs.index(best["weight_on_bit"]), zetas.index(best["lateral_ratio"]),
                        "o", ms=22, mfc="none", mec="r", mew=2)
            ax.set_xticks(range(len(wobs)), [f"{w / 1e3:.3g}" for w in wobs])
            ax.set_yticks(range(len(zetas)), [f"{z:g}" for z in zetas])
            ax.set_xlabel("weight on bit [kN]")
            ax.set_ylabel("lateral damping ratio")
            ax.set_title(f"top spring {kt:.0e} N/m, gravity {g:g} m/s$^2$", fontsize=9)
    fig.colorbar(im, ax=axes, label="mean objective J (better unbalance body)")
    fig.suptitle(f"Coarse grid: mean J over the ensemble members (best: {best['group']}, "
                 f"J = {best['objective']:.3g})", fontsize=10)
    return save_figure(fig, path)


_OAT = (("weight_on_bit", "weight on bit [kN]", 1e-3, False),
        ("top_axial_stiffness", "top spring [N/m]", 1.0, True),
        ("lateral_ratio", "lateral damping ratio", 1.0, False),
        ("unbalance_body", "unbalance body", 1.0, False))


def _oat_sets(ranked: Sequence[Mapping[str, Any]], best: PlantChoice, knob: str
              ) -> list[Mapping[str, Any]]:
    """The sets of ``ranked`` that differ from ``best`` in ``knob`` only (best included)."""
    out = []
    for a in ranked:
        if all(math.isclose(a[c], getattr(best, c), rel_tol=1e-9, abs_tol=1e-12)
               for c in KNOB_COLUMNS if c != knob):
            out.append(a)
    return sorted(out, key=lambda a: a[knob])


def hanging_family(ranked: Sequence[Mapping[str, Any]], best: PlantChoice
                   ) -> list[Mapping[str, Any]]:
    """The refine sets of the paper's hook-load mechanism (WOB from the top spring)."""
    out = []
    for a in ranked:
        if a["gravity"] == 9.81 and a["lateral_ratio"] == best.lateral_ratio and \
                a["unbalance_body"] == best.unbalance_body and math.isclose(
                    a["weight_on_bit"], hanging_weight_on_bit(a["top_axial_stiffness"]),
                    rel_tol=1e-6):
            out.append(a)
    return sorted(out, key=lambda a: a["top_axial_stiffness"])


def plot_sensitivity(ranked: Sequence[Mapping[str, Any]], best: PlantChoice, path: Path) -> Path:
    """One at a time around ``best`` (the refine stage): mean J +- se (top) and the long
    span's peak, steady mean and half-band against the paper's values (bottom)."""
    import matplotlib.pyplot as plt

    from drillcosim.cosim.scenario.plots import save_figure

    panels = [(k, lab, sc, log, _oat_sets(ranked, best, k)) for k, lab, sc, log in _OAT]
    panels.append(("top_axial_stiffness", "top spring [N/m], WOB from the hanging string", 1.0,
                   True, hanging_family(ranked, best)))
    fig, axes = plt.subplots(2, len(panels), figsize=(3.6 * len(panels), 6.4),
                             layout="constrained", sharey="row")
    for j, (knob, label, scale, log, sets) in enumerate(panels):
        x = [a[knob] * scale for a in sets]
        ax = axes[0, j]
        ax.errorbar(x, [a["objective"] for a in sets],
                    yerr=[a["objective_se"] for a in sets], fmt="o-", capsize=3)
        bx = getattr(best, knob) * scale
        ax.axvline(bx, color="r", lw=0.8, ls=":")
        ax.set_yscale("log")
        ax.set_title(label, fontsize=9)
        ax2 = axes[1, j]
        for col, name, c in (("long_peak_m", "peak", "C0"), ("long_mean_m", "steady mean", "C1"),
                             ("long_band_m", "half-band", "C2")):
            ax2.errorbar(x, [a[col] * MM for a in sets], yerr=[a[f"{col}_sd"] * MM for a in sets],
                         fmt="o-", color=c, capsize=3, label=name)
            ax2.axhline(TARGETS[col] * MM, color=c, lw=0.8, ls="--")
        ax2.axvline(bx, color="r", lw=0.8, ls=":")
        ax2.set_xlabel(label)
        if log:
            ax.set_xscale("log")
            ax2.set_xscale("log")
    axes[0, 0].set_ylabel("mean objective J (+- se)")
    axes[1, 0].set_ylabel("long span [mm] (+- sd over members)\ndashed: the paper's values")
    axes[1, 0].legend(fontsize=8)
    fig.suptitle(f"One at a time around {best.label} (red dotted)", fontsize=10)
    return save_figure(fig, path)


def _traces(scene: str, overrides: Mapping[str, Any] | None, members: int, stop: float):
    return [simulate_member(scene, stop, overrides=overrides, member=k)[0] for k in range(members)]


def plot_traces(best: PlantChoice, path: Path, members: int = 4) -> Path:
    """Radial deflection of the long and short span's middle bodies for ``members`` members
    of today's scene and the calibrated set (member 0 thick), with the paper's values."""
    import matplotlib.pyplot as plt

    from drillcosim.cosim.scenario.plots import save_figure

    cases = (("today: " + TODAY.label, TODAY), ("calibrated: " + best.label, best))
    fig, axes = plt.subplots(len(cases), 2, figsize=(12, 3.2 * len(cases)),
                             layout="constrained", sharex=True, sharey=True, squeeze=False)
    for i, (title, choice) in enumerate(cases):
        runs = _traces(BASE_SCENE, choice.overrides(), members, STOP_TIME)
        for j, (body, span) in enumerate(((11, "long"), (26, "short"))):
            ax = axes[i, j]
            for k, d in enumerate(runs):
                ax.plot(d["time"], d[ref(PLANT, body_signal(body, "radial_deflection"))] * MM,
                        lw=1.0 if k == 0 else 0.5, alpha=1.0 if k == 0 else 0.6,
                        label="member 0" if k == 0 else (f"members 1-{members - 1}"
                                                         if k == 1 else None))
            ax.axhline(20.0, color="k", lw=0.8, ls="--", label="clearance 20 mm")
            if span == "long":
                ax.axhline(15.0, color="r", lw=0.8, ls=":", label="paper peak 15 mm")
                ax.axhspan(3.0, 13.0, xmin=2 / 3, color="r", alpha=0.08,
                           label="paper steady 8 +- 5 mm")
            ax.set_title(f"{title}: body {body} ({span} span)", fontsize=9)
            ax.set_ylabel("radial deflection [mm]")
    for ax in axes[-1]:
        ax.set_xlabel("time [s]")
    axes[0, 0].legend(fontsize=7, loc="upper left")
    return save_figure(fig, path)


def plot_experiments(path: Path) -> Path:
    """Member 0 of every experiment: long and short span radial deflection and the site-1
    actuator force, today's scenes (left) and the calibrated ones (right)."""
    import matplotlib.pyplot as plt

    from drillcosim.cosim.scenario.plots import save_figure

    fig, axes = plt.subplots(len(EXPERIMENTS), len(FAMILIES),
                             figsize=(6.2 * len(FAMILIES), 2.6 * len(EXPERIMENTS)),
                             layout="constrained", sharey=True, squeeze=False)
    for i, e in enumerate(EXPERIMENTS):
        for j, fam in enumerate(FAMILIES):
            d = _traces(e.scene(fam), None, 1, e.stop_time)[0]
            ax = axes[i, j]
            t = d["time"]
            ax.plot(t, d["plant.body11_radial_deflection"] * MM, lw=0.7, label="long span")
            ax.plot(t, d["plant.body26_radial_deflection"] * MM, lw=0.7, alpha=0.7,
                    label="short span")
            ax.axhline(20.0, color="k", lw=0.6, ls="--")
            ax.set_title(f"{e.scene(fam)} ({e.figures})", fontsize=9)
            ax.set_ylabel("radial defl. [mm]")
            name = "controller.actuator1_force_C"
            if name in (d.dtype.names or ()):
                axf = ax.twinx()
                axf.plot(t, d[name] / 1e3, color="C3", lw=0.4, alpha=0.6)
                axf.set_ylabel("site 1 force C [kN]", color="C3", fontsize=8)
    for ax in axes[-1]:
        ax.set_xlabel("time [s]")
    axes[0, 0].legend(fontsize=7, loc="upper left")
    return save_figure(fig, path)


# -- the report -----------------------------------------------------------------------------
def report(out_dir: str | Path, figures: str | Path | None = None,
           trace_members: int = 4) -> str:
    """Write the CSVs and PNGs of a finished study into ``figures`` and return the markdown.

    Parameters
    ----------
    out_dir : path-like
        Study folder (the stages that exist are reported).
    figures : path-like, optional
        Default ``out_dir/report``.
    trace_members : int
        Members re-run for :func:`plot_traces`.
    """
    out = Path(out_dir)
    fig_dir = Path(figures) if figures is not None else out / "report"
    fig_dir.mkdir(parents=True, exist_ok=True)
    text = ["## Searched quantities", "", ranges_markdown()]
    ranked: dict[str, list[dict[str, Any]]] = {}
    for st in STAGES:
        if (out / st / "results.csv").exists():
            ranked[st] = rank(CalibrationTable(out / st).rows)
            atomic_write(fig_dir / f"calibration_{st}.csv", rows_csv(ranked[st]))
            consistent = [a for a in ranked[st] if a["paper_consistent"]]
            text += [f"## Stage {st}: {len(ranked[st])} sets", "",
                     f"Best 10 paper-consistent sets (top spring 1e9 N/m, gravity on), of "
                     f"{len(consistent)}:", "", ranking_markdown(consistent, 10),
                     "Best 5 of all sets:", "", ranking_markdown(ranked[st], 5)]
    if "coarse" in ranked:
        grid_png = plot_grid(ranked["coarse"], fig_dir / "calibration_grid.png")
        text.append(f"![]({grid_png})")
    if "refine" in ranked and "coarse" in ranked:
        coarse_best = PlantChoice.from_row(
            next(a for a in ranked["coarse"] if a["paper_consistent"]))
        sens_png = plot_sensitivity(ranked["refine"], coarse_best,
                                    fig_dir / "calibration_sensitivity.png")
        text += ["", oat_markdown(ranked["refine"], coarse_best), f"![]({sens_png})"]
    final = ranked.get("confirm") or ranked.get("refine") or ranked.get("coarse")
    final = [a for a in final or [] if a["paper_consistent"]]
    if final:
        best = PlantChoice.from_row(final[0])
        text += ["", f"Calibrated set: {best.label}", "",
                 f"![]({plot_traces(best, fig_dir / 'calibration_traces.png', trace_members)})"]
    if (out / "experiments" / "results.csv").exists():
        rows = SceneTable(out / "experiments").rows
        cmp = comparison_rows(rows)
        atomic_write(fig_dir / "experiments.csv", rows_csv(rows_sorted(rows)))
        text += ["", "## Experiments", "", markdown_table(cmp),
                 f"![]({plot_experiments(fig_dir / 'experiments.png')})"]
    return "\n".join(text) + "\n"


def rows_sorted(rows: Sequence[Mapping[str, Any]]) -> list[dict[str, Any]]:
    """Rows sorted by group and member (a table's finish order removed)."""
    return sorted((dict(r) for r in rows), key=lambda r: (r["group"], r["member"]))
