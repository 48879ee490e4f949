"""PNG figures of a run, after the paper's Figs. 9-16.

* :func:`plot_orbit` - lateral X-Y orbit of the long span's middle body with the
  wellbore clearance circle (Figs. 9, 15);
* :func:`plot_deflection_contact` - radial deflection and contact force vs time
  at every contact body (Figs. 10, 12, 14, 16);
* :func:`plot_actuators` - actuator forces and powers vs time (Figs. 11, 13, 14);
* :func:`plot_axial_torsional` - rotary speeds, torques and the bit's axial force vs time (the
  axial-torsional scenes: stick-slip, bit bounce);
* :func:`plot_run` - all of the above that the recorded outputs allow, for one run.

Inputs are the structured arrays of :class:`cosim.master.Result` or
:func:`cosim.scenario.summary.load_results` (columns ``plant.<output>`` /
``controller.<output>``). Files are written atomically
(:class:`cosim.master.files.AtomicFile`). Uses matplotlib's non-interactive Agg backend.

Long runs are drawn from what a 300-dpi figure can show (:data:`SHOW_DPI`): a time series keeps,
per pixel column of the figure's width at 300 dpi, its first, last, smallest and largest
sample (:func:`envelope`: every peak stays), an orbit the samples where it enters and leaves
a 300-dpi pixel (:func:`thin_path`); the figures are saved at 120 dpi, so the drawn lines are
those of the full data. The figures have fixed margins (no layout engine pass) and are
matplotlib ``Figure`` objects (no pyplot state).
"""

from __future__ import annotations

import io
from collections.abc import Callable, Collection, Mapping, Sequence
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import numpy as np  # noqa: E402
from matplotlib.figure import Figure  # noqa: E402

from drillcosim.cosim.master.files import AtomicFile  # noqa: E402
from drillcosim.plant.signals import (  # noqa: E402
    AXES,
    CONTROLLER,
    PLANT,
    TOP_DRIVE,
    actuator_force,
    actuator_power,
    body_signal,
)

from .summary import column, contact_bodies  # noqa: E402

__all__ = ["DPI", "SHOW_DPI", "ActuatorsFigure", "AxialTorsionalFigure",
           "DeflectionContactFigure", "OrbitFigure", "RunFigure", "envelope", "last_third",
           "plot_actuators", "plot_axial_torsional", "plot_deflection_contact", "plot_orbit",
           "plot_run", "run_figures", "save_figure", "thin_path"]

MM = 1e3  # m -> mm
KN = 1e-3  # N -> kN
#: The resolution the decimated lines keep [dots per inch] (the figures are saved at :data:`DPI`).
SHOW_DPI = 300
#: The resolution of a run's figures [dots per inch].
DPI = 120


def save_figure(fig, path: str | Path, dpi: int = 120, compress_level: int = 6) -> Path:
    """Save ``fig`` as PNG atomically (:class:`cosim.master.files.AtomicFile`) and close it
    (a pyplot figure is released from pyplot; a plain ``Figure`` needs nothing).

    ``compress_level``: zlib level of the PNG, 0-9 (the figures of a run use 1: ~3x faster to
    encode, ~1.3x larger)."""
    try:
        with AtomicFile(path, "wb") as fh:
            fig.savefig(fh, dpi=dpi, format="png", pil_kwargs={"compress_level": compress_level})
    finally:
        import sys

        if "matplotlib.pyplot" in sys.modules:
            sys.modules["matplotlib.pyplot"].close(fig)
    return Path(path)


