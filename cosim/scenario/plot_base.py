"""The machinery of a run's figures: decimated lines, envelope bands, two-layer drawing.

Long runs are drawn from what the figure can show. A trace with more samples than twice the
pixel columns of its axes (at :data:`DPI`, the resolution the figures are saved at) is drawn as
its envelope: a band between its smallest and largest value in bins of two saved pixels
(:func:`bands`), as an oscillation denser than the pixels looks anyway, without the solid bars
of a line that zig-zags within every pixel. A sparser trace is a line of the samples a 300-dpi
figure can show (:data:`SHOW_DPI`): per pixel column, its first, last, smallest and largest
sample (:func:`envelope`: every peak stays). An orbit keeps the samples where it enters and
leaves a 300-dpi pixel (:func:`thin_path`). The figures have fixed margins (no layout engine
pass) and are matplotlib ``Figure`` objects (no pyplot state).

A figure may carry a *baseline*: the open-loop run of the same scene
(:mod:`.baseline`), drawn in grey behind the run's traces.
"""

from __future__ import annotations

import io
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import numpy as np  # noqa: E402
from matplotlib.collections import PolyCollection  # noqa: E402
from matplotlib.figure import Figure  # noqa: E402

from drillcosim.cosim.master.files import AtomicFile  # noqa: E402

from .summary import column  # noqa: E402

__all__ = ["BASELINE_COLOR", "DPI", "SHOW_DPI", "RunFigure", "Trace", "bands", "envelope",
           "figure_grid", "save_figure", "thin_path"]

#: The resolution the decimated lines keep [dots per inch] (the figures are saved at :data:`DPI`).
SHOW_DPI = 300
#: The resolution of a run's figures [dots per inch].
DPI = 120
#: Colour of the open-loop baseline's traces.
BASELINE_COLOR = "0.55"
#: Saved pixels per bin of an envelope band.
BAND_PIXELS = 2


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


