"""Maps of a sweep: stability and control benefit over (actuator delay, gain), one panel per
communication step, with the linear prediction overlaid; and the growth rate against the delay.

* ``stability_map.png``: each point a marker by verdict (stable / unstable: growing envelope /
  diverged / undecided / error), the legend stating the rules in words
  (:func:`cosim.study.verdict.rule_text`); a ring around each point whose verdict differs from
  the linear prediction, coloured by why (below the margin, wall contact, unexplained:
  :func:`cosim.study.verdict.compare_with_prediction`); the predicted critical gain ``K_c(tau)``
  as a line (unstable above it, shaded).
* ``benefit_map.png``: the long span's control benefit ``1 - RMS/RMS_open`` (colour), unstable
  points crossed out, points whose benefit cannot be judged (the open-loop reference still
  building up: :func:`cosim.study.verdict.benefit_note`) grey, same boundary.
* ``growth_rate.png``: per step, the measured growth rate over the open loop (``growth_excess``,
  +-2 standard errors) against the delay, one colour per gain, with the predicted growth rate
  of each gain as a line and the verdicts' margin.

The prediction (:mod:`cosim.study.prediction`) is computed once, with a progress bar, and kept in
``prediction.json`` next to the table. A sweep of another gain than the strain controller's
(``gain_key``, e.g. ``top_drive_controller.p_gain``) gets ``stick_slip_map.png`` instead: the
stick-slip severity (colour) over (actuator delay, gain), diverged points crossed out.
"""

from __future__ import annotations

import json
import math
import os
import textwrap
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from drillcosim.cosim.master.files import atomic_write

from .prediction import predicted_boundary, predicted_curves, prediction_progress
from .table import read_table, reference_key
from .verdict import GROWTH_MARGIN, benefit_note, rule_text

__all__ = ["map_figures", "plot_maps", "predicted_boundary"]

#: Axis label of a sweep's gain, by gain key.
GAIN_LABELS = {"controller.gain": "controller gain K [N per unit strain]",
               "top_drive_controller.p_gain": "top-drive P gain [N m s/rad]",
               "top_drive_controller.i_gain": "top-drive I gain [N m/rad]"}
#: Ring colour of a point whose verdict differs from the prediction, by the note's first words.
DIFFERS = {"below the margin": ("tab:purple", "predicted growth below the "
                                f"{GROWTH_MARGIN:g} 1/s margin"),
           "wall contact": ("saddlebrown", "wall contact (not in the linear model)"),
           "unexplained": ("magenta", "no known reason")}
#: Points of the fine grids of the predicted lines.
FINE = 13


@dataclass
class _Layout:
    """What the maps show: rows, the panels and the fine grids of the prediction."""

    rows: list[dict[str, Any]]
    by_key: dict[str, dict[str, Any]]
    steps: list[float]
    delays: list[float]
    gains: list[float]
    by_step: bool           # one delay, several steps: one panel over (H, K)
    scene: str
    stop: float
    engine: str
    overrides: dict | None

    @property
    def gain_range(self) -> tuple[float, float]:
        return self.gains[0] / 10, self.gains[-1] * 10

    def panels(self) -> list[tuple[str, list[dict[str, Any]], Callable, str, float]]:
        """``(title, rows, x of a row [s], x label, step or delay of the panel)``."""
        if self.by_step:
            return [(f"actuator delay = {self.delays[0] * 1e3:g} ms", self.rows,
                     lambda r: r["step"], "communication step H [ms]", self.delays[0])]
        return [(f"communication step H = {h * 1e3:g} ms", [r for r in self.rows
                                                             if r["step"] == h],
                 lambda r: r["delay"], "actuator delay $\\tau$ [ms]", h) for h in self.steps]

    def fine(self) -> list[float]:
        """The fine x grid [s] (steps or delays) of the predicted lines."""
        if self.by_step:
            grid = np.linspace(min(self.steps), max(self.steps), FINE)
            return sorted(set(grid.tolist()) | set(self.steps))
        return sorted(set(np.linspace(0.0, max(self.delays), FINE).tolist()) | set(self.delays))

    def xlim(self) -> tuple[float, float]:
        xs = self.steps if self.by_step else self.delays
        lo, hi = (min(xs) if self.by_step else 0.0) * 1e3, max(xs) * 1e3
        pad = 0.05 * max(hi - lo, 1e-3)
        return lo - pad, hi + pad

    def reference(self, row: dict[str, Any]) -> dict[str, Any] | None:
        return self.by_key.get(reference_key(row["key"]))


