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

from collections.abc import Collection, Mapping, Sequence
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import numpy as np  # noqa: E402
from matplotlib.figure import Figure  # noqa: E402

from drillcosim.cosim.master.files import AtomicFile  # noqa: E402
from drillcosim.plant.signals import CONTROLLER, PLANT, TOP_DRIVE  # noqa: E402

from .summary import column, contact_bodies  # noqa: E402

__all__ = ["SHOW_DPI", "envelope", "plot_actuators", "plot_axial_torsional",
           "plot_deflection_contact", "plot_orbit", "plot_run", "save_figure", "thin_path"]

MM = 1e3  # m -> mm
KN = 1e-3  # N -> kN
#: The resolution the decimated lines keep [dots per inch] (the figures are saved at 120).
SHOW_DPI = 300


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
    """A figure of ``rows x cols`` axes with fixed margins and gaps [in] (no layout engine)."""
    fig = Figure(figsize=(width, height))
    axes = fig.subplots(rows, cols, sharex=sharex, squeeze=False)
    axes_w = (width - left - right - wspace * (cols - 1)) / cols
    axes_h = (height - top - bottom - hspace * (rows - 1)) / rows
    fig.subplots_adjust(left=left / width, right=1 - right / width, bottom=bottom / height,
                        top=1 - top / height, wspace=wspace / axes_w, hspace=hspace / axes_h)
    return fig, axes


def _series(ax, t: np.ndarray, y: np.ndarray, **kw) -> None:
    """Plot ``y(t)`` decimated to the pixel columns of the figure's width at :data:`SHOW_DPI`."""
    columns = int(np.ceil(ax.figure.get_figwidth() * SHOW_DPI))
    ax.plot(*envelope(t, y, columns), **kw)


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


def plot_orbit(data: np.ndarray, path: str | Path, clearance: float,
               spans: Mapping[int, Mapping] | None = None, title: str = "",
               t_from: float | None = None) -> Path | None:
    """X-Y orbit [mm] of the long span's middle body with the clearance circle.

    Parameters
    ----------
    t_from : float, optional
        Plot only ``t >= t_from`` [s] (default: everything).
    """
    body = _long_body(data, spans)
    if body is None:
        return None
    x, y = column(data, PLANT, f"body{body}_X"), column(data, PLANT, f"body{body}_Y")
    if x is None or y is None:
        return None
    sel = np.ones(len(x), bool) if t_from is None else data["time"] >= t_from
    fig, axes = _figure(5.5, 5.5, 1, 1, top=0.5, left=0.7, bottom=0.55)
    ax = axes[0, 0]
    lim = 1.15 * max(clearance * MM, float(np.nanmax(np.hypot(x[sel], y[sel]))) * MM)
    # a 300-dpi pixel of the (at most 5.5 in wide) axes
    ax.plot(*thin_path(x[sel] * MM, y[sel] * MM, 2 * lim / (5.5 * SHOW_DPI)), lw=0.6,
            color="tab:blue", label="mass centre")
    phi = np.linspace(0, 2 * np.pi, 361)
    ax.plot(clearance * MM * np.cos(phi), clearance * MM * np.sin(phi), "k--", lw=1.0,
            label=f"clearance {clearance * MM:g} mm")
    ax.set_xlim(-lim, lim)
    ax.set_ylim(-lim, lim)
    ax.set_aspect("equal")
    ax.set_xlabel("X [mm]")
    ax.set_ylabel("Y [mm]")
    ax.grid(alpha=0.3)
    ax.legend(loc="upper right", fontsize=8)
    window = "" if t_from is None else f", t >= {t_from:g} s"
    ax.set_title(f"{title}\nlateral orbit, {_span_label(body, spans)}{window}".strip(), y=1.0)
    return save_figure(fig, path, compress_level=1)


def _mark(axes, switch_on_time: float | None) -> None:
    if switch_on_time:
        for ax in np.ravel(axes):
            ax.axvline(switch_on_time, color="0.4", ls=":", lw=1.0)
        ax = np.ravel(axes)[0]
        ax.annotate("controller on", (switch_on_time, 1.0), xycoords=("data", "axes fraction"),
                    xytext=(3, -12), textcoords="offset points", fontsize=8, color="0.3")


def plot_deflection_contact(data: np.ndarray, path: str | Path, clearance: float,
                            spans: Mapping[int, Mapping] | None = None,
                            title: str = "", switch_on_time: float | None = None) -> Path | None:
    """Radial deflection [mm] and contact force [kN] vs time at each contact body.

    ``switch_on_time`` [s], if given, is marked by a dotted line.
    """
    bodies = contact_bodies(data)
    if not bodies:
        return None
    t = data["time"]
    fig, axes = _figure(5 * len(bodies), 6, 2, len(bodies), sharex=True)
    for j, b in enumerate(bodies):
        r = column(data, PLANT, f"body{b}_radial_deflection")
        f = column(data, PLANT, f"body{b}_contact_force")
        ax = axes[0, j]
        _series(ax, t, r * MM, lw=0.7)
        ax.axhline(clearance * MM, color="k", ls="--", lw=1.0, label="clearance")
        ax.set_ylabel("radial deflection [mm]")
        ax.set_title(_span_label(b, spans), y=1.0)   # y given: no title-overlap search
        ax.legend(loc="upper left", fontsize=8)
        ax.grid(alpha=0.3)
        ax = axes[1, j]
        if f is not None:
            _series(ax, t, f * KN, lw=0.7, color="tab:red")
        ax.set_ylabel("contact force [kN]")
        ax.set_xlabel("time [s]")
        ax.grid(alpha=0.3)
    _mark(axes, switch_on_time)
    fig.suptitle(f"{title}: radial deflection and wellbore contact force" if title else
                 "radial deflection and wellbore contact force")
    return save_figure(fig, path, compress_level=1)


