"""PNG figures of a run, after the paper's Figs. 9-16: the closed loop against its open-loop
baseline (:mod:`.baseline`, grey), titled with the scene and the controller's settings.

* :class:`OrbitFigure` - lateral X-Y orbit of the long span's middle body over the last few
  revolutions of the top drive, with the wellbore clearance circle (Figs. 9, 15);
* :class:`DeflectionContactFigure` - radial deflection and contact force vs time at every contact
  body (Figs. 10, 12, 14, 16); a body without contact says so instead of a flat line;
* :class:`ActuatorsFigure` - actuator forces C and E (each its own panel) and delivered power vs
  time per site (Figs. 11, 13, 14);
* :class:`AxialTorsionalFigure` - rotary speeds, torques and the bit's axial force vs time (the
  axial-torsional scenes: stick-slip, bit bounce);
* :func:`run_figures` / :func:`plot_run` - all of the above that the recorded outputs allow.

Inputs are the structured arrays of :class:`cosim.master.Result` or
:func:`cosim.scenario.summary.load_results` (columns ``plant.<output>`` /
``controller.<output>``). Dense traces are drawn as envelope bands, sparse ones as decimated
lines (:mod:`.plot_base`). Files are written atomically.
"""

from __future__ import annotations

from collections.abc import Callable, Collection, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from drillcosim.plant.signals import (
    AXES,
    CONTROLLER,
    PLANT,
    TOP_DRIVE,
    actuator_force,
    actuator_power,
    body_signal,
)

from .plot_base import (
    BASELINE_COLOR,
    DPI,
    SHOW_DPI,
    RunFigure,
    envelope,
    figure_grid,
    save_figure,
    thin_path,
)
from .summary import column, contact_bodies

__all__ = ["DPI", "REVOLUTIONS", "SHOW_DPI", "ActuatorsFigure", "AxialTorsionalFigure",
           "DeflectionContactFigure", "OrbitFigure", "RunFigure", "envelope", "last_revolutions",
           "plot_axial_torsional", "plot_run", "run_figures", "save_figure", "thin_path"]

MM = 1e3  # m -> mm
KN = 1e-3  # N -> kN
#: Revolutions of the top drive the orbit shows (the run's last).
REVOLUTIONS = 5
#: Label of the run's traces when a baseline is drawn / of the baseline's.
RUN_LABEL, BASELINE_LABEL = "closed loop", "open loop (controller off)"


def _span_label(body: int, spans: Mapping[int, Mapping] | None) -> str:
    info = (spans or {}).get(body, {})
    kind = info.get("span", "")
    return f"body {body} ({kind} span)" if kind and kind != "only" else f"body {body}"


def _long_body(data: np.ndarray, spans: Mapping[int, Mapping] | None) -> int | None:
    if spans:
        for b, info in spans.items():
            if info.get("span") == "long":
                return b
    bodies = contact_bodies(data)
    return bodies[0] if bodies else None


def last_revolutions(period: float | None, n: int = REVOLUTIONS
                     ) -> Callable[[np.ndarray], float | None]:
    """A window for :class:`OrbitFigure`: the last ``n`` revolutions of ``period`` [s] (the last
    third of the run without a period)."""
    def window(t: np.ndarray) -> float | None:
        if len(t) < 2:
            return None
        if period is None or not period > 0:
            return float(t[0] + 2.0 / 3.0 * (t[-1] - t[0]))
        return float(max(t[0], t[-1] - n * period))
    window.label = (f"last {n} revolutions of the top drive" if period and period > 0
                    else "last third of the run")
    return window


def _legend(ax, handles: Sequence[Any] = (), **kw) -> None:
    if handles:
        ax.legend(handles=list(handles), fontsize=8, **kw)


def _run_handles(self: RunFigure, color: str) -> list:
    """Legend proxies: the run (``color``) and, if drawn, the baseline (its envelope)."""
    from matplotlib.lines import Line2D
    from matplotlib.patches import Patch

    out = [Patch(color=color, alpha=0.75,
                 label=RUN_LABEL if self.baseline is not None else "this run")]
    if self.baseline is not None:
        out.append(Line2D([], [], color=BASELINE_COLOR, label=BASELINE_LABEL))
    return out