def _layout(folder: Path, meta: dict[str, Any]) -> _Layout:
    every = read_table(folder)
    rows = [r for r in every if r["kind"] == "closed_loop"]
    if not rows:
        raise ValueError(f"{folder}: no closed-loop points to map")
    steps = sorted({r["step"] for r in rows})
    delays = sorted({r["delay"] for r in rows})
    return _Layout(rows, {r["key"]: r for r in every}, steps, delays,
                   sorted({r["gain"] for r in rows if r["gain"] > 0}) or [1.0],
                   len(delays) == 1 and len(steps) > 1, rows[0]["scene"], rows[0]["stop_time"],
                   rows[0]["engine"], meta.get("overrides") or None)


def _prediction(folder: Path, lay: _Layout, progress: bool | None) -> dict[str, Any]:
    """The boundary and the growth curves, from ``prediction.json`` if it holds them."""
    path = folder / "prediction.json"
    fine = lay.fine()
    steps = fine if lay.by_step else lay.steps
    delays = lay.delays if lay.by_step else fine
    ident = {"scene": lay.scene, "steps": steps, "delays": delays, "gains": lay.gains,
             "gain_range": list(lay.gain_range), "overrides": lay.overrides or {}, "version": 2}
    if path.exists():
        try:
            saved = json.loads(path.read_text())
            if saved.get("ident") == ident:
                return _decoded(saved)
        except (ValueError, KeyError, TypeError):
            pass
    bar = prediction_progress(len(steps) * len(delays) * (1 + len(lay.gains)), progress)
    try:
        boundary = predicted_boundary(lay.scene, steps, delays, lay.gain_range, lay.overrides,
                                      progress=bar)
        curves = predicted_curves(lay.scene, lay.gains, steps, delays, lay.overrides, bar)
    finally:
        bar.close()
    saved = {"ident": ident,
             "boundary": {repr(h): v for h, v in boundary.items()},
             "curves": [[k, h, v] for (k, h), v in curves.items()]}
    atomic_write(path, json.dumps(saved, default=lambda x: None if not math.isfinite(x) else x))
    return _decoded(json.loads(path.read_text()))


def _decoded(saved: dict[str, Any]) -> dict[str, Any]:
    def num(x: Any, missing: float) -> float:
        return missing if x is None else float(x)

    ident = saved["ident"]
    return {"steps": ident["steps"], "delays": ident["delays"],
            "boundary": {float(h): [(d, num(k, math.inf)) for d, k in v]
                         for h, v in saved["boundary"].items()},
            "curves": {(float(k), float(h)): [num(g, math.nan) for g in v]
                       for k, h, v in saved["curves"]}}


def _boundary_line(ax, pred: dict[str, Any], lay: _Layout, panel: float) -> None:
    gmin, gmax = lay.gain_range
    if lay.by_step:
        pts = [(h, v[0][1]) for h, v in sorted(pred["boundary"].items())]
    else:
        pts = pred["boundary"][panel]
    x = np.array([p[0] for p in pts]) * 1e3
    k = np.clip(np.array([p[1] for p in pts], dtype=float), gmin, gmax)
    ax.plot(x, k, "k-", lw=1.8, label="predicted boundary (linear, $\\rho = 1$)")
    ax.fill_between(x, k, gmax, color="0.85", zorder=0, label="predicted unstable")


def _figure(lay: _Layout, n: int, sharey: bool = True):
    """A figure of ``n`` panels in a row (a plain ``Figure``: no pyplot state)."""
    from matplotlib.figure import Figure

    fig = Figure(figsize=(4.6 * n + 2.8, 5.2), layout="constrained")
    return fig, fig.subplots(1, n, squeeze=False, sharey=sharey)


def _gain_axes(ax, lay: _Layout, xlabel: str, title: str) -> None:
    ax.set_yscale("log")
    ax.set_ylim(*lay.gain_range)
    ax.set_xlim(*lay.xlim())
    ax.set_xlabel(xlabel)
    ax.set_title(title)
    ax.grid(True, which="major", alpha=0.3)


def _legend(fig, axes) -> None:
    handles, labels = [], []
    for ax in axes:
        for hd, lb in zip(*ax.get_legend_handles_labels()):
            if lb not in labels:
                handles.append(hd)
                labels.append(lb)
    if handles:
        # long entries (the rules in words): one column unless the panels are wide
        ncol = 1 if len(axes) < 2 else 2
        fig.legend(handles, labels, loc="outside lower center", ncol=ncol, fontsize=8)


