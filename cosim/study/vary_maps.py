"""Maps of sweeps over two scene keys (``drillcosim sweep --vary``): one metric on a grid.

:func:`plot_vary_map` draws, for each sweep folder given (e.g. one per controller law), a panel
of the closed-loop points over two of the varied keys (or ``delay`` / ``step`` / ``gain``, the
shortcut axes): the metric's value in each cell (colour, log scale; the number written in it),
a diverged point marked ``x``. The panels share the colour scale, so laws compare at a glance.

``python -m drillcosim.cosim.study.vary_maps OUT.png FOLDER [FOLDER ...] --x KEY --y KEY
[--metric stick_slip_severity]`` draws it from the command line (docs/physics.md section 6
gives the commands of its figure).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from .table import read_table

__all__ = ["axis_value", "plot_vary_map"]

#: The table's own columns that are axes of every sweep (the shortcut axes).
SHORTCUTS = ("gain", "delay", "step")


def axis_value(row: dict[str, Any], key: str) -> float:
    """A point's value of axis ``key``: a shortcut column, else its ``varied`` entry."""
    if key in SHORTCUTS:
        return float(row[key])
    return float(json.loads(row["varied"] or "{}")[key])


def _label(key: str) -> str:
    scale = {"delay": "actuator delay [ms]", "step": "communication step [ms]",
             "cosim.actuator_delay": "actuator delay [ms]",
             "cosim.controller_sample_period": "controller sample period [ms]"}
    return scale.get(key, key)


def _ms(key: str) -> float:
    return 1e3 if key in ("delay", "step", "cosim.actuator_delay", "cosim.step",
                          "cosim.controller_sample_period", "cosim.sensor_delay") else 1.0


def plot_vary_map(folders: Sequence[str | Path], x: str, y: str, path: str | Path,
                  metric: str = "stick_slip_severity", titles: Sequence[str] = ()) -> Path:
    """One panel per sweep folder: ``metric`` of its closed-loop points over ``x`` and ``y``.

    Parameters
    ----------
    folders : sequence of path-like
        Sweep folders (``results.csv``).
    x, y : str
        Axes: a varied key path or ``gain`` / ``delay`` / ``step``.
    path : path-like
        The PNG written.
    metric : str
        A numeric column of the table.
    titles : sequence of str, optional
        Panel titles (default: each folder's scene).

    Returns
    -------
    Path
    """
    import matplotlib

    matplotlib.use("Agg")
    from matplotlib.colors import LogNorm
    from matplotlib.figure import Figure

    tables = [[r for r in read_table(f) if r["kind"] == "closed_loop"] for f in folders]
    values = [r[metric] for rows in tables for r in rows
              if r["status"] == "ok" and isinstance(r[metric], float) and r[metric] > 0]
    norm = LogNorm(vmin=max(min(values, default=1e-3), 1e-4), vmax=max(values, default=1.0))
    fig = Figure(figsize=(4.2 * len(tables) + 0.8, 4.0))
    axes = fig.subplots(1, len(tables), squeeze=False)[0]
    image = None
    for k, (ax, rows) in enumerate(zip(axes, tables)):
        xs = sorted({axis_value(r, x) for r in rows})
        ys = sorted({axis_value(r, y) for r in rows})
        grid = np.full((len(ys), len(xs)), math.nan)
        for r in rows:
            i, j = ys.index(axis_value(r, y)), xs.index(axis_value(r, x))
            if r["status"] == "ok":
                grid[i, j] = max(r[metric], norm.vmin)
                ax.text(j, i, f"{r[metric]:.2g}", ha="center", va="center", fontsize=7)
            else:
                ax.text(j, i, "x", ha="center", va="center", fontsize=11, color="tab:red")
        image = ax.imshow(grid, origin="lower", cmap="viridis", norm=norm, aspect="auto")
        ax.set_xticks(range(len(xs)), [f"{v * _ms(x):g}" for v in xs])
        ax.set_yticks(range(len(ys)), [f"{v * _ms(y):g}" for v in ys])
        ax.set_xlabel(_label(x))
        if k == 0:
            ax.set_ylabel(_label(y))
        ax.set_title(titles[k] if k < len(titles) else (rows[0]["scene"] if rows else ""),
                     fontsize=9)
    if image is not None:
        fig.colorbar(image, ax=list(axes), label=f"{metric} (x: diverged)")
    path = Path(path)
    fig.savefig(path, dpi=110)
    return path


def main(argv: Sequence[str] | None = None) -> int:
    """Command-line entry point; returns the exit status."""
    parser = argparse.ArgumentParser(prog="python -m drillcosim.cosim.study.vary_maps",
                                     description=__doc__.split("\n")[0])
    parser.add_argument("out", help="the PNG to write")
    parser.add_argument("folders", nargs="+", help="sweep folders, one panel each")
    parser.add_argument("--x", required=True, help="the x axis (a --vary key, gain, delay, step)")
    parser.add_argument("--y", required=True, help="the y axis")
    parser.add_argument("--metric", default="stick_slip_severity")
    parser.add_argument("--title", action="append", default=[], help="a panel's title")
    args = parser.parse_args(argv)
    print(plot_vary_map(args.folders, args.x, args.y, args.out, args.metric, args.title))
    return 0


if __name__ == "__main__":
    sys.exit(main())
