"""Run a scene end to end: scene -> system -> co-simulation -> results, summary, plots.

Used by ``drillcosim run`` (:mod:`cosim.cli`). The output folder (default
``out/<scene>``) receives

* ``results.csv`` - every recorded variable at the output interval, header
  line ``time,plant.body11_X,...`` (streamed during the run, moved into place
  atomically; readable by ``numpy.loadtxt(..., delimiter=",", skiprows=1)``);
* ``summary.json`` - see :mod:`cosim.scenario.summary`;
* ``orbit.png``, ``orbit_steady.png``, ``deflection_contact.png``,
  ``actuators.png`` - see :mod:`cosim.scenario.plots`.

A run that fails while stepping (divergence: a non-finite output, or the plant
discarding a step) keeps the rows recorded so far, writes the summary (with
``diverged`` set) and the plots, and reports one line; exit code 1. A run that
fails before the first step leaves earlier files of the folder untouched and
raises :class:`CosimError` whose message ends with the FMU's own message, received
through the FMI logger callback (e.g. the plant naming an out-of-range parameter at
``fmi2ExitInitializationMode``).
Bad input raises ``ValueError`` (exit code 2 in the CLI; so does an FMU
rejecting its parameters with fmi2Error at initialization).
"""

from __future__ import annotations

import dataclasses
import math
import os
import sys
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

from drillcosim.cosim.master.errors import CosimError
from drillcosim.cosim.master.master import Master, Result

__all__ = ["EXIT_DIVERGED", "EXIT_OK", "SceneOutcome", "parse_set", "scene_system_from_options",
           "seconds_text",
           "simulate_into", "simulate_scene", "simulate_system"]

EXIT_OK = 0
EXIT_DIVERGED = 1


def seconds_text(seconds: float) -> str:
    """A wall time [s] for a one-line message: 3 significant digits, whole seconds from 1000 s."""
    return f"{seconds:.3g}" if seconds < 1000 else f"{seconds:.0f}"


@dataclass(frozen=True)
class SceneOutcome:
    """What :func:`simulate_scene` produced.

    Attributes
    ----------
    exit_code : int
        0 (completed) or 1 (stopped early: divergence or an FMU failure).
    message : str
        One line: where the files are, or why the run stopped.
    out_dir : Path
    summary : dict
        The content of ``summary.json``.
    files : tuple of Path
        Files written.
    """

    exit_code: int
    message: str
    out_dir: Path
    summary: dict
    files: tuple[Path, ...]


def _value(text: str) -> Any:
    try:
        return tomllib.loads(f"v = {text}")["v"]
    except tomllib.TOMLDecodeError:
        return text  # a bare word: take it as a string (e.g. mode=compressive_only)


def parse_set(items: Sequence[str]) -> dict[str, Any]:
    """``["section.key=value", ...]`` -> nested overrides dict (values parsed as TOML).

    ``key=value`` without a section sets a top-level scene key (e.g.
    ``gravity=0``). A value that is not valid TOML is taken as a string.

    Raises
    ------
    ValueError
        On an item without ``=`` or with an empty key.
    """
    out: dict[str, Any] = {}
    for item in items:
        key, sep, text = item.partition("=")
        key = key.strip()
        if not sep or not key or any(not p for p in key.split(".")):
            raise ValueError(f"--set {item!r}: expected section.key=value (value in TOML "
                             "syntax, e.g. cosim.actuator_delay=0.002)")
        node = out
        *path, last = key.split(".")
        for p in path:
            node = node.setdefault(p, {})
            if not isinstance(node, dict):
                raise ValueError(f"--set {item!r}: '{p}' is set both as a value and a table")
        node[last] = _value(text.strip())
    return out


def _merge(base: dict[str, Any], over: Mapping[str, Any]) -> dict[str, Any]:
    out = dict(base)
    for k, v in over.items():
        if isinstance(v, Mapping) and isinstance(out.get(k), dict):
            out[k] = _merge(out[k], v)
        else:
            out[k] = dict(v) if isinstance(v, Mapping) else v
    return out