def envelope(t: np.ndarray, y: np.ndarray, columns: int) -> tuple[np.ndarray, np.ndarray]:
    """The samples of ``y(t)`` a plot ``columns`` pixels wide shows: in each of ``columns``
    equal time bins, the first, the last, the smallest and the largest sample, in time order.

    Parameters
    ----------
    t : numpy.ndarray
        Times, shape (n,), non-decreasing.
    y : numpy.ndarray
        Values, shape (n,); NaN samples are kept where they are a bin's first or last.
    columns : int
        Pixel columns across ``t[0] .. t[-1]``.

    Returns
    -------
    (t, y) : tuple of numpy.ndarray
        At most ``4 * columns`` samples (all of them when there are not more than that).
    """
    n = len(t)
    if n <= 4 * columns or not t[-1] > t[0]:
        return t, y
    starts = np.unique(np.searchsorted(t, np.linspace(t[0], t[-1], columns + 1)[:-1]))
    ends = np.append(starts[1:], n)
    counts = ends - starts
    index = np.arange(n)
    picks = [starts, ends - 1]
    for reduce in (np.fmin, np.fmax):          # NaN-ignoring; the first sample at the extreme
        extreme = np.repeat(reduce.reduceat(y, starts), counts)
        picks.append(np.minimum.reduceat(np.where(y == extreme, index, n), starts))
    keep = np.unique(np.concatenate(picks))
    keep = keep[keep < n]
    return t[keep], y[keep]


def thin_path(x: np.ndarray, y: np.ndarray, cell: float) -> tuple[np.ndarray, np.ndarray]:
    """A path with only the samples where it enters or leaves a square pixel of side
    ``cell`` (consecutive samples inside one pixel collapse to the first and last of them).

    Parameters
    ----------
    x, y : numpy.ndarray
        Shape (n,).
    cell : float
        Pixel side in the units of ``x`` and ``y`` (> 0).

    Returns
    -------
    (x, y) : tuple of numpy.ndarray
    """
    if len(x) < 3 or not cell > 0:
        return x, y
    ix, iy = np.floor(x / cell), np.floor(y / cell)
    moved = (ix[1:] != ix[:-1]) | (iy[1:] != iy[:-1])
    keep = np.ones(len(x), bool)
    keep[1:-1] = moved[:-1] | moved[1:]     # leaves its pixel next, or entered it just now
    return x[keep], y[keep]


def _figure(width: float, height: float, rows: int, cols: int, *, sharex: bool = False,
            top: float = 0.55, bottom: float = 0.5, left: float = 0.85, right: float = 0.15,
            hspace: float = 0.3, wspace: float = 0.95):
    """A figure of ``rows x cols`` axes with fixed margins and gaps [in] (no layout engine),
    at the resolution it is saved at (:data:`DPI`)."""
    fig = Figure(figsize=(width, height), dpi=DPI)
    axes = fig.subplots(rows, cols, sharex=sharex, squeeze=False)
    axes_w = (width - left - right - wspace * (cols - 1)) / cols
    axes_h = (height - top - bottom - hspace * (rows - 1)) / rows
    fig.subplots_adjust(left=left / width, right=1 - right / width, bottom=bottom / height,
                        top=1 - top / height, wspace=wspace / axes_w, hspace=hspace / axes_h)
    return fig, axes