class OrbitFigure(RunFigure):
    """X-Y orbit [mm] of the long span's middle body with the clearance circle, from
    ``window(times)`` [s] on, the baseline's over the same times; :meth:`build`."""

    @classmethod
    def build(cls, data: np.ndarray, clearance: float,
              spans: Mapping[int, Mapping] | None = None, title: str = "",
              window: Callable[[np.ndarray], float | None] = lambda t: None,
              baseline: np.ndarray | None = None) -> OrbitFigure | None:
        """The figure for ``data``'s columns (None: no orbit recorded)."""
        body = _long_body(data, spans)
        names = [body_signal(body, a) for a in "XY"] if body is not None else []
        if body is None or any(column(data, PLANT, n) is None for n in names):
            return None
        if baseline is not None and any(column(baseline, PLANT, n) is None for n in names):
            baseline = None
        return cls(body, clearance, spans, title, window, baseline)

    def __init__(self, body: int, clearance: float, spans: Mapping[int, Mapping] | None,
                 title: str, window: Callable[[np.ndarray], float | None],
                 baseline: np.ndarray | None = None):
        fig, axes = figure_grid(5.5, 6.1, 1, 1, top=1.0, left=0.7, bottom=0.55)
        super().__init__(fig, baseline)
        self.body, self.clearance, self.window = body, clearance, window
        self.names = [body_signal(body, a) for a in "XY"]
        self._headed(axes, None, title, f"lateral orbit, {_span_label(body, spans)}")
        ax = self.ax = axes[0, 0]
        self.base_path = None
        if baseline is not None:
            self.base_path, = ax.plot([], [], lw=0.8, color=BASELINE_COLOR, zorder=2.0,
                                      label=BASELINE_LABEL)
        self.path, = ax.plot([], [], lw=0.8, color="tab:blue", zorder=2.2,
                             label=RUN_LABEL if baseline is not None else "mass centre")
        phi = np.linspace(0, 2 * np.pi, 361)
        ax.plot(clearance * MM * np.cos(phi), clearance * MM * np.sin(phi), "k--", lw=1.0,
                label=f"clearance {clearance * MM:g} mm")
        ax.set_aspect("equal")
        ax.set_xlabel("X [mm]")
        ax.set_ylabel("Y [mm]")
        ax.grid(alpha=0.3)
        ax.legend(loc="upper right", fontsize=8)
        self.title = ax.set_title("", y=1.0, fontsize=9)

    def _orbit(self, data: np.ndarray, t_from: float | None, t_to: float
               ) -> tuple[np.ndarray, np.ndarray]:
        t = data["time"]
        sel = (t <= t_to) if t_from is None else (t >= t_from) & (t <= t_to)
        x, y = (column(data, PLANT, n)[sel] * MM for n in self.names)
        return x, y

    def update(self, data: np.ndarray, t_end: float | None = None) -> None:
        t = data["time"]
        t_from = self.window(t if t_end is None or len(t) < 2 else np.array([t[0], t_end]))
        x, y = self._orbit(data, t_from, float(t[-1]))
        reach = float(np.nanmax(np.hypot(x, y), initial=0.0))   # 0: no rows yet
        base = None
        if self.base_path is not None:
            base = self._orbit(self.baseline, t_from, float(t[-1]))
            reach = max(reach, float(np.nanmax(np.hypot(*base), initial=0.0)))
        lim = 1.15 * max(self.clearance * MM, reach)
        cell = 2 * lim / (5.5 * SHOW_DPI)          # a 300-dpi pixel of the axes
        self.path.set_data(*thin_path(x, y, cell))
        if base is not None:
            self.base_path.set_data(*thin_path(*base, cell))
        self.ax.set_xlim(-lim, lim)
        self.ax.set_ylim(-lim, lim)
        what = getattr(self.window, "label", "")
        span = "" if t_from is None else \
            f"{what + ': ' if what else ''}t = {t_from:.4g} .. {float(t[-1]):.4g} s"
        self.title.set_text(span)