def figure_grid(width: float, height: float, rows: int, cols: int, *, sharex: bool = False,
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


def bands(t: np.ndarray, y: np.ndarray, bins: int) -> np.ndarray:
    """The envelope band of ``y(t)``: its smallest and largest value in each of ``bins`` equal
    time bins, as the polygon ``(t, lower)`` forward then ``(t, upper)`` backward, each bin at
    the middle of its samples' times (and the first and last bins also at the first and last
    sample's times: the band spans the whole trace).

    Returns
    -------
    numpy.ndarray, shape (2 * bins' + 4, 2)
        ``bins' <= bins`` (empty bins left out; NaN samples ignored).
    """
    if len(t) < 2 or not t[-1] > t[0]:
        return np.zeros((0, 2))
    starts = np.unique(np.searchsorted(t, np.linspace(t[0], t[-1], bins + 1)[:-1]))
    ends = np.append(starts[1:], len(t)) - 1
    lo, hi = np.fmin.reduceat(y, starts), np.fmax.reduceat(y, starts)
    x = np.concatenate([[t[0]], 0.5 * (t[starts] + t[ends]), [t[-1]]])
    lo, hi = np.concatenate([lo[:1], lo, lo[-1:]]), np.concatenate([hi[:1], hi, hi[-1:]])
    return np.vstack([np.column_stack([x, lo]), np.column_stack([x[::-1], hi[::-1]])])


@dataclass
class Trace:
    """One time series of a figure: a line, or its envelope band when it is denser than the
    pixels; from the run's rows or from its baseline's."""

    line: Any
    band: PolyCollection
    fmu: str
    output: str
    scale: float
    baseline: bool


class RunFigure:
    """One figure of a run: built from the recorded columns (``data``'s fields: which lines and
    panels), its traces set from the rows by :meth:`update`.

    The picture depends only on the last :meth:`update`'s rows (and the baseline's, fixed at
    build): the worker processes (:mod:`.plot_workers`) draw their figures with the rows of a
    run so far while it steps, and update them with all the rows at its end;
    :func:`.plots.plot_run` builds, updates once and saves.

    :meth:`render` draws in two layers: what lies below the traces (axes backgrounds, grids,
    ticks and their labels) once per set of axes limits, kept as a bitmap; then, on a copy of
    that bitmap, every artist from the traces up (lines, bands, spines, texts and legends in the
    axes), in the order the axes draws them. A figure drawn before with the same limits (a run's
    figures drawn while it steps, their limits reached) draws only its traces. A figure that is
    only updated (not rendered) is a plain matplotlib figure (:meth:`.result.Result.plot`).
    """

    def __init__(self, fig: Figure, baseline: np.ndarray | None = None,
                 period: float | None = None):
        self.fig = fig
        #: the open-loop rows drawn behind the run's (None: none)
        self.baseline = baseline
        #: shortest bin of an envelope band [s] (the top drive's revolution: a band is then the
        #: vibration's amplitude, not the oscillation within each revolution)
        self.period = period
        #: the time series, set by :meth:`update`
        self.series: list[Trace] = []
        self._below: tuple[Any, Any] | None = None    # (limits and titles, bitmap)

    def _series(self, ax, data: np.ndarray, fmu: str, output: str, scale: float = 1.0,
                baseline: bool = False, **kw) -> bool:
        """Add the trace of ``fmu.output`` [times ``scale``] to ``ax`` if ``data`` (``baseline``:
        the baseline's rows) recorded it; ``kw``: the line's style (``color``, ``lw``,
        ``label``), the band takes its colour."""
        source = self.baseline if baseline else data
        if source is None or column(source, fmu, output) is None:
            return False
        if baseline:
            kw = {**kw, "color": BASELINE_COLOR}
        z = 2.0 if baseline else 2.2                 # the baseline behind the run
        line, = ax.plot([], [], zorder=z + 0.1, **kw)
        band = PolyCollection([], facecolors=line.get_color(), edgecolors=line.get_color(),
                              linewidths=0.4, alpha=0.45 if baseline else 0.75, zorder=z)
        ax.add_collection(band, autolim=False)
        self.series.append(Trace(line, band, fmu, output, scale, baseline))
        return True

    def _headed(self, axes, switch_on_time: float | None, title: str, what: str):
        """Mark the controller's switch-on in ``axes``, head the figure ``title: what``."""
        _mark(axes, switch_on_time)
        import textwrap

        width = int(self.fig.get_figwidth() * 10)       # characters of an 11-pt line
        head = [title] if len(title) <= width else title.split(": ", 1)   # scene / settings
        lines = [w for part in head for w in textwrap.wrap(part, width)]
        self.fig.suptitle("\n".join([*lines, what]) if title else what, fontsize=11)
        return self

    def _pixels(self, ax) -> int:
        """Width of ``ax`` in saved pixels (:data:`DPI`)."""
        return max(1, int(ax.get_position().width * self.fig.get_figwidth() * DPI))

    def update(self, data: np.ndarray, t_end: float | None = None) -> None:
        """Set the traces from ``data`` (at least 2 rows) and the baseline, and rescale the axes.

        ``t_end`` [s]: the time axis as if the rows went on to ``t_end`` (a run's rows so far
        drawn with the time axis of the whole run). The baseline is drawn up to the end of that
        axis."""
        t = data["time"]
        stop = max(float(t[-1]), t_end if t_end is not None else -np.inf)
        for tr in self.series:
            source = self.baseline if tr.baseline else data
            ts = np.asarray(source["time"], dtype=float)
            y = column(source, tr.fmu, tr.output) * tr.scale
            if tr.baseline:
                keep = ts <= stop
                ts, y = ts[keep], y[keep]
            px = self._pixels(tr.line.axes)
            if len(ts) > 2 * px:             # denser than the pixels: its envelope
                n = px // BAND_PIXELS
                if self.period and len(ts) > 1:
                    n = max(1, min(n, int((ts[-1] - ts[0]) / self.period)))
                band = bands(ts, y, n)
                if tr.baseline:              # the baseline: its upper envelope, a line
                    half = len(band) // 2
                    tr.line.set_data(band[half:, 0][::-1], band[half:, 1][::-1])
                    tr.band.set_verts([])
                else:
                    tr.line.set_data([], [])
                    tr.band.set_verts([band])
            else:
                tr.line.set_data(*envelope(ts, y, int(np.ceil(px * SHOW_DPI / DPI))))
                tr.band.set_verts([])
        drawn = list({id(tr.line.axes): tr.line.axes for tr in self.series}.values())
        for ax in drawn:                # an axes without series keeps its limits (0 .. 1)
            ax.relim()
            for tr in self.series:
                if tr.line.axes is ax and tr.band.get_paths():
                    ax.update_datalim(tr.band.get_paths()[0].vertices)
            if t_end is not None and t_end > t[-1]:
                ax.dataLim.update_from_data_x(np.array([t_end]), ignore=False)
        for ax in drawn:
            ax.autoscale_view()

    def _above(self, ax) -> list:
        """The artists of ``ax`` from its traces up, in the order it draws them."""
        low = min((tr.band.get_zorder() for tr in self.series if tr.line.axes is ax),
                  default=min((line.get_zorder() for line in ax.lines), default=np.inf))
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




def _mark(axes, switch_on_time: float | None) -> None:
    if switch_on_time:
        for ax in np.ravel(axes):
            ax.axvline(switch_on_time, color="0.4", ls=":", lw=1.0)
        ax = np.ravel(axes)[0]
        ax.annotate("controller on", (switch_on_time, 1.0), xycoords=("data", "axes fraction"),
                    xytext=(3, -12), textcoords="offset points", fontsize=8, color="0.3")
