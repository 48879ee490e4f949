"""Tables and figures of the comparison study (:mod:`.compare`; ``docs/control_design.md``).

Per row (:func:`compare_rows`): the simulated verdict (:func:`cosim.study.verdict.judge`
against the open-loop run, member 0, of the same run plant and step; ``below_margin`` as in the
paper study: completed and the envelope's excess growth clearly below the margin), the
prediction's verdict (``predicted_growth_rate < 0``), and the long-span benefit ``1 - RMS /
RMS_open`` against the mean of the open-loop ensemble of the same run plant and step (one run of
the chaotic open loop decides nothing: its members spread by +-30 %).

:func:`tolerance` answers the question: per family, sites per span and step, the largest delay
up to which every delay of the grid is stable (simulated and predicted) with at least a given
benefit, and the peak force and power there.

Figures: ``control_growth.png`` (predicted growth rate vs delay, simulated verdicts as
markers), ``control_benefit.png`` (benefit vs delay), ``control_force.png`` (peak actuator
force vs delay); CSV: ``control_compare.csv`` (every row with the derived columns).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from drillcosim.cosim.master.files import atomic_write

from ..ensemble import ensemble_stat
from ..table import rows_csv
from ..verdict import GROWTH_MARGIN, NOISE_FACTOR, judge
from . import linear
from .compare import (
    DELAYS,
    DELAYS_1MS,
    FAMILIES,
    PER_SPAN,
    STEP,
    STEP_1MS,
    VARIANTS,
    CompareTable,
    reference_variant,
)

__all__ = ["BENEFITS", "compare_rows", "ensembles", "open_references", "report", "tolerance"]

#: Benefit levels of the answer (1 - RMS / RMS_open of the long span).
BENEFITS = (0.5, 0.7)
_LABEL = {"p1e8": "P 1e8", "p1e9": "P 1e9", "pred1e8": "predictor 1e8",
          "pred1e9": "predictor 1e9", "lqg3e-6": "LQG (strain noise 3e-6)",
          "lqg1e-6": "LQG (strain noise 1e-6)"}
_STYLE = {"p1e8": ("C0", "--"), "p1e9": ("C3", "--"), "pred1e8": ("C0", "-"),
          "pred1e9": ("C3", "-"), "lqg3e-6": ("C2", "-."), "lqg1e-6": ("C4", "-.")}


def _same(a: float, b: float) -> bool:
    return math.isclose(a, b, rel_tol=1e-9, abs_tol=1e-12)


def open_references(rows: Sequence[Mapping[str, Any]]) -> dict[tuple[str, float], dict[str, Any]]:
    """Per (run-plant variant, step): the open-loop member 0 row (``row``) and the ensemble's
    long/short RMS mean and sd [m] over its completed members."""
    out: dict[tuple[str, float], dict[str, Any]] = {}
    for r in rows:
        if r["family"] != "open":
            continue
        e = out.setdefault((r["variant"], r["step"]), {"members": []})
        e["members"].append(r)
        if not r["member"]:
            e["row"] = r
    for e in out.values():
        ok = [m for m in e["members"] if m["status"] == "ok"]
        for span in ("long", "short"):
            s = ensemble_stat([m[f"{span}_rms_m"] for m in ok])
            e[f"{span}_rms_m"], e[f"{span}_rms_sd_m"] = s.mean, s.sd
        e["n"] = len(ok)
    return out


def compare_rows(rows: Sequence[Mapping[str, Any]]) -> list[dict[str, Any]]:
    """Closed-loop rows with ``verdict``, ``verdict_reason``, ``excess``, ``below_margin``,
    ``predicted_stable``, ``tolerated`` (completed, below the margin, predicted stable),
    ``benefit_long`` / ``benefit_short`` (vs the open-loop ensemble mean of the same run plant
    and step), ``benefit_long_run0`` (vs its member 0)."""
    refs = open_references(rows)
    out = []
    for r in rows:
        if r["family"] == "open":
            continue
        d = dict(r)
        ref = refs.get((reference_variant(r["variant"]), r["step"]), {})
        ref_row = ref.get("row")
        d["kind"] = "closed_loop"                  # judge's vocabulary
        d["min_stop_time"] = math.nan
        d["verdict"], d["verdict_reason"], d["excess"] = judge(d, ref_row)
        d["kind"] = r["kind"]
        noise = math.hypot(d["growth_noise"], ref_row["growth_noise"]) if ref_row else math.nan
        d["below_margin"] = float(d["status"] == "ok" and d["verdict"] != "unstable"
                                  and d["excess"] + NOISE_FACTOR * noise < GROWTH_MARGIN)
        d["predicted_stable"] = float(d["predicted_growth_rate"] < 0)
        d["tolerated"] = float(bool(d["below_margin"]) and bool(d["predicted_stable"]))
        ok = d["status"] == "ok"
        for span in ("long", "short"):
            d[f"benefit_{span}"] = (1.0 - d[f"{span}_rms_m"] / ref[f"{span}_rms_m"]
                                    if ok and ref.get("n") else math.nan)
        d["benefit_long_run0"] = (1.0 - d["long_rms_m"] / ref_row["long_rms_m"]
                                  if ok and ref_row and ref_row["status"] == "ok" else math.nan)
        out.append(d)
    order = {f: i for i, f in enumerate(FAMILIES)}
    out.sort(key=lambda d: (d["variant"] != "nominal", d["variant"], d["step"],
                            order.get(d["family"], 99), d["per_span"], d["delay"], d["member"]))
    return out


def _grid(rows: Sequence[Mapping[str, Any]], family: str, n: int, step: float
          ) -> list[Mapping[str, Any]]:
    """Member 0 of the nominal grid of one family, sites per span and step, by delay."""
    sel = [r for r in rows if r["family"] == family and r["per_span"] == n
           and _same(r["step"], step) and r["variant"] == "nominal" and not r["member"]]
    return sorted(sel, key=lambda r: r["delay"])


def tolerance(rows: Sequence[Mapping[str, Any]], benefit: float) -> list[dict[str, Any]]:
    """Per family, sites per span and step: ``max_delay`` [s], the largest delay of the grid
    up to which every delay is tolerated with ``benefit_long >= benefit`` (NaN: not even the
    first), the peak force [N] / power [W] there, and the benefit there."""
    out = []
    for step in (STEP, STEP_1MS):
        for f in FAMILIES:
            if f == "open":
                continue
            for n in PER_SPAN:
                grid = _grid(rows, f, n, step)
                if not grid:
                    continue
                best = None
                for r in grid:
                    if not (r["tolerated"] and r["benefit_long"] >= benefit):
                        break
                    best = r
                out.append({"family": f, "per_span": n, "step": step, "benefit": benefit,
                            "max_delay": best["delay"] if best else math.nan,
                            "grid_max": grid[-1]["delay"],
                            "peak_force": best["peak_force"] if best else math.nan,
                            "peak_power": best["peak_power"] if best else math.nan,
                            "benefit_long": best["benefit_long"] if best else math.nan})
    return out


def ensembles(rows: Sequence[Mapping[str, Any]]) -> list[dict[str, Any]]:
    """Per configuration run with more than one member: members, completed, long-span RMS
    mean / sd / min / max [m], benefit of the mean (vs the open-loop ensemble), largest peak
    force [N]."""
    groups: dict[tuple, list[Mapping[str, Any]]] = {}
    for r in rows:
        groups.setdefault((r["family"], r["per_span"], r["delay"], r["step"], r["variant"]),
                          []).append(r)
    out = []
    for (f, n, d, step, v), members in groups.items():
        if len(members) < 2:
            continue
        ok = [m for m in members if m["status"] == "ok"]
        s = ensemble_stat([m["long_rms_m"] for m in ok])
        ref_mean = members[0].get("benefit_long", math.nan)
        ref_mean = (members[0]["long_rms_m"] / (1 - ref_mean)
                    if math.isfinite(ref_mean) and ref_mean < 1 else math.nan)
        out.append({"family": f, "per_span": n, "delay": d, "step": step, "variant": v,
                    "members": len(members), "completed": len(ok), "long_rms_m": s.mean,
                    "long_rms_sd_m": s.sd,
                    "long_rms_min_m": min((m["long_rms_m"] for m in ok), default=math.nan),
                    "long_rms_max_m": max((m["long_rms_m"] for m in ok), default=math.nan),
                    "benefit_long": 1 - s.mean / ref_mean if math.isfinite(ref_mean)
                    else math.nan,
                    "all_tolerated": float(all(m["tolerated"] for m in members)),
                    "peak_force": max((m["peak_force"] for m in ok), default=math.nan)})
    order = {f: i for i, f in enumerate(FAMILIES)}
    out.sort(key=lambda e: (order.get(e["family"], 99), e["per_span"], e["delay"]))
    return out


# -- figures -------------------------------------------------------------------------------
def _axes(nrows: int, ncols: int):
    import matplotlib.pyplot as plt

    return plt.subplots(nrows, ncols, figsize=(4.0 * ncols, 3.2 * nrows), sharex="row",
                        squeeze=False, layout="constrained")


def _legend(axes, **kwargs: Any) -> None:
    """One legend, in the first panel that has labelled lines."""
    for ax in axes.flat:
        if ax.get_legend_handles_labels()[0]:
            ax.legend(fontsize=6, **kwargs)
            return


def _steps(rows: Sequence[Mapping[str, Any]]) -> list[tuple[float, tuple[float, ...]]]:
    have = {r["step"] for r in rows}
    return [(s, d) for s, d in ((STEP, DELAYS), (STEP_1MS, DELAYS_1MS))
            if any(_same(s, h) for h in have)]


def _panels(rows: Sequence[Mapping[str, Any]], path: Path, draw, ylabel: str, title: str,
            yscale: dict[str, Any]) -> Path:
    """A panel per step (rows) and sites per span (columns); ``draw(ax, family, color,
    linestyle, grid)`` per family."""
    from drillcosim.cosim.scenario.plots import save_figure

    steps = _steps(rows)
    fig, axes = _axes(len(steps), len(PER_SPAN))
    for i, (step, _delays) in enumerate(steps):
        for j, n in enumerate(PER_SPAN):
            ax = axes[i, j]
            for f, (c, ls) in _STYLE.items():
                draw(ax, f, c, ls, _grid(rows, f, n, step))
            if yscale:
                ax.set_yscale(**yscale)
            ax.set_title(f"{n} site(s)/span, H = {step * 1e3:g} ms", fontsize=9)
            ax.set_xlabel("actuator delay [ms]")
        axes[i, 0].set_ylabel(ylabel)
    _legend(axes)
    fig.suptitle(title, fontsize=9)
    return save_figure(fig, path)


def plot_growth(rows: Sequence[Mapping[str, Any]], path: Path) -> Path:
    """Predicted growth rate vs delay (lines, symlog) per family; the simulated verdict as
    markers on them (o tolerated, x unstable, s undecided above the margin's noise)."""
    def draw(ax, f, c, ls, g):
        if not g:
            return
        x = [r["delay"] * 1e3 for r in g]
        ax.plot(x, [r["predicted_growth_rate"] for r in g], color=c, ls=ls, lw=1,
                label=_LABEL[f])
        for r in g:
            m = "o" if r["below_margin"] else "x" if r["verdict"] == "unstable" else "s"
            ax.plot(r["delay"] * 1e3, r["predicted_growth_rate"], m, color=c, ms=4,
                    mfc="none" if m == "o" else c)
        ax.axhline(0.0, color="k", lw=0.6)

    return _panels(rows, path, draw, "predicted growth rate [1/s]", "lines: linear "
                   "prediction; markers: simulation (o stable, x unstable, s undecided)",
                   {"value": "symlog", "linthresh": 0.1})


def _plot_metric(rows: Sequence[Mapping[str, Any]], path: Path, key: str, scale: float,
                 ylabel: str, log: bool = False) -> Path:
    def draw(ax, f, c, ls, g):
        g = [r for r in g if r["below_margin"]]
        if g:
            ax.plot([r["delay"] * 1e3 for r in g], [r[key] * scale for r in g], color=c,
                    ls=ls, marker="o", ms=3, lw=1, label=_LABEL[f])

    return _panels(rows, path, draw, ylabel, "completed runs below the growth margin "
                   "(unstable points left out)", {"value": "log"} if log else {})


def plot_benefit(rows: Sequence[Mapping[str, Any]], path: Path) -> Path:
    """Long-span benefit [%] vs delay per family (stable runs)."""
    return _plot_metric(rows, path, "benefit_long", 100.0,
                        "long-span benefit 1 - RMS/RMS_open [%]")


def plot_force(rows: Sequence[Mapping[str, Any]], path: Path) -> Path:
    """Peak actuator force [kN] vs delay per family (stable runs)."""
    return _plot_metric(rows, path, "peak_force", 1e-3, "peak actuator force [kN]", log=True)


# -- markdown ------------------------------------------------------------------------------
def _fmt(x: Any, spec: str) -> str:
    return format(x, spec) if isinstance(x, float) and math.isfinite(x) else "-"


def _cell(r: Mapping[str, Any] | None) -> str:
    """A verdict/benefit/force cell."""
    if r is None:
        return ""
    if r["status"] == "diverged":
        return f"x ({r['end_time']:.2g} s)"
    v = "ok" if r["tolerated"] else ("sim ok, pred. unst." if r["below_margin"] else
                                     "x" if r["verdict"] == "unstable" else "?")
    return (f"{v} {_fmt(r['benefit_long'] * 100, '.0f')} % "
            f"{_fmt(r['peak_force'] / 1e3, '.3g')} kN")


def markdown(rows: Sequence[Mapping[str, Any]], raw: Sequence[Mapping[str, Any]]) -> str:
    """The report's tables."""
    refs = open_references(raw)
    lines = ["Open-loop references (4 members; long / short span RMS radial deflection over "
             "the last third):", "", "| run plant | H [ms] | long RMS [mm] mean +- sd | "
             "short RMS [mm] | member 0 long [mm] |", "|---|---|---|---|---|"]
    for (v, step), e in sorted(refs.items(), key=lambda kv: (kv[0][1], kv[0][0])):
        r0 = e.get("row", {})
        lines.append(f"| {v} | {step * 1e3:g} | {_fmt(e['long_rms_m'] * 1e3, '.2f')} +- "
                     f"{_fmt(e['long_rms_sd_m'] * 1e3, '.2f')} | "
                     f"{_fmt(e['short_rms_m'] * 1e3, '.2f')} | "
                     f"{_fmt(r0.get('long_rms_m', math.nan) * 1e3, '.2f')} |")
    lines += [""]
    for step, delays in _steps(rows):
        lines += [f"Nominal grid at H = {step * 1e3:g} ms (member 0; cell: verdict, long-span "
                  "benefit vs the open-loop ensemble, peak force; ok = stable in simulation and "
                  "prediction; x = unstable, in parentheses the time it diverged):", "",
                  "| family | sites/span | " + " | ".join(f"{d * 1e3:g} ms" for d in delays)
                  + " |", "|---|---|" + "---|" * len(delays)]
        for f in FAMILIES:
            for n in PER_SPAN:
                g = {round(r["delay"], 9): r for r in _grid(rows, f, n, step)}
                if g:
                    lines.append(f"| {_LABEL[f]} | {n} | " + " | ".join(
                        _cell(g.get(round(d, 9))) for d in delays) + " |")
        lines.append("")
    agree = [r for r in rows if r["status"] != "error" and math.isfinite(
        r["predicted_growth_rate"]) and r["verdict"] in ("stable", "unstable", "undecided")]
    pairs = {(p, s): 0 for p in ("stable", "unstable") for s in ("stable", "unstable", "other")}
    for r in agree:
        p = "stable" if r["predicted_stable"] else "unstable"
        s = ("stable" if r["below_margin"] else "unstable" if r["verdict"] == "unstable"
             else "other")
        pairs[(p, s)] += 1
    lines += ["Prediction vs simulation (every closed-loop run; simulated stable = completed "
              "below the growth margin):", "", "| predicted | simulated stable | simulated "
              "unstable | undecided |", "|---|---|---|---|"]
    for p in ("stable", "unstable"):
        lines.append(f"| {p} | {pairs[(p, 'stable')]} | {pairs[(p, 'unstable')]} | "
                     f"{pairs[(p, 'other')]} |")
    lines.append("")
    for b in BENEFITS:
        lines += [f"Delay tolerated with a long-span benefit >= {b:.0%} (every grid delay up "
                  "to it stable in simulation and prediction with that benefit):", "",
                  "| family | sites/span | H [ms] | max delay [ms] | benefit there | peak force "
                  "[kN] | peak power [W] |", "|---|---|---|---|---|---|---|"]
        none = []
        for t in tolerance(rows, b):
            if not math.isfinite(t["max_delay"]):
                none.append(f"{_LABEL[t['family']]} {t['per_span']}/span at "
                            f"{t['step'] * 1e3:g} ms")
                continue
            md = (f">= {t['max_delay'] * 1e3:g} (all)" if _same(t["max_delay"], t["grid_max"])
                  else _fmt(t["max_delay"] * 1e3, "g") if math.isfinite(t["max_delay"])
                  else "none")
            lines.append(f"| {_LABEL[t['family']]} | {t['per_span']} | {t['step'] * 1e3:g} | "
                         f"{md} | {_fmt(t['benefit_long'] * 100, '.0f')} % | "
                         f"{_fmt(t['peak_force'] / 1e3, '.3g')} | "
                         f"{_fmt(t['peak_power'], '.3g')} |")
        lines += ["", "None (unstable or below that benefit from 0 ms on): "
                  f"{', '.join(none)}." if none else "", ""]
    variants = [v for v in VARIANTS if v != "nominal"]
    robust = [r for r in rows if r["variant"] != "nominal" and not r["member"]]
    if robust:
        lines += ["Robustness at H = 0.25 ms (designed on the calibrated plant for the delay "
                  "shown unless said otherwise; cell as above, the benefit against the open "
                  "loop of the run plant; nominal = the grid's run):", "",
                  "| family | sites/span | delay [ms] | nominal | " + " | ".join(variants)
                  + " |", "|---|---|---|---|" + "---|" * len(variants)]
        keys = sorted({(r["family"], r["per_span"], r["delay"]) for r in robust},
                      key=lambda k: (list(FAMILIES).index(k[0]), k[1], k[2]))
        at = {(r["family"], r["per_span"], round(r["delay"], 9), r["variant"]): r
              for r in rows if _same(r["step"], STEP) and not r["member"]}
        for f, n, d in keys:
            cells = [_cell(at.get((f, n, round(d, 9), v))) for v in ("nominal", *variants)]
            lines.append(f"| {_LABEL[f]} | {n:.0f} | {d * 1e3:g} | " + " | ".join(cells) + " |")
        lines.append("")
    ens = ensembles(rows)
    if ens:
        lines += ["Ensembles (4 members, H = 0.25 ms; member 0 = the grid's run, the others "
                  "start 1 um apart):", "", "| family | sites/span | delay [ms] | completed | "
                  "long RMS [mm] mean +- sd (min-max) | benefit of the mean | all tolerated | "
                  "peak force [kN] |", "|---|---|---|---|---|---|---|---|"]
        for e in ens:
            lines.append(
                f"| {_LABEL[e['family']]} | {e['per_span']:.0f} | {e['delay'] * 1e3:g} | "
                f"{e['completed']}/{e['members']} | {_fmt(e['long_rms_m'] * 1e3, '.2f')} +- "
                f"{_fmt(e['long_rms_sd_m'] * 1e3, '.2f')} ({_fmt(e['long_rms_min_m'] * 1e3, '.2f')}"
                f"-{_fmt(e['long_rms_max_m'] * 1e3, '.2f')}) | "
                f"{_fmt(e['benefit_long'] * 100, '.0f')} % | "
                f"{'yes' if e['all_tolerated'] else 'no'} | {_fmt(e['peak_force'] / 1e3, '.3g')} |")
        lines.append("")
    return "\n".join(lines)


def report(out_dir: str | Path, figures: str | Path | None = None) -> str:
    """Write ``control_compare.csv`` and the figures (``control_linear.png`` of the
    linear-regime check, :mod:`.linear`, and the study's three) into ``figures`` (default
    ``out_dir/report``); return the markdown."""
    out = Path(out_dir)
    fig_dir = Path(figures) if figures is not None else out / "report"
    fig_dir.mkdir(parents=True, exist_ok=True)
    text, paths = "", []
    lin = linear.load_linear(out)
    if lin:
        text += linear.markdown(lin) + "\n"
        paths.append(linear.plot(lin, fig_dir / "control_linear.png"))
    raw = CompareTable(out).rows
    if raw:
        rows = compare_rows(raw)
        atomic_write(fig_dir / "control_compare.csv", rows_csv(rows))
        text += markdown(rows, raw) + "\n"
        paths += [plot_growth(rows, fig_dir / "control_growth.png"),
                  plot_benefit(rows, fig_dir / "control_benefit.png"),
                  plot_force(rows, fig_dir / "control_force.png")]
    return text + "\n".join(f"![]({p})" for p in paths) + "\n"