def _time_panel(ax, ylabel: str) -> None:
    """Label a bottom panel (time axis) and grid it."""
    ax.set_ylabel(ylabel)
    ax.set_xlabel("time [s]")
    ax.grid(alpha=0.3)


class DeflectionContactFigure(RunFigure):
    """Radial deflection [mm] and contact force [kN] vs time at each contact body, the run
    against its baseline; a contact panel without contact says so; :meth:`build`."""

    @classmethod
    def build(cls, data: np.ndarray, clearance: float,
              spans: Mapping[int, Mapping] | None = None, title: str = "",
              switch_on_time: float | None = None, baseline: np.ndarray | None = None,
              period: float | None = None) -> DeflectionContactFigure | None:
        """The figure for ``data``'s columns (None: no contact body recorded);
        ``switch_on_time`` [s], if given, is marked by a dotted line; ``period``: the shortest
        bin of an envelope band [s] (:class:`RunFigure`)."""
        bodies = contact_bodies(data)
        if not bodies:
            return None
        fig, axes = figure_grid(5 * len(bodies), 6.3, 2, len(bodies), sharex=True, top=0.85)
        self = cls(fig, baseline, period)
        self.clearance = clearance
        self.quiet: list[tuple[Any, Any, int]] = []     # (axes, text, body) of contact panels
        for j, b in enumerate(bodies):
            ax = axes[0, j]
            deflection = body_signal(b, "radial_deflection")
            self._series(ax, data, PLANT, deflection, MM, baseline=True, lw=0.7)
            self._series(ax, data, PLANT, deflection, MM, lw=0.7, color="tab:blue")
            ax.axhline(clearance * MM, color="k", ls="--", lw=1.0)
            ax.set_ylabel("radial deflection [mm]")
            ax.set_title(_span_label(b, spans), y=1.0)   # y given: no title-overlap search
            from matplotlib.lines import Line2D

            _legend(ax, [*_run_handles(self, "tab:blue"),
                         Line2D([], [], color="k", ls="--", label="clearance")],
                    loc="upper left")
            ax.grid(alpha=0.3)
            ax = axes[1, j]
            force = body_signal(b, "contact_force")
            self._series(ax, data, PLANT, force, KN, baseline=True, lw=0.7)
            self._series(ax, data, PLANT, force, KN, lw=0.7, color="tab:red")
            if self.baseline is not None:
                _legend(ax, _run_handles(self, "tab:red"), loc="upper left")
            text = ax.text(0.5, 0.6, "", ha="center", va="center", transform=ax.transAxes,
                           fontsize=9, color="0.2", zorder=5, wrap=False,
                           bbox={"facecolor": "white", "edgecolor": "0.7", "pad": 4})
            self.quiet.append((ax, text, b))
            _time_panel(ax, "contact force [kN]")
        return self._headed(axes, switch_on_time, title,
                            "radial deflection and wellbore contact force")

    def update(self, data: np.ndarray, t_end: float | None = None) -> None:
        super().update(data, t_end)
        for _ax, text, body in self.quiet:
            runs = [(data, "")] + ([(self.baseline, " (open loop too)")]
                                   if self.baseline is not None else [])
            force = body_signal(body, "contact_force")
            touched = any(np.any(column(d, PLANT, force) > 0) for d, _ in runs
                          if column(d, PLANT, force) is not None)
            peak = np.nanmax(column(data, PLANT, body_signal(body,
                                                  "radial_deflection")),
                             initial=0.0) * MM
            text.set_text("" if touched else
                          f"no wall contact{runs[-1][1]}:\npeak radial deflection {peak:.3g} mm"
                          f"\n< clearance {self.clearance * MM:g} mm")
            text.set_visible(not touched)


