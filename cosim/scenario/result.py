"""The result of a simulated scene: recorded data with units, summary, plots, files.

:class:`Result` is what :func:`drillcosim.simulate` returns and what ``drillcosim run``
writes (:meth:`Result.save`):

* ``results.csv`` - every recorded variable at the output interval, header line
  ``time,plant.body11_X,...`` (readable by ``numpy.loadtxt(..., delimiter=",", skiprows=1)``;
  17 significant digits: the numbers of the run, exactly);
* ``summary.json`` - :attr:`Result.summary` (:mod:`.summary`);
* the figures of :meth:`Result.plot` (:mod:`.plots`, matplotlib figures) as PNGs: ``orbit.png``,
  ``deflection_contact.png``, ``actuators.png`` (``axial_torsional.png`` for the chain), a
  closed-loop run against its open-loop baseline (:mod:`.baseline`).
"""

from __future__ import annotations

import base64
import math
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path
from typing import Any

import numpy as np

from drillcosim.cosim.master.files import AtomicFile
from drillcosim.plant.signals import CONTROLLER

from .config import SceneConfig
from .summary import span_info, summarize, write_json

__all__ = ["Figures", "Result", "plot_settings", "run_title", "seconds_text"]


def seconds_text(seconds: float) -> str:
    """A wall time [s] for a one-line message: 3 significant digits, whole seconds from 1000 s."""
    return f"{seconds:.3g}" if seconds < 1000 else f"{seconds:.0f}"


def run_title(config: SceneConfig) -> str:
    """A run's figure title: the scene, the strain controller's gain [N/strain] (or that it is
    off) and switch-on time, the actuator delay [ms] and the communication step [ms]."""
    ctrl, st = config.controller, config.cosim
    gain = getattr(ctrl.params, "gain", None)
    if not ctrl.enabled:
        law = "controller off"
    elif ctrl.matrices is not None:
        law = f"state-space controller {ctrl.matrices.name}"
    elif CONTROLLER in config.fmu_files:
        law = f"controller FMU {config.fmu_files[CONTROLLER].name}"
    elif gain is None:
        law = f"{ctrl.kind} law"
    else:
        k = f"{gain:.3g}".replace("e+0", "e").replace("e+", "e").replace("e-0", "e-")
        law = (f"{'' if ctrl.kind == 'proportional' else ctrl.kind.upper() + ' '}K = {k} N/strain"
               + (f" from {config.switch_on_time:g} s" if config.switch_on_time else ""))
    return (f"{config.name}: {law}, actuator delay {st.actuator_delay * 1e3:g} ms, "
            f"step H = {st.step * 1e3:g} ms")


def plot_settings(config: SceneConfig, baseline: str | Path | None = None) -> dict[str, Any]:
    """The keyword arguments of :func:`.plots.plot_run` for a run of ``config`` besides its
    rows and folder: clearance [m], spans, sites, title (:func:`run_title`), controller
    switch-on time [s], the baseline's file (:func:`.baseline.baseline_path`) and the top
    drive's period [s]."""
    speed = config.scene.plant.top_drive.rotary_speed
    return {"clearance": config.scene.plant.contact.clearance,
            "spans": span_info(config.scene), "n_sites": config.n_sites,
            "title": run_title(config),
            "switch_on_time": config.switch_on_time or None,
            "baseline": None if baseline is None else str(baseline),
            "revolution": 2 * math.pi / speed if speed > 0 else None}


class Figures(dict):
    """A run's figures: file name without ``.png`` -> ``matplotlib.figure.Figure`` (restyle or
    overlay them; :meth:`save` writes the PNGs); a notebook shows them inline."""

    def save(self, folder: str | Path) -> list[Path]:
        """Write ``<name>.png`` of every figure into ``folder`` (created; files atomic)."""
        from .plots import save_figure

        out = Path(folder)
        out.mkdir(parents=True, exist_ok=True)
        return [save_figure(fig, out / f"{name}.png", dpi=fig.dpi, compress_level=1)
                for name, fig in self.items()]

    def _repr_html_(self) -> str:
        import io

        html = []
        for name, fig in self.items():
            buf = io.BytesIO()
            fig.savefig(buf, format="png", dpi=fig.dpi)
            html.append(f'<img src="data:image/png;base64,'
                        f'{base64.b64encode(buf.getvalue()).decode()}" title="{name}"/>')
        return "".join(html)


