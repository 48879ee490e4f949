"""Maps of a sweep: stability and control benefit over (actuator delay, gain), one panel
per communication step, with the linear prediction's boundary overlaid.

* ``stability_map.png``: each point a marker (stable / unstable: growing envelope /
  diverged / error); the predicted critical gain ``K_c(tau)`` of
  :class:`cosim.study.stability.LoopModel` as a line (unstable above it).
* ``benefit_map.png``: the long span's control benefit ``1 - RMS/RMS_open`` (colour),
  unstable points crossed out, same boundary.

The predicted boundary is cached in ``prediction.json`` next to the table. A sweep of another
gain than the strain controller's (``gain_key``, e.g. ``top_drive_controller.p_gain``) gets
``stick_slip_map.png`` instead: the stick-slip severity (colour) over (actuator delay, gain),
diverged points crossed out.
"""

from __future__ import annotations

import json
import math
import os
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from drillcosim.cosim.master.files import atomic_write

from .stability import LoopModel
from .table import read_table

__all__ = ["plot_maps", "predicted_boundary"]

#: Axis label of a sweep's gain, by gain key.
GAIN_LABELS = {"controller.gain": "controller gain K [N per unit strain]",
               "top_drive_controller.p_gain": "top-drive P gain [N m s/rad]",
               "top_drive_controller.i_gain": "top-drive I gain [N m/rad]"}


def predicted_boundary(scene: str, steps: Sequence[float], delays: Sequence[float],
                       gain_range: tuple[float, float], overrides: dict | None = None,
                       rtol: float = 0.02) -> dict[float, list[tuple[float, float]]]:
    """Critical gain [N/strain] vs actuator delay [s] for each step [s].

    Returns
    -------
    dict
        ``{step: [(delay, critical_gain), ...]}``; ``inf`` where stable over the range,
        ``0`` where unstable at its low end.
    """
    lm = LoopModel.from_scene(scene, overrides=overrides)
    lo, hi = gain_range
    out: dict[float, list[tuple[float, float]]] = {}
    for h in steps:
        out[float(h)] = [(float(d), lm.critical_gain(h, float(d), gain_min=lo, gain_max=hi,
                                                     per_decade=2, rtol=rtol))
                         for d in delays]
    return out


def _cached_boundary(folder: Path, scene: str, steps: list[float], delays: list[float],
                     gain_range: tuple[float, float], overrides: dict | None
                     ) -> dict[float, list[tuple[float, float]]]:
    path = folder / "prediction.json"
    ident = {"scene": scene, "steps": steps, "delays": delays, "gain_range": list(gain_range),
             "overrides": overrides or {}}
    if path.exists():
        try:
            saved = json.loads(path.read_text())
            if saved.get("ident") == ident:
                return {float(k): [tuple(p) for p in v] for k, v in saved["boundary"].items()}
        except (ValueError, KeyError):
            pass
    b = predicted_boundary(scene, steps, delays, gain_range, overrides)
    atomic_write(path, json.dumps({"ident": ident, "boundary": {repr(k): v for k, v in
                                                                b.items()}},
                                  default=lambda x: None if not math.isfinite(x) else x))
    return b


def _boundary_line(ax, pts: list[tuple[float, float]], gmin: float, gmax: float) -> None:
    d = np.array([p[0] for p in pts]) * 1e3
    k = np.array([math.inf if p[1] is None else p[1] for p in pts], dtype=float)
    k = np.clip(k, gmin, gmax)
    ax.plot(d, k, "k-", lw=1.8, label="predicted boundary (linear, $\\rho = 1$)")
    ax.fill_between(d, k, gmax, color="0.85", zorder=0, label="predicted unstable")