class ActuatorsFigure(RunFigure):
    """Actuator forces C and E [kN] (a panel each) and delivered power [W] vs time per site;
    :meth:`build`."""

    @classmethod
    def build(cls, data: np.ndarray, n_sites: int = 2,
              spans_by_site: Sequence[str] | None = None, title: str = "",
              switch_on_time: float | None = None, period: float | None = None
              ) -> ActuatorsFigure | None:
        """The figure for ``data``'s columns (None: no actuator power recorded); ``period``:
        as for :meth:`DeflectionContactFigure.build`."""
        if all(column(data, PLANT, actuator_power(s)) is None
               for s in range(1, n_sites + 1)):
            return None
        fig, axes = figure_grid(5 * n_sites, 7.8, 3, n_sites, sharex=True, top=0.85)
        self = cls(fig, None, period)
        colors = {"C": "tab:blue", "E": "tab:orange"}
        for j, s in enumerate(range(1, n_sites + 1)):
            where = (f" ({spans_by_site[j]} span)" if spans_by_site and j < len(spans_by_site)
                     else "")
            for row, a in enumerate(AXES):
                ax = axes[row, j]
                drawn = self._series(ax, data, CONTROLLER, actuator_force(s, a), KN,
                                     lw=0.7, color=colors[a])
                ax.set_ylabel(f"force {a} [kN]")
                ax.set_title(f"site {s}{where}: actuator {a}" if row == 0 else
                             f"actuator {a}", y=1.0, fontsize=10)
                if not drawn:
                    ax.text(0.5, 0.5, "controller disabled", ha="center",
                            transform=ax.transAxes)
                ax.grid(alpha=0.3)
            ax = axes[len(AXES), j]
            self._series(ax, data, PLANT, actuator_power(s), lw=0.7, color="tab:green")
            _time_panel(ax, "power [W]")
        return self._headed(axes, switch_on_time, title,
                            "actuator forces (C: bending about body y, E: about body x) and "
                            "delivered power")


#: Panels of :class:`AxialTorsionalFigure`: (ylabel, scale, [(fmu, output, label), ...]).
_AXIAL_TORSIONAL = (
    ("rotary speed [rad/s]", 1.0, [(PLANT, "top_rotary_speed", "top"),
                                   (PLANT, "bit_rotary_speed", "bit")]),
    ("torque [kN m]", KN, [(PLANT, "top_torque", "top (string on the drive)"),
                           (PLANT, "bit_torque", "bit (rock on the bit)"),
                           (TOP_DRIVE, "top_drive_torque", "motor (controller)")]),
    ("bit axial force [kN]", KN, [(PLANT, "bit_axial_force", "on the bit")]),
)


class AxialTorsionalFigure(RunFigure):
    """Rotary speeds, torques and the bit's axial force vs time, the times the bit is off the
    bottom shaded; :meth:`build`."""

    @classmethod
    def build(cls, data: np.ndarray, title: str = "") -> AxialTorsionalFigure | None:
        """The figure for ``data``'s columns (None: none of its outputs recorded)."""
        panels = [(label, scale, found) for label, scale, curves in _AXIAL_TORSIONAL
                  if (found := [c for c in curves if column(data, *c[:2]) is not None])]
        if not panels:
            return None
        fig, axes = figure_grid(8, 2.4 * len(panels) + 0.9, len(panels), 1, sharex=True,
                                top=0.8, right=0.25, hspace=0.2)
        self = cls(fig)
        for ax, (label, scale, curves) in zip(axes[:, 0], panels):
            for fmu, output, lab in curves:
                self._series(ax, data, fmu, output, scale, lw=0.8, label=lab)
            ax.set_ylabel(label)
            ax.grid(alpha=0.3)
            ax.legend(loc="upper right", fontsize=8)
        axes[-1, 0].set_xlabel("time [s]")
        self._headed(axes, None, title, "rotary speed, torque and bit force")
        self.shades: dict[Any, Any] = {}
        return self

    def update(self, data: np.ndarray, t_end: float | None = None) -> None:
        super().update(data, t_end)
        off = column(data, PLANT, "bit_on_bottom")
        shade = off is not None and bool((off < 0.5).any())
        for ax in self.fig.axes:
            old = self.shades.pop(ax, None)
            if old is not None:
                old.remove()
            if shade:
                self.shades[ax] = ax.fill_between(
                    data["time"], 0, 1, where=off < 0.5, color="0.85", step="mid",
                    transform=ax.get_xaxis_transform(), label="bit off bottom")
            if (old is None) == shade:          # shaded now and not before, or the reverse
                ax.legend(loc="upper right", fontsize=8)