def _stability_map(lay: _Layout, pred: dict[str, Any] | None):
    rules = rule_text(lay.stop)
    styles = [(lambda r: r["verdict"] == "stable", "o", "tab:green", rules["stable"]),
              (lambda r: r["verdict"] == "unstable" and r["status"] == "ok", "^", "tab:orange",
               rules["unstable"]),
              (lambda r: r["status"] == "diverged", "X", "tab:red", rules["diverged"]),
              (lambda r: r["verdict"] == "undecided", "D", "0.6", rules["undecided"]),
              (lambda r: r["status"] == "error", "s", "0.3", rules["error"])]
    panels = lay.panels()
    fig, axes = _figure(lay, len(panels))
    for ax, (title, sel, xof, xlabel, panel) in zip(axes[0], panels):
        x = np.array([xof(r) for r in sel]) * 1e3
        k = np.array([max(r["gain"], lay.gain_range[0]) for r in sel])
        if pred is not None:
            _boundary_line(ax, pred, lay, panel)
        for test, mk, col, lab in styles:
            m = np.array([bool(test(r)) for r in sel], dtype=bool)
            if m.any():
                ax.scatter(x[m], k[m], marker=mk, c=col, s=60, label=lab, zorder=3,
                           edgecolors="k", linewidths=0.5)
        for start, (col, why) in DIFFERS.items():
            m = np.array([r["agrees_with_prediction"] == 0.0 and
                          str(r["prediction_note"]).startswith(start) for r in sel], dtype=bool)
            if m.any():
                ax.scatter(x[m], k[m], marker="o", s=260, facecolors="none", edgecolors=col,
                           linewidths=2.0, zorder=4, label=f"differs from the prediction: {why}")
        _gain_axes(ax, lay, xlabel, title)
    axes[0][0].set_ylabel(GAIN_LABELS["controller.gain"])
    _legend(fig, axes[0])
    fig.suptitle(f"Stability of the strain-feedback loop\n{lay.scene}, engine '{lay.engine}', "
                 f"{lay.stop:g} s runs", fontsize=11)
    return fig


def _benefit_map(lay: _Layout, pred: dict[str, Any] | None):
    from matplotlib.colors import TwoSlopeNorm

    panels = lay.panels()
    fig, axes = _figure(lay, len(panels))
    handle, notes = None, set()
    for ax, (title, sel, xof, xlabel, panel) in zip(axes[0], panels):
        x = np.array([xof(r) for r in sel]) * 1e3
        k = np.array([max(r["gain"], lay.gain_range[0]) for r in sel])
        if pred is not None:
            _boundary_line(ax, pred, lay, panel)
        b = np.array([r["benefit_long"] for r in sel], dtype=float)
        ok = np.isfinite(b) & np.array([r["stable"] == 1.0 for r in sel])
        note = [benefit_note(lay.reference(r), ("long",)) for r in sel]
        grey = ok & np.array([bool(n) for n in note])
        notes.update(n for n, g in zip(note, grey) if g)
        judged = ok & ~grey
        handle = ax.scatter(x[judged], k[judged], c=np.clip(b[judged], -1, 1), cmap="RdYlGn",
                            norm=TwoSlopeNorm(0.0, -1.0, 1.0), s=140, marker="s",
                            edgecolors="k", linewidths=0.5, zorder=3)
        if grey.any():
            ax.scatter(x[grey], k[grey], c="0.8", s=140, marker="s", edgecolors="0.5",
                       linewidths=0.5, zorder=3,
                       label="not judged: open loop still building up (run longer)")
        labelled = len(set(x[ok])) <= 6     # values as text only if legible
        for xi, yi, v, g in zip(x[ok], k[ok], b[ok], grey[ok]) if labelled else ():
            ax.annotate(f"{v:.2f}", (xi, yi), textcoords="offset points", xytext=(0, 9),
                        ha="center", fontsize=7, color="0.5" if g else "k")
        if (~ok).any():
            ax.scatter(x[~ok], k[~ok], marker="x", c="tab:red", s=50, zorder=3,
                       label="unstable / no benefit")
        _gain_axes(ax, lay, xlabel, title)
    axes[0][0].set_ylabel(GAIN_LABELS["controller.gain"])
    _legend(fig, axes[0])
    if handle is not None:
        fig.colorbar(handle, ax=axes[0].tolist(), label="long-span benefit 1 - RMS/RMS$_{open}$")
    line = "\n" + "\n".join(textwrap.wrap(sorted(notes)[0], 90)) if notes else ""
    fig.suptitle(f"Control benefit (long span radial deflection)\n{lay.scene}, engine "
                 f"'{lay.engine}', {lay.stop:g} s runs{line}", fontsize=10 if notes else 11)
    return fig