@dataclass(frozen=True, eq=False)
class Result:
    """A simulated scene.

    Attributes
    ----------
    config : SceneConfig
        What ran (scene, controllers, co-simulation settings, overrides).
    engine : {"fmu", "inprocess"}
    data : numpy.ndarray
        Structured array, shape (n_rows,): ``time`` [s], then one field per recorded variable
        ``'instance.variable'`` (e.g. ``plant.body11_radial_deflection`` [m]).
    units : dict of str -> str
        The unit of each field of ``data`` (``"1"``: dimensionless, e.g. a strain).
    stop_time : float
        Requested stop time [s].
    end_time : float
        Simulated time reached [s] (< ``stop_time`` if the run stopped early).
    wall_time : float
        Wall-clock time of the stepping loop [s].
    real_time_factor : float
        Simulated / wall time [1].
    failure : dict or None
        Why the run stopped early, ``{"time_s", "quantity", "value", "message"}``; None if it
        completed.
    csv_path : Path or None
        The ``results.csv`` streamed during the run, if any.
    components : dict
        What ran each instance (:meth:`.build.BuiltSystem.components`: the FMU file, GUID,
        model name, generation tool, drillcosim version and the parameters set).
    profile : dict
        Where the stepping loop's time went (:meth:`cosim.master.master.Result.profile`): per
        component the mean and longest step [s] and its share, the master's own share, the
        real-time factor; ``summary.json``'s ``telemetry``, :meth:`profile_table`.
    """

    config: SceneConfig
    engine: str
    data: np.ndarray
    units: dict[str, str]
    stop_time: float
    end_time: float
    wall_time: float
    real_time_factor: float
    failure: dict[str, Any] | None = None
    csv_path: Path | None = None
    components: dict[str, Any] = field(default_factory=dict)
    profile: dict[str, Any] = field(default_factory=dict)

    @property
    def completed(self) -> bool:
        """The run reached its stop time."""
        return self.failure is None

    @property
    def columns(self) -> tuple[str, ...]:
        """The recorded variables ``'instance.variable'`` (``time`` aside)."""
        return tuple(n for n in self.data.dtype.names if n != "time")

    def __getitem__(self, name: str) -> np.ndarray:
        """One recorded column (``"time"`` or ``'instance.variable'``), as floats."""
        return np.asarray(self.data[name], dtype=float)

    def to_pandas(self):
        """The recorded data as a ``pandas.DataFrame``: index ``time`` [s], one column per
        variable ``'instance.variable'`` (units: :attr:`units`)."""
        import pandas as pd  # an optional heavy import: only here

        frame = pd.DataFrame({n: self.data[n] for n in self.columns},
                             index=pd.Index(self.data["time"], name="time"))
        frame.attrs["units"] = dict(self.units)
        return frame

    @cached_property
    def spans(self) -> dict[int, dict[str, Any]]:
        """Per contact body: its span's length [m] and ``'long'`` / ``'short'`` / ``'only'``."""
        return span_info(self.config.scene)

    @cached_property
    def summary(self) -> dict[str, Any]:
        """Peak and steady deflection, actuator effort, contact, stick-slip (the keys of
        :mod:`.summary`), and the run's controllers and co-simulation settings."""
        cfg = self.config
        summary = summarize(self.data, scene=cfg.name, scene_file=cfg.source, spans=self.spans,
                            n_sites=cfg.n_sites, stop_time=self.stop_time, step=cfg.cosim.step,
                            output_interval=cfg.cosim.output_interval, wall_time=self.wall_time,
                            real_time_factor=self.real_time_factor, end_time=self.end_time,
                            switch_on_time=self._switch_on_time, diverged=self.failure)
        summary["controller"] = cfg.controller.record()
        if cfg.top_drive.enabled:
            summary["top_drive_controller"] = cfg.top_drive.record()
        summary["cosim"] = cfg.cosim.as_dict()
        summary["engine"] = self.engine
        summary["components"] = self.components
        summary["telemetry"] = self.profile
        return summary

    def profile_table(self) -> str:
        """:attr:`profile` as a text table (``drillcosim run --profile``): per component its
        steps, mean and longest step [us], exchange calls [s] and share of the stepping loop;
        then the master's own share and the real-time factor."""
        p = self.profile
        if not p:
            return "no telemetry (the run did not step)"
        lines = [f"{'component':<22}{'steps':>9}{'mean step':>12}{'max step':>12}"
                 f"{'exchange':>11}{'share':>8}",
                 f"{'':<22}{'':>9}{'[us]':>12}{'[us]':>12}{'[s]':>11}{'[%]':>8}"]
        for name, c in p["components"].items():
            lines.append(f"{name:<22}{c['steps']:>9d}{1e6 * c['step_mean_s']:>12.2f}"
                         f"{1e6 * c['step_max_s']:>12.1f}{c['exchange_s']:>11.3f}"
                         f"{100 * c['share']:>8.1f}")
        lines.append(f"{'master (exchange, recording, observers)':<66}"
                     f"{100 * p['master_share']:>8.1f}")
        lines.append(f"stepping loop {p['wall_time_s']:.3g} s for {self.end_time:g} s simulated: "
                     f"real-time factor {p['real_time_factor']:.3g}")
        return "\n".join(lines)

    @property
    def _switch_on_time(self) -> float | None:
        return self.config.switch_on_time

    def baseline(self) -> Path | None:
        """The file of this run's open-loop baseline (:func:`.baseline.baseline_path`: taken
        from the cache, or run once now); None for a run without the strain controller."""
        from .baseline import baseline_path

        return baseline_path(self.config)

    def plot(self, baseline: bool = True) -> Figures:
        """The run's figures (:mod:`.plots`), as matplotlib figures.

        Parameters
        ----------
        baseline : bool
            Draw the open-loop baseline behind the run (:meth:`baseline`; a closed-loop run
            only).

        Returns
        -------
        Figures
            ``{"orbit": Figure, "deflection_contact": Figure, "actuators": Figure}`` (the
            axial-torsional chain: ``{"axial_torsional": Figure}``); empty when fewer than two
            rows were recorded.
        """
        if len(self.data) < 2:
            return Figures()
        from .plots import run_figures  # matplotlib: imported only when plotting

        settings = plot_settings(self.config, self.baseline() if baseline else None)
        figures = Figures()
        for name, fig in run_figures(self.data, **settings).items():
            fig.update(self.data)
            figures[name] = fig.fig
        return figures

    def save(self, folder: str | Path, plots: bool = True, workers=None,
             baseline: bool | str | Path | None = True) -> list[Path]:
        """Write ``results.csv``, ``summary.json`` and (``plots``) the PNGs into ``folder``
        (created if missing; each file written atomically). A ``results.csv`` the run streamed
        into ``folder`` is kept as it is.

        ``workers``: a :class:`.plot_workers.PlotWorkers` started with the run (``drillcosim
        run`` does), which draws the figures in parallel; default: drawn in this process.
        ``baseline``: as for :meth:`plot`, or the baseline's file (:meth:`baseline`; None: none).

        Returns
        -------
        list of Path
            The files written.
        """
        out = Path(folder)
        out.mkdir(parents=True, exist_ok=True)
        csv = out / "results.csv"
        if self.csv_path is None or Path(self.csv_path).resolve() != csv.resolve():
            flat = self.data.view(np.float64).reshape(len(self.data), -1) if len(self.data) \
                else np.zeros((0, len(self.data.dtype.names)))
            with AtomicFile(csv, "w", newline="") as fh:
                fh.write(",".join(self.data.dtype.names) + "\n")
                np.savetxt(fh, flat, delimiter=",", fmt="%.17g")
        files = [csv, write_json(self.summary, out / "summary.json")]
        if plots and len(self.data) >= 2:
            if baseline is True:
                baseline = self.baseline()
            settings = plot_settings(self.config, baseline or None)
            if workers is None:
                from .plots import plot_run  # matplotlib: imported only when plotting
            else:
                plot_run = workers.plot_run
            files += list(plot_run(self.data, out, **settings))
        return files

    def message(self, folder: Path | None = None, files: list[Path] | None = None) -> str:
        """One line: what ran and where the files are, or why the run stopped."""
        where = f" in {folder}" if folder is not None else ""
        if self.failure is not None:
            return (f"run stopped at t = {self.end_time:.6g} s of {self.stop_time:g} s: "
                    f"{self.failure['message']}" + (f"; partial results{where}" if where else ""))
        pngs = [Path(f).name for f in files or () if str(f).endswith(".png")]
        saved = (f"; results.csv, summary.json{' and plots ' + ', '.join(pngs) if pngs else ''}"
                 f"{where}") if folder is not None else ""
        return (f"{self.config.name}: {self.end_time:g} s simulated in "
                f"{seconds_text(self.wall_time)} s (real-time factor "
                f"{self.real_time_factor:.3g}){saved}")

    def __repr__(self) -> str:
        return (f"<drillcosim.Result {self.config.name!r} ({self.engine}): {len(self.data)} rows "
                f"x {len(self.columns)} variables, {self.end_time:g} of {self.stop_time:g} s"
                f"{'' if self.completed else ', stopped early: ' + self.failure['message']}>")