class RunFigure:
    """One figure of a run: built from the recorded columns (``data``'s fields: which lines and
    panels), its lines set from the rows by :meth:`update`.

    The picture depends only on the last :meth:`update`'s rows: the worker processes
    (:mod:`.plot_workers`) draw their figures with the rows of a run so far while it steps,
    and update them with all the rows at its end; :func:`plot_run` builds, updates once and
    saves.

    :meth:`render` draws in two layers: what lies below the lines (axes backgrounds, grids,
    ticks and their labels, titles) once per set of axes limits and titles, kept as a bitmap;
    then, on a copy of that bitmap, every artist from the lines up (lines, spines, texts and
    legends in the axes), in the order the axes draws them. A figure drawn before with the same
    limits (a run's figures drawn while it steps, their limits reached) draws only its lines.
    """

    def __init__(self, fig: Figure):
        self.fig = fig
        #: the time series: (line, fmu, output, scale), set by :meth:`update`
        self.series: list[tuple[Any, str, str, float]] = []
        self._below: tuple[Any, Any] | None = None    # (limits and titles, bitmap)

    def _series(self, ax, data: np.ndarray, fmu: str, output: str, scale: float = 1.0,
                **kw) -> bool:
        """Add the line of ``fmu.output`` [times ``scale``] to ``ax`` if it was recorded."""
        if column(data, fmu, output) is None:
            return False
        line, = ax.plot([], [], **kw)
        self.series.append((line, fmu, output, scale))
        return True

    def _headed(self, axes, switch_on_time: float | None, title: str, what: str):
        """Mark the controller's switch-on in ``axes``, head the figure ``title: what``."""
        _mark(axes, switch_on_time)
        self.fig.suptitle(f"{title}: {what}" if title else what)
        return self

    def update(self, data: np.ndarray, t_end: float | None = None) -> None:
        """Set the lines from ``data`` (at least 2 rows; the time series decimated to the pixel
        columns of the figure's width at :data:`SHOW_DPI`) and rescale the axes.

        ``t_end`` [s]: the time axis as if the rows went on to ``t_end`` (a run's rows so far
        drawn with the time axis of the whole run)."""
        t = data["time"]
        columns = int(np.ceil(self.fig.get_figwidth() * SHOW_DPI))
        for line, fmu, output, scale in self.series:
            line.set_data(*envelope(t, column(data, fmu, output) * scale, columns))
        drawn = list({id(line.axes): line.axes for line, *_ in self.series}.values())
        for ax in drawn:                # an axes without series keeps its limits (0 .. 1)
            ax.relim()
            if t_end is not None and t_end > t[-1]:
                ax.dataLim.update_from_data_x(np.array([t_end]), ignore=False)
        for ax in drawn:
            ax.autoscale_view()

    def _above(self, ax) -> list:
        """The artists of ``ax`` from its lines up, in the order it draws them."""
        low = min((line.get_zorder() for line in ax.lines), default=np.inf)
        return [a for a in sorted(ax.get_children(), key=lambda a: a.get_zorder())
                if a.get_zorder() >= low and a.get_visible()]

    def _key(self) -> tuple:
        """What the layer below the lines depends on: every axes' limits."""
        return tuple(tuple(ax.viewLim.bounds) for ax in self.fig.axes)

    def prepare(self) -> None:
        """Draw the layer below the lines now if the limits changed since it was drawn (a
        later :meth:`render` with these limits draws only the lines and above)."""
        from matplotlib.backends.backend_agg import FigureCanvasAgg

        canvas = self.fig.canvas
        if not isinstance(canvas, FigureCanvasAgg):
            canvas = FigureCanvasAgg(self.fig)
        key = self._key()
        if self._below is None or self._below[0] != key:
            for ax in self.fig.axes:
                for a in self._above(ax):
                    a.set_animated(True)        # not drawn by canvas.draw()
            canvas.draw()
            self._below = (key, canvas.copy_from_bbox(self.fig.bbox))

    def render(self) -> None:
        """Draw the figure with Agg (see the class docstring)."""
        below = self._below
        self.prepare()
        canvas = self.fig.canvas
        if below is self._below:                # drawn before: a copy of it
            canvas.restore_region(self._below[1])
        for ax in self.fig.axes:
            for a in self._above(ax):
                ax.draw_artist(a)

    def png(self) -> bytes:
        """The figure drawn now, as PNG (zlib level 1: ~3x faster to encode than 6, ~1.3x
        larger)."""
        import matplotlib.image

        self.render()
        buf = io.BytesIO()
        matplotlib.image.imsave(buf, self.fig.canvas.buffer_rgba(), format="png",
                                origin="upper", dpi=DPI, pil_kwargs={"compress_level": 1})
        return buf.getvalue()

    def save(self, path: str | Path, png: bytes | None = None) -> Path:
        """Write :meth:`png` (or ``png``, drawn before) to ``path`` atomically."""
        with AtomicFile(path, "wb") as fh:
            fh.write(self.png() if png is None else png)
        return Path(path)


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


def last_third(t: np.ndarray) -> float | None:
    """The start [s] of the last third of the times ``t`` [s] (None: fewer than 2)."""
    return float(t[0] + 2.0 / 3.0 * (t[-1] - t[0])) if len(t) > 1 else None