def _draw(fig: RunFigure | None, data: np.ndarray, path: str | Path) -> Path | None:
    """Update ``fig`` with ``data`` and save it to ``path`` (None: no figure)."""
    if fig is None:
        return None
    fig.update(data)
    return fig.save(path)


def plot_axial_torsional(data: np.ndarray, path: str | Path, title: str = "") -> Path | None:
    """Top and bit rotary speed [rad/s], top / bit / motor torque [kN m] and the bit's axial
    force [kN] vs time, each panel drawn if one of its outputs was recorded; times the bit is
    off the bottom (``plant.bit_on_bottom`` = 0) are shaded."""
    return _draw(AxialTorsionalFigure.build(data, title), data, path)


def _load_baseline(baseline: str | Path | np.ndarray | None) -> np.ndarray | None:
    if baseline is None or isinstance(baseline, np.ndarray):
        return baseline
    from .baseline import load_baseline

    return load_baseline(baseline)


def run_figures(data: np.ndarray, clearance: float,
                spans: Mapping[int, Mapping] | None = None, n_sites: int = 2,
                title: str = "", switch_on_time: float | None = None,
                figures: Collection[str] | None = None,
                baseline: str | Path | np.ndarray | None = None,
                revolution: float | None = None) -> dict[str, RunFigure]:
    """The figures :func:`plot_run` draws for ``data``'s columns (file names without ``.png``
    -> figure), built, their traces not set yet (:meth:`RunFigure.update`); ``figures``: only
    these names; ``baseline``: the open-loop rows (or their file, :mod:`.baseline`) drawn
    behind the run's; ``revolution``: the top drive's period [s] (the orbit's window)."""
    site_spans = None
    if spans:
        site_spans = [info.get("span", "") for _, info in sorted(spans.items())]
    base = _load_baseline(baseline)
    if not contact_bodies(data):  # the axial-torsional chain: no lateral motion to show
        make = {"axial_torsional": lambda: AxialTorsionalFigure.build(data, title)}
    else:
        make = {
            "orbit": lambda: OrbitFigure.build(data, clearance, spans, title,
                                               last_revolutions(revolution), base),
            "deflection_contact": lambda: DeflectionContactFigure.build(
                data, clearance, spans, title, switch_on_time, base, revolution),
            "actuators": lambda: ActuatorsFigure.build(data, n_sites, site_spans, title,
                                                       switch_on_time, revolution)}
    built = {name: f() for name, f in make.items() if figures is None or name in figures}
    return {name: fig for name, fig in built.items() if fig is not None}


def plot_run(data: np.ndarray, out_dir: str | Path, clearance: float,
             spans: Mapping[int, Mapping] | None = None, n_sites: int = 2,
             title: str = "", switch_on_time: float | None = None,
             figures: Collection[str] | None = None,
             baseline: str | Path | np.ndarray | None = None,
             revolution: float | None = None) -> list[Path]:
    """Write ``orbit.png``, ``deflection_contact.png`` and ``actuators.png`` (a scene without
    contact bodies, i.e. the axial-torsional chain: ``axial_torsional.png`` instead); return
    their paths (a plot without data is skipped).

    ``figures``: only these (file names without ``.png``; default: all; the figures drawn by
    worker processes: :mod:`.plot_workers`); ``baseline``, ``revolution``: as for
    :func:`run_figures`."""
    out = Path(out_dir)
    return [_draw(fig, data, out / f"{name}.png") for name, fig in
            run_figures(data, clearance, spans, n_sites, title, switch_on_time, figures,
                        baseline, revolution).items()]