def _growth_figure(lay: _Layout, pred: dict[str, Any] | None):
    from matplotlib.lines import Line2D

    panels = lay.panels()
    fig, axes = _figure(lay, len(panels), sharey=False)
    colors = {k: c for k, c in zip(lay.gains, _colors(len(lay.gains)))}
    for ax, (title, sel, xof, xlabel, panel) in zip(axes[0], panels):
        top = 1.0
        for k in lay.gains:
            mine = [r for r in sel if r["gain"] == k]
            x = np.array([xof(r) for r in mine]) * 1e3
            g = np.array([r["growth_excess"] for r in mine], dtype=float)
            err = np.array([2 * math.hypot(r["growth_noise"], (lay.reference(r) or {}).get(
                "growth_noise", math.nan)) for r in mine], dtype=float)
            fin = np.isfinite(g)
            ax.errorbar(x[fin], g[fin], yerr=np.where(np.isfinite(err[fin]), err[fin], 0.0),
                        fmt="o", color=colors[k], ms=6, capsize=3, zorder=3)
            top = max(top, float(np.max(np.abs(g[fin]), initial=0.0)))
            if pred is not None:
                xs, ys = _curve(pred, lay, k, panel)
                ax.plot(np.array(xs) * 1e3, ys, "-", color=colors[k], lw=1.4)
                top = max(top, float(np.nanmax(np.abs(ys), initial=0.0)))
            div = np.array([r["status"] == "diverged" for r in mine], dtype=bool)
            if div.any():
                ax.scatter(x[div], np.full(div.sum(), 1.5 * top), marker="X", color=colors[k],
                           s=80, edgecolors="k", linewidths=0.5, zorder=4)
        ax.axhline(GROWTH_MARGIN, color="k", ls="--", lw=1.0)
        ax.axhline(0.0, color="0.5", lw=0.8)
        ax.set_yscale("symlog", linthresh=1.0)
        ax.set_ylim(-2.0 * top, 2.5 * top)
        ax.set_xlim(*lay.xlim())
        ax.set_xlabel(xlabel)
        ax.set_ylabel("growth rate [1/s]")
        ax.set_title(title)
        ax.grid(True, which="major", alpha=0.3)
        handles = [Line2D([], [], color=colors[k], marker="o", ls="-",
                          label=f"K = {k:.3g} N/strain") for k in lay.gains]
        handles += [Line2D([], [], color="k", marker="o", ls="none",
                           label="measured: envelope growth over open loop (+-2 s.e.)"),
                    Line2D([], [], color="k", marker="X", ls="none", label="diverged")]
        if pred is not None:
            handles.append(Line2D([], [], color="k", ls="-", label="predicted (linear)"))
        handles.append(Line2D([], [], color="k", ls="--",
                              label=f"verdict margin {GROWTH_MARGIN:g} 1/s"))
        ax.legend(handles=handles, fontsize=7, loc="upper left")
    fig.suptitle(f"Growth rate of the strain loop: measured and predicted\n{lay.scene}, engine "
                 f"'{lay.engine}', {lay.stop:g} s runs", fontsize=11)
    return fig


def _curve(pred: dict[str, Any], lay: _Layout, gain: float, panel: float
           ) -> tuple[list[float], list[float]]:
    """The predicted growth rate of ``gain`` along the panel's x (delays, or steps)."""
    if lay.by_step:
        return pred["steps"], [pred["curves"][(gain, h)][0] for h in pred["steps"]]
    return pred["delays"], pred["curves"][(gain, panel)]


def _colors(n: int) -> list:
    import matplotlib

    cmap = matplotlib.colormaps["viridis"]
    return [cmap(0.85 * i / max(n - 1, 1)) for i in range(n)]