class OrbitFigure(RunFigure):
    """X-Y orbit [mm] of the long span's middle body with the clearance circle, from
    ``window(times)`` [s] on (None: everything); :meth:`build`."""

    @classmethod
    def build(cls, data: np.ndarray, clearance: float,
              spans: Mapping[int, Mapping] | None = None, title: str = "",
              window: Callable[[np.ndarray], float | None] = lambda t: None
              ) -> OrbitFigure | None:
        """The figure for ``data``'s columns (None: no orbit recorded)."""
        body = _long_body(data, spans)
        if body is None or any(column(data, PLANT, body_signal(body, a)) is None for a in "XY"):
            return None
        return cls(body, clearance, spans, title, window)

    def __init__(self, body: int, clearance: float, spans: Mapping[int, Mapping] | None,
                 title: str, window: Callable[[np.ndarray], float | None]):
        fig, axes = _figure(5.5, 5.5, 1, 1, top=0.5, left=0.7, bottom=0.55)
        super().__init__(fig)
        self.body, self.clearance, self.window = body, clearance, window
        self.heading = f"{title}\nlateral orbit, {_span_label(body, spans)}"
        ax = self.ax = axes[0, 0]
        self.path, = ax.plot([], [], lw=0.6, color="tab:blue", label="mass centre")
        phi = np.linspace(0, 2 * np.pi, 361)
        ax.plot(clearance * MM * np.cos(phi), clearance * MM * np.sin(phi), "k--", lw=1.0,
                label=f"clearance {clearance * MM:g} mm")
        ax.set_aspect("equal")
        ax.set_xlabel("X [mm]")
        ax.set_ylabel("Y [mm]")
        ax.grid(alpha=0.3)
        ax.legend(loc="upper right", fontsize=8)
        self.title = ax.set_title("", y=1.0)

    def update(self, data: np.ndarray, t_end: float | None = None) -> None:
        x = column(data, PLANT, body_signal(self.body, "X"))
        y = column(data, PLANT, body_signal(self.body, "Y"))
        t = data["time"]
        t_from = self.window(t if t_end is None or len(t) < 2 else np.array([t[0], t_end]))
        sel = np.ones(len(x), bool) if t_from is None else data["time"] >= t_from
        reach = float(np.nanmax(np.hypot(x[sel], y[sel]), initial=0.0))   # 0: no rows yet
        lim = 1.15 * max(self.clearance * MM, reach * MM)
        # a 300-dpi pixel of the (at most 5.5 in wide) axes
        self.path.set_data(*thin_path(x[sel] * MM, y[sel] * MM, 2 * lim / (5.5 * SHOW_DPI)))
        self.ax.set_xlim(-lim, lim)
        self.ax.set_ylim(-lim, lim)
        window = "" if t_from is None else f", t >= {t_from:g} s"
        self.title.set_text(f"{self.heading}{window}".strip())


def plot_orbit(data: np.ndarray, path: str | Path, clearance: float,
               spans: Mapping[int, Mapping] | None = None, title: str = "",
               t_from: float | None = None) -> Path | None:
    """X-Y orbit [mm] of the long span's middle body with the clearance circle.

    Parameters
    ----------
    t_from : float, optional
        Plot only ``t >= t_from`` [s] (default: everything).
    """
    fig = OrbitFigure.build(data, clearance, spans, title, lambda t: t_from)
    return _draw(fig, data, path)


def _draw(fig: RunFigure | None, data: np.ndarray, path: str | Path) -> Path | None:
    """Update ``fig`` with ``data`` and save it to ``path`` (None: no figure)."""
    if fig is None:
        return None
    fig.update(data)
    return fig.save(path)


def _time_panel(ax, ylabel: str) -> None:
    """Label a bottom panel (time axis) and grid it."""
    ax.set_ylabel(ylabel)
    ax.set_xlabel("time [s]")
    ax.grid(alpha=0.3)