def _failure(err: CosimError | None, result: Result) -> dict[str, Any] | None:
    if result.diverged is not None:
        d = result.diverged
        return {"time_s": d.time, "quantity": d.quantity, "value": d.value,
                "message": f"non-finite {d.quantity} = {d.value!r} at t = {d.time:.6g} s"}
    if err is None:
        return None
    return {"time_s": err.time, "quantity": f"{err.fmu_name}.{err.call}", "value": None,
            "message": f"FMU '{err.fmu_name}' {err.call} failed at t = {err.time:.6g} s: "
                       f"{err.fmu_message or err.message}"}


def simulate_into(system, outputs: Sequence[str], output_ticks: int, stop: float, out: Path,
                  progress: bool | None) -> tuple[Result, dict[str, Any] | None, Path]:
    """Run ``system`` to ``stop`` [s], recording ``outputs`` every ``output_ticks`` base steps
    into ``out/results.csv`` (written atomically, :class:`cosim.master.recorder.Recorder`).

    Returns
    -------
    (Result, dict or None, Path)
        The result, the failure (time, quantity, value, message) if the run stopped early,
        and the CSV path.

    Raises
    ------
    CosimError
        If the run failed before its first step (an earlier ``results.csv`` is kept); its
        message ends with the FMU's own message when it logged one.
    """
    csv = out / "results.csv"
    err: CosimError | None = None
    try:
        result = Master(system).simulate(stop_time=stop, outputs=outputs,
                                          output_ticks=output_ticks, progress=progress,
                                          csv_path=csv)
    except CosimError as exc:
        err = exc
        result = exc.result
        if result is None or not math.isfinite(result.end_time) or \
                result.end_time <= system.start_time:
            raise
    return result, _failure(err, result), csv


def simulate_system(ss, out_dir: str | Path, stop_time: float | None = None,
                    progress: bool | None = None, plots: bool = True) -> SceneOutcome:
    """Run a :class:`cosim.scenario.scene_system.SceneSystem` and write results, summary and plots.

    Parameters
    ----------
    ss : SceneSystem
    out_dir : path-like
        Created if missing.
    stop_time : float, optional
        [s]; default ``ss.stop_time``.
    progress : bool or None
        Progress bar (None: only on a TTY).
    plots : bool
        Write the PNGs.

    Returns
    -------
    SceneOutcome
        ``exit_code`` 1 if the run stopped before ``stop_time``.

    Raises
    ------
    ValueError
        Bad stop time or output interval (nothing is written).
    CosimError
        If the run failed before its first step (earlier files are kept).
    """
    from .plot_workers import PlotWorkers

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    stop = ss.stop_time if stop_time is None else float(stop_time)
    if not (math.isfinite(stop) and stop > 0):
        raise ValueError(f"stop time: a finite number > 0 [s], got {stop!r}")
    with PlotWorkers(None if plots else 0) as workers:   # they import matplotlib meanwhile
        result, failure, csv = simulate_into(ss.system, ss.outputs, ss.settings.output_ticks,
                                             stop, out, progress)
        return _write_outputs(ss, out, stop, result, failure, csv, plots, workers)


def _write_outputs(ss, out: Path, stop: float, result: Result, failure: dict[str, Any] | None,
                   csv: Path, plots: bool, workers) -> SceneOutcome:
    """Summary, plots and the one-line message of :func:`simulate_system`."""
    from .scene_system import scene_controller, scene_top_drive_controller, span_info
    from .summary import summarize, write_json

    scene = ss.scene
    spans = span_info(scene)
    n_sites = len(scene.plant.actuator_joints)
    ctrl = scene_controller(scene)
    switch = ctrl.switch_on_time if ctrl.enabled else None
    summary = summarize(result.data, scene=scene.name, scene_file=scene.source, spans=spans,
                        n_sites=n_sites, stop_time=stop, step=ss.system.base_step,
                        output_interval=ss.output_interval, wall_time=result.wall_time,
                        real_time_factor=result.real_time_factor, end_time=result.end_time,
                        switch_on_time=switch, diverged=failure)
    summary["controller"] = dataclasses.asdict(ctrl)
    top_drive = scene_top_drive_controller(scene)
    if top_drive.enabled:
        summary["top_drive_controller"] = dataclasses.asdict(top_drive)
    summary["cosim"] = {**vars(ss.settings), "output_interval": ss.settings.output_interval}
    files = [csv, write_json(summary, out / "summary.json")]
    if plots and len(result.data) > 1:
        files += workers.plot_run(result.data, out, scene.plant.contact.clearance, spans,
                                  n_sites, title=scene.name, switch_on_time=switch or None)
    if failure is not None:
        msg = (f"run stopped at t = {result.end_time:.6g} s of {stop:g} s: "
               f"{failure['message']}; partial results in {out}")
        return SceneOutcome(EXIT_DIVERGED, msg, out, summary, tuple(files))
    pngs = [Path(f).name for f in files if str(f).endswith(".png")]
    where = f"results.csv, summary.json{' and plots ' + ', '.join(pngs) if pngs else ''} in {out}"
    msg = (f"{scene.name}: {result.end_time:g} s simulated in {seconds_text(result.wall_time)} s "
           f"(real-time factor {result.real_time_factor:.3g}); {where}")
    return SceneOutcome(EXIT_OK, msg, out, summary, tuple(files))