def plot_actuators(data: np.ndarray, path: str | Path, n_sites: int = 2,
                   spans_by_site: Sequence[str] | None = None, title: str = "",
                   switch_on_time: float | None = None) -> Path | None:
    """Actuator forces [kN] (C and E) and delivered power [W] vs time per site."""
    t = data["time"]
    if all(column(data, PLANT, f"actuator{s}_power") is None for s in range(1, n_sites + 1)):
        return None
    fig, axes = _figure(5 * n_sites, 6, 2, n_sites, sharex=True)
    for j, s in enumerate(range(1, n_sites + 1)):
        ax = axes[0, j]
        for a, color in (("C", "tab:blue"), ("E", "tab:orange")):
            f = column(data, CONTROLLER, f"actuator{s}_force_{a}")
            if f is not None:
                _series(ax, t, f * KN, lw=0.7, color=color, label=f"force {a}")
        ax.set_ylabel("actuator force [kN]")
        where = f" ({spans_by_site[j]} span)" if spans_by_site and j < len(spans_by_site) else ""
        ax.set_title(f"site {s}{where}", y=1.0)
        if ax.lines:
            ax.legend(loc="upper left", fontsize=8)
        else:
            ax.text(0.5, 0.5, "controller disabled", ha="center", transform=ax.transAxes)
        ax.grid(alpha=0.3)
        ax = axes[1, j]
        p = column(data, PLANT, f"actuator{s}_power")
        if p is not None:
            _series(ax, t, p, lw=0.7, color="tab:green")
        ax.set_ylabel("actuator power [W]")
        ax.set_xlabel("time [s]")
        ax.grid(alpha=0.3)
    _mark(axes, switch_on_time)
    fig.suptitle(f"{title}: actuator force and power" if title else "actuator force and power")
    return save_figure(fig, path, compress_level=1)


#: Panels of :func:`plot_axial_torsional`: (ylabel, scale, [(fmu, output, label), ...]).
_AXIAL_TORSIONAL = (
    ("rotary speed [rad/s]", 1.0, [(PLANT, "top_rotary_speed", "top"),
                                   (PLANT, "bit_rotary_speed", "bit")]),
    ("torque [kN m]", KN, [(PLANT, "top_torque", "top (string on the drive)"),
                           (PLANT, "bit_torque", "bit (rock on the bit)"),
                           (TOP_DRIVE, "top_drive_torque", "motor (controller)")]),
    ("bit axial force [kN]", KN, [(PLANT, "bit_axial_force", "on the bit")]),
)


def plot_axial_torsional(data: np.ndarray, path: str | Path, title: str = "") -> Path | None:
    """Top and bit rotary speed [rad/s], top / bit / motor torque [kN m] and the bit's axial
    force [kN] vs time, each panel drawn if one of its outputs was recorded; times the bit is
    off the bottom (``plant.bit_on_bottom`` = 0) are shaded."""
    t = data["time"]
    panels = []
    for label, scale, curves in _AXIAL_TORSIONAL:
        found = [(y, lab) for f, n, lab in curves if (y := column(data, f, n)) is not None]
        if found:
            panels.append((label, scale, found))
    if not panels:
        return None
    fig, axes = _figure(8, 2.4 * len(panels) + 0.6, len(panels), 1, sharex=True, top=0.5,
                        right=0.25, hspace=0.2)
    off = column(data, PLANT, "bit_on_bottom")
    for ax, (label, scale, curves) in zip(axes[:, 0], panels):
        for y, lab in curves:
            _series(ax, t, y * scale, lw=0.8, label=lab)
        if off is not None and (off < 0.5).any():
            ax.fill_between(t, 0, 1, where=off < 0.5, color="0.85", step="mid",
                            transform=ax.get_xaxis_transform(), label="bit off bottom")
        ax.set_ylabel(label)
        ax.grid(alpha=0.3)
        ax.legend(loc="upper right", fontsize=8)
    axes[-1, 0].set_xlabel("time [s]")
    fig.suptitle(f"{title}: rotary speed, torque and bit force" if title else
                 "rotary speed, torque and bit force")
    return save_figure(fig, path, compress_level=1)


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
    t = data["time"]
    t_from = float(t[0] + 2.0 / 3.0 * (t[-1] - t[0])) if len(t) > 1 else None
    site_spans = None
    if spans:
        site_spans = [info.get("span", "") for _, info in sorted(spans.items())]
    if not contact_bodies(data):  # the axial-torsional chain: no lateral motion to show
        draw = {"axial_torsional": lambda: plot_axial_torsional(
            data, out / "axial_torsional.png", title)}
    else:
        draw = {
            "orbit": lambda: plot_orbit(data, out / "orbit.png", clearance, spans, title),
            "orbit_steady": lambda: plot_orbit(data, out / "orbit_steady.png", clearance, spans,
                                               title, t_from),
            "deflection_contact": lambda: plot_deflection_contact(
                data, out / "deflection_contact.png", clearance, spans, title, switch_on_time),
            "actuators": lambda: plot_actuators(data, out / "actuators.png", n_sites,
                                                site_spans, title, switch_on_time)}
    paths = [f() for name, f in draw.items() if figures is None or name in figures]
    return [p for p in paths if p is not None]