def map_figures(folder: str | os.PathLike, predict: bool = True,
                progress: bool | None = None) -> dict[str, Any]:
    """The maps of a sweep of the strain gain as matplotlib figures: ``{"stability_map": Figure,
    "benefit_map": ..., "growth_rate": ...}`` (arguments: :func:`plot_maps`)."""
    folder = Path(folder)
    meta: dict[str, Any] = {}
    if (folder / "sweep.json").exists():
        meta = json.loads((folder / "sweep.json").read_text()).get("spec", {})
    lay = _layout(folder, meta)
    pred = _prediction(folder, lay, progress) if predict else None
    return {"stability_map": _stability_map(lay, pred), "benefit_map": _benefit_map(lay, pred),
            "growth_rate": _growth_figure(lay, pred)}


def plot_maps(folder: str | os.PathLike, predict: bool = True,
              progress: bool | None = None) -> list[Path]:
    """Write ``stability_map.png``, ``benefit_map.png`` and ``growth_rate.png`` for a sweep
    folder (``stick_slip_map.png`` for a sweep of a top-drive gain).

    Parameters
    ----------
    folder : path-like
        A :func:`cosim.study.sweep.execute_sweep` output folder.
    predict : bool
        Overlay the linear prediction (computed once, cached in ``prediction.json``).
    progress : bool or None
        Progress bar of the prediction (None: only on a terminal).

    Returns
    -------
    list of Path
    """
    import matplotlib

    matplotlib.use("Agg")
    from drillcosim.cosim.scenario.plots import save_figure

    folder = Path(folder)
    meta: dict[str, Any] = {}
    if (folder / "sweep.json").exists():
        meta = json.loads((folder / "sweep.json").read_text()).get("spec", {})
    gain_key = meta.get("gain_key", "controller.gain")
    if gain_key != "controller.gain":
        rows = [r for r in read_table(folder) if r["kind"] == "closed_loop"]
        if not rows:
            raise ValueError(f"{folder}: no closed-loop points to map")
        return [_stick_slip_map(folder, rows, gain_key)]
    return [save_figure(fig, folder / f"{name}.png", dpi=110)
            for name, fig in map_figures(folder, predict, progress).items()]


def _stick_slip_map(folder: Path, rows: Sequence[dict[str, Any]], gain_key: str) -> Path:
    """``stick_slip_map.png``: severity over (delay, gain), one panel per step."""
    import matplotlib.pyplot as plt

    from drillcosim.cosim.scenario.plots import save_figure

    steps = sorted({r["step"] for r in rows})
    fig, axes = plt.subplots(1, len(steps), figsize=(4.6 * len(steps) + 2.8, 4.8),
                             squeeze=False, sharey=True, layout="constrained")
    handle = None
    top = 3.0  # full stick-slip is ~2 (the bit stops, slips at ~3x its mean speed); above: clipped
    for ax, h in zip(axes[0], steps):
        sel = [r for r in rows if r["step"] == h]
        d = np.array([r["delay"] for r in sel]) * 1e3
        k = np.array([r["gain"] for r in sel])
        sev = np.array([r["stick_slip_severity"] for r in sel], dtype=float)
        ok = np.isfinite(sev)
        handle = ax.scatter(d[ok], k[ok], c=sev[ok], cmap="viridis_r", vmin=0.0, vmax=top,
                            s=140, marker="s", edgecolors="k", linewidths=0.5, zorder=3)
        for x, y, v in zip(d[ok], k[ok], sev[ok]):
            ax.annotate(f"{v:.2g}", (x, y), textcoords="offset points", xytext=(0, 9),
                        ha="center", fontsize=7)
        if (~ok).any():
            ax.scatter(d[~ok], k[~ok], marker="x", c="tab:red", s=50, zorder=3,
                       label="diverged / error")
        ax.set_yscale("log")
        ax.set_xlabel("actuator delay $\\tau$ [ms]")
        ax.set_title(f"communication step H = {h * 1e3:g} ms")
        ax.grid(True, which="major", alpha=0.3)
    axes[0][0].set_ylabel(GAIN_LABELS.get(gain_key, gain_key))
    if handle is not None:
        fig.colorbar(handle, ax=axes[0].tolist(), extend="max",
                     label="stick-slip severity (max - min) / mean bit speed")
    fig.suptitle(f"Stick-slip severity\n{rows[0]['scene']}, engine '{rows[0]['engine']}', "
                 f"{rows[0]['stop_time']:g} s runs", fontsize=11)
    return save_figure(fig, folder / "stick_slip_map.png", dpi=110)