def plot_maps(folder: str | os.PathLike, predict: bool = True) -> list[Path]:
    """Write ``stability_map.png`` and ``benefit_map.png`` for a sweep folder.

    Parameters
    ----------
    folder : path-like
        A :func:`cosim.study.sweep.execute_sweep` output folder.
    predict : bool
        Overlay the linear prediction (computed once, cached in ``prediction.json``).

    Returns
    -------
    list of Path
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.colors import TwoSlopeNorm

    from drillcosim.cosim.scenario.plots import save_figure

    folder = Path(folder)
    rows = [r for r in read_table(folder) if r["kind"] == "closed_loop"]
    if not rows:
        raise ValueError(f"{folder}: no closed-loop points to map")
    meta: dict[str, Any] = {}
    if (folder / "sweep.json").exists():
        meta = json.loads((folder / "sweep.json").read_text()).get("spec", {})
    gain_key = meta.get("gain_key", "controller.gain")
    if gain_key != "controller.gain":
        return [_stick_slip_map(folder, rows, gain_key)]
    steps = sorted({r["step"] for r in rows})
    delays = sorted({r["delay"] for r in rows})
    gains = sorted({r["gain"] for r in rows if r["gain"] > 0}) or [1.0]
    gmin, gmax = gains[0] / 10, gains[-1] * 10
    scene = rows[0]["scene"]
    by_step = len(delays) == 1 and len(steps) > 1   # map over (H, K) in one panel
    over = meta.get("overrides") or None
    if by_step:
        d0 = delays[0]
        fine_h = sorted(set(np.linspace(min(steps), max(steps), 13).tolist()) | set(steps))
        panels = [(f"actuator delay = {d0 * 1e3:g} ms", rows,
                   lambda r: r["step"], "communication step H [ms]")]
        if predict:
            b = _cached_boundary(folder, scene, fine_h, [d0], (gmin, gmax), over)
            bounds = [[(h, v[0][1]) for h, v in sorted(b.items())]]
        xs_all = steps
    else:
        panels = [(f"communication step H = {h * 1e3:g} ms", [r for r in rows if r["step"] == h],
                   lambda r: r["delay"], "actuator delay $\\tau$ [ms]") for h in steps]
        if predict:
            fine = sorted(set(np.linspace(0.0, max(delays), 13).tolist()) | set(delays))
            b = _cached_boundary(folder, scene, steps, fine, (gmin, gmax), over)
            bounds = [b[h] for h in steps]
        xs_all = delays
    engine = rows[0]["engine"]
    stop = rows[0]["stop_time"]
    n = len(panels)
    paths = []
    for what in ("stability", "benefit"):
        fig, axes = plt.subplots(1, n, figsize=(4.6 * n + 2.8, 4.8), squeeze=False,
                                 sharey=True, layout="constrained")
        sc_handle = None
        for i, (ax, (title, sel, xof, xlabel)) in enumerate(zip(axes[0], panels)):
            d = np.array([xof(r) for r in sel]) * 1e3
            k = np.array([max(r["gain"], gmin) for r in sel])
            if predict:
                _boundary_line(ax, bounds[i], gmin, gmax)
            if what == "stability":
                styles = [("ok", 1.0, "o", "tab:green", "stable"),
                          ("ok", 0.0, "^", "tab:orange", "unstable (envelope grows)"),
                          ("diverged", None, "X", "tab:red", "diverged"),
                          ("error", None, "s", "0.4", "error")]
                for status, stable, mk, col, lab in styles:
                    m = np.array([r["status"] == status and (stable is None or
                                                            r["stable"] == stable)
                                  for r in sel], dtype=bool)
                    if m.any():
                        ax.scatter(d[m], k[m], marker=mk, c=col, s=60, label=lab, zorder=3,
                                   edgecolors="k", linewidths=0.5)
            else:
                b = np.array([r["benefit_long"] for r in sel], dtype=float)
                ok = np.isfinite(b) & np.array([r["stable"] == 1.0 for r in sel])
                sc_handle = ax.scatter(d[ok], k[ok], c=np.clip(b[ok], -1, 1), cmap="RdYlGn",
                                       norm=TwoSlopeNorm(0.0, -1.0, 1.0), s=140, marker="s",
                                       edgecolors="k", linewidths=0.5, zorder=3)
                labelled = len(set(d[ok])) <= 6     # values as text only if legible
                for x, y, v in zip(d[ok], k[ok], b[ok]) if labelled else ():
                    ax.annotate(f"{v:.2f}", (x, y), textcoords="offset points", xytext=(0, 9),
                                ha="center", fontsize=7)
                if (~ok).any():
                    ax.scatter(d[~ok], k[~ok], marker="x", c="tab:red", s=50, zorder=3,
                               label="unstable / no benefit")
            ax.set_yscale("log")
            ax.set_ylim(gmin, gmax)
            lo, hi = (min(xs_all) if by_step else 0.0) * 1e3, max(xs_all) * 1e3
            pad = 0.05 * max(hi - lo, 1e-3)
            ax.set_xlim(lo - pad, hi + pad)
            ax.set_xlabel(xlabel)
            ax.set_title(title)
            ax.grid(True, which="major", alpha=0.3)
        axes[0][0].set_ylabel(GAIN_LABELS["controller.gain"])
        handles, labels = [], []
        for ax in axes[0]:
            for hd, lb in zip(*ax.get_legend_handles_labels()):
                if lb not in labels:
                    handles.append(hd)
                    labels.append(lb)
        if handles:
            fig.legend(handles, labels, loc="outside lower center", ncol=min(4, len(handles)),
                       fontsize=8)
        if what == "benefit" and sc_handle is not None:
            fig.colorbar(sc_handle, ax=axes[0].tolist(),
                         label="long-span benefit 1 - RMS/RMS$_{open}$")
        title = {"stability": "Stability of the strain-feedback loop",
                 "benefit": "Control benefit (long span radial deflection)"}[what]
        fig.suptitle(f"{title}\n{scene}, engine '{engine}', {stop:g} s runs", fontsize=11)
        paths.append(save_figure(fig, folder / f"{what}_map.png", dpi=110))
    return paths


def _stick_slip_map(folder: Path, rows: list[dict[str, Any]], gain_key: str) -> Path:
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