def _mark(axes, switch_on_time: float | None) -> None:
    if switch_on_time:
        for ax in np.ravel(axes):
            ax.axvline(switch_on_time, color="0.4", ls=":", lw=1.0)
        ax = np.ravel(axes)[0]
        ax.annotate("controller on", (switch_on_time, 1.0), xycoords=("data", "axes fraction"),
                    xytext=(3, -12), textcoords="offset points", fontsize=8, color="0.3")


class DeflectionContactFigure(RunFigure):
    """Radial deflection [mm] and contact force [kN] vs time at each contact body;
    :meth:`build`."""

    @classmethod
    def build(cls, data: np.ndarray, clearance: float,
              spans: Mapping[int, Mapping] | None = None, title: str = "",
              switch_on_time: float | None = None) -> DeflectionContactFigure | None:
        """The figure for ``data``'s columns (None: no contact body recorded);
        ``switch_on_time`` [s], if given, is marked by a dotted line."""
        bodies = contact_bodies(data)
        if not bodies:
            return None
        fig, axes = _figure(5 * len(bodies), 6, 2, len(bodies), sharex=True)
        self = cls(fig)
        for j, b in enumerate(bodies):
            ax = axes[0, j]
            self._series(ax, data, PLANT, body_signal(b, "radial_deflection"), MM, lw=0.7)
            ax.axhline(clearance * MM, color="k", ls="--", lw=1.0, label="clearance")
            ax.set_ylabel("radial deflection [mm]")
            ax.set_title(_span_label(b, spans), y=1.0)   # y given: no title-overlap search
            ax.legend(loc="upper left", fontsize=8)
            ax.grid(alpha=0.3)
            ax = axes[1, j]
            self._series(ax, data, PLANT, body_signal(b, "contact_force"), KN, lw=0.7,
                         color="tab:red")
            _time_panel(ax, "contact force [kN]")
        return self._headed(axes, switch_on_time, title,
                            "radial deflection and wellbore contact force")


def plot_deflection_contact(data: np.ndarray, path: str | Path, clearance: float,
                            spans: Mapping[int, Mapping] | None = None,
                            title: str = "", switch_on_time: float | None = None) -> Path | None:
    """Radial deflection [mm] and contact force [kN] vs time at each contact body.

    ``switch_on_time`` [s], if given, is marked by a dotted line.
    """
    return _draw(DeflectionContactFigure.build(data, clearance, spans, title, switch_on_time),
                 data, path)


class ActuatorsFigure(RunFigure):
    """Actuator forces [kN] (C and E) and delivered power [W] vs time per site;
    :meth:`build`."""

    @classmethod
    def build(cls, data: np.ndarray, n_sites: int = 2,
              spans_by_site: Sequence[str] | None = None, title: str = "",
              switch_on_time: float | None = None) -> ActuatorsFigure | None:
        """The figure for ``data``'s columns (None: no actuator power recorded)."""
        if all(column(data, PLANT, actuator_power(s)) is None
               for s in range(1, n_sites + 1)):
            return None
        fig, axes = _figure(5 * n_sites, 6, 2, n_sites, sharex=True)
        self = cls(fig)
        for j, s in enumerate(range(1, n_sites + 1)):
            ax = axes[0, j]
            for a, color in zip(AXES, ("tab:blue", "tab:orange")):
                self._series(ax, data, CONTROLLER, actuator_force(s, a), KN, lw=0.7,
                             color=color, label=f"force {a}")
            ax.set_ylabel("actuator force [kN]")
            where = (f" ({spans_by_site[j]} span)" if spans_by_site and j < len(spans_by_site)
                     else "")
            ax.set_title(f"site {s}{where}", y=1.0)
            if ax.lines:
                ax.legend(loc="upper left", fontsize=8)
            else:
                ax.text(0.5, 0.5, "controller disabled", ha="center", transform=ax.transAxes)
            ax.grid(alpha=0.3)
            ax = axes[1, j]
            self._series(ax, data, PLANT, actuator_power(s), lw=0.7, color="tab:green")
            _time_panel(ax, "actuator power [W]")
        return self._headed(axes, switch_on_time, title, "actuator force and power")