def scene_system_from_options(scene: str | os.PathLike, *, stop_time: float | None = None,
                              step: float | None = None, delay: float | None = None,
                              gain: float | None = None, sets: Sequence[str] = (),
                              fmu_dir: str | Path | None = None,
                              plant_fmu: str | Path | None = None,
                              controller_fmu: str | Path | None = None):
    """Load a scene with the command-line overrides and build its checked system.

    Parameters: as :func:`simulate_scene`.

    Returns
    -------
    SceneSystem

    Raises
    ------
    ValueError
        Bad input (scene, keys, values, an FMU pair that does not fit).
    """
    from drillcosim.plant.scene import load_scene

    from .scene_system import scene_system

    over: dict[str, Any] = {}
    for section, key, value in (("cosim", "stop_time", stop_time), ("cosim", "step", step),
                                ("cosim", "actuator_delay", delay),
                                ("controller", "gain", gain)):
        if value is not None:
            over.setdefault(section, {})[key] = value
    over = _merge(over, parse_set(sets))
    sc = load_scene(scene, overrides=over or None)
    plant_over = {k: v for k, v in over.items() if k not in ("cosim", "controller", "plant")}
    return scene_system(sc, fmu_dir, plant_fmu=plant_fmu, controller_fmu=controller_fmu,
                        plant_overrides=plant_over)


def simulate_scene(scene: str | os.PathLike = "paper_closed_loop", *,
                   stop_time: float | None = None, step: float | None = None,
                   delay: float | None = None, gain: float | None = None,
                   sets: Sequence[str] = (), out_dir: str | Path | None = None,
                   fmu_dir: str | Path | None = None, progress: bool | None = None,
                   plots: bool = True, plant_fmu: str | Path | None = None,
                   controller_fmu: str | Path | None = None) -> SceneOutcome:
    """Load a scene with overrides, run it and write the output folder.

    Parameters
    ----------
    scene : str or path
        Scene name (``scenes/<name>.toml``) or file.
    stop_time : float, optional
        Overrides ``[cosim] stop_time`` [s].
    step : float, optional
        Overrides ``[cosim] step`` [s].
    delay : float, optional
        Overrides ``[cosim] actuator_delay`` [s].
    gain : float, optional
        Overrides ``[controller] gain`` [N per unit strain] (does not enable a
        disabled controller).
    sets : sequence of str
        ``section.key=value`` overrides of any scene key (value parsed as TOML);
        applied after the options above.
    out_dir : path-like, optional
        Default ``out/<scene name>``.
    fmu_dir : path-like, optional
        FMU folder (default ``build/fmus``; built on demand).
    progress : bool or None
        Progress bar (None: only on a TTY).
    plots : bool
        Write the PNGs.
    plant_fmu, controller_fmu : path-like, optional
        FMU files (any maker) used instead of the project's; the pair is checked before the
        first step (:mod:`cosim.scenario.interface`).

    Returns
    -------
    SceneOutcome

    Raises
    ------
    ValueError
        Bad input (scene, keys, values, an FMU pair that does not fit), one line per problem.
    """
    ss = scene_system_from_options(scene, stop_time=stop_time, step=step, delay=delay, gain=gain,
                                   sets=sets, fmu_dir=fmu_dir, plant_fmu=plant_fmu,
                                   controller_fmu=controller_fmu)
    out = Path(out_dir) if out_dir is not None else Path("out") / ss.scene.name
    return simulate_system(ss, out, progress=progress, plots=plots)