def plot_actuators(data: np.ndarray, path: str | Path, n_sites: int = 2,
                   spans_by_site: Sequence[str] | None = None, title: str = "",
                   switch_on_time: float | None = None) -> Path | None:
    """Actuator forces [kN] (C and E) and delivered power [W] vs time per site."""
    return _draw(ActuatorsFigure.build(data, n_sites, spans_by_site, title, switch_on_time),
                 data, path)


#: Panels of :func:`plot_axial_torsional`: (ylabel, scale, [(fmu, output, label), ...]).
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
        fig, axes = _figure(8, 2.4 * len(panels) + 0.6, len(panels), 1, sharex=True,
                            top=0.5, right=0.25, hspace=0.2)
        self = cls(fig)
        for ax, (label, scale, curves) in zip(axes[:, 0], panels):
            for fmu, output, lab in curves:
                self._series(ax, data, fmu, output, scale, lw=0.8, label=lab)
            ax.set_ylabel(label)
            ax.grid(alpha=0.3)
            ax.legend(loc="upper right", fontsize=8)
        axes[-1, 0].set_xlabel("time [s]")
        fig.suptitle(f"{title}: rotary speed, torque and bit force" if title else
                     "rotary speed, torque and bit force")
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


def plot_axial_torsional(data: np.ndarray, path: str | Path, title: str = "") -> Path | None:
    """Top and bit rotary speed [rad/s], top / bit / motor torque [kN m] and the bit's axial
    force [kN] vs time, each panel drawn if one of its outputs was recorded; times the bit is
    off the bottom (``plant.bit_on_bottom`` = 0) are shaded."""
    return _draw(AxialTorsionalFigure.build(data, title), data, path)


def run_figures(data: np.ndarray, clearance: float,
                spans: Mapping[int, Mapping] | None = None, n_sites: int = 2,
                title: str = "", switch_on_time: float | None = None,
                figures: Collection[str] | None = None) -> dict[str, RunFigure]:
    """The figures :func:`plot_run` draws for ``data``'s columns (file names without ``.png``
    -> figure), built, their lines not set yet (:meth:`RunFigure.update`); ``figures``: only
    these names."""
    site_spans = None
    if spans:
        site_spans = [info.get("span", "") for _, info in sorted(spans.items())]
    if not contact_bodies(data):  # the axial-torsional chain: no lateral motion to show
        make = {"axial_torsional": lambda: AxialTorsionalFigure.build(data, title)}
    else:
        make = {
            "orbit": lambda: OrbitFigure.build(data, clearance, spans, title),
            "orbit_steady": lambda: OrbitFigure.build(data, clearance, spans, title,
                                                      last_third),
            "deflection_contact": lambda: DeflectionContactFigure.build(
                data, clearance, spans, title, switch_on_time),
            "actuators": lambda: ActuatorsFigure.build(data, n_sites, site_spans, title,
                                                       switch_on_time)}
    built = {name: f() for name, f in make.items() if figures is None or name in figures}
    return {name: fig for name, fig in built.items() if fig is not None}


def plot_run(data: np.ndarray, out_dir: str | Path, clearance: float,
             spans: Mapping[int, Mapping] | None = None, n_sites: int = 2,
             title: str = "", switch_on_time: float | None = None,
             figures: Collection[str] | None = None) -> list[Path]:
    """Write ``orbit.png``, ``orbit_steady.png`` (last third), ``deflection_contact.png``
    and ``actuators.png`` (a scene without contact bodies, i.e. the axial-torsional chain:
    ``axial_torsional.png`` instead); return their paths (a plot without data is skipped).

    ``figures``: only these (file names without ``.png``; default: all; the figures drawn by
    worker processes: :mod:`.plot_workers`)."""
    out = Path(out_dir)
    return [_draw(fig, data, out / f"{name}.png") for name, fig in
            run_figures(data, clearance, spans, n_sites, title, switch_on_time, figures).items()]
