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
raises :class:`CosimError` whose message ends with the FMU's own log line (e.g.
the plant naming an out-of-range parameter at ``fmi2ExitInitializationMode``).
Bad input raises ``ValueError`` (exit code 2 in the CLI; so does an FMU
rejecting its parameters with fmi2Error at initialization).
"""

from __future__ import annotations

import contextlib
import io
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

from drillcosim.cosim.master.cosimulation import CoSimulation, Result
from drillcosim.cosim.master.errors import CosimError

__all__ = ["EXIT_DIVERGED", "EXIT_OK", "RunOutcome", "parse_set", "run_scene", "run_system",
           "scene_system_from_options", "simulate_into"]

EXIT_OK = 0
EXIT_DIVERGED = 1


@dataclass(frozen=True)
class RunOutcome:
    """What :func:`run_scene` produced.

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


class _FmuLog(io.TextIOBase):
    """stdout pass-through remembering FMU log lines (fmpy prints them as ``[STATUS] msg``).

    A message holding a Python traceback (the native FMI wrapper logs exceptions as
    ``name: Python exception in fmi2X: Traceback ...``) is remembered with the
    traceback's last line (the exception) in place of ``Traceback ...``.
    """

    _TRACEBACK = "Traceback (most recent call last):"

    def __init__(self, target):
        self.target = target
        self.problems: list[str] = []
        self._buf = ""
        self._in_traceback = False
        self._head = ""

    def write(self, s: str) -> int:
        self.target.write(s)
        self._buf += s
        *lines, self._buf = self._buf.split("\n")
        for ln in lines:
            if ln.startswith(("[DISCARD]", "[ERROR]", "[FATAL]")):
                self.problems.append(ln)
                self._in_traceback = ln.endswith(self._TRACEBACK)
                self._head = ln[: -len(self._TRACEBACK)]
            elif ln.startswith("["):
                self._in_traceback = False
            elif self._in_traceback and ln.strip() and not ln.startswith(" "):
                self.problems[-1] = self._head + ln.strip()
        return len(s)

    def detail(self, fmu_name: str) -> str | None:
        """The last problem line of FMU instance ``fmu_name`` (else any), without the label."""
        texts = [p.split("] ", 1)[-1] for p in self.problems]
        own = [t for t in texts if t.startswith(f"{fmu_name}:")]
        return (own or texts or [None])[-1]

    def flush(self) -> None:
        self.target.flush()


def _failure(err: CosimError | None, result: Result, log: _FmuLog) -> dict[str, Any] | None:
    if result.diverged is not None:
        d = result.diverged
        return {"time_s": d.time, "quantity": d.quantity, "value": d.value,
                "message": f"non-finite {d.quantity} = {d.value!r} at t = {d.time:.6g} s"}
    if err is None:
        return None
    detail = log.detail(err.fmu_name) or err.message
    return {"time_s": err.time, "quantity": f"{err.fmu_name}.{err.call}", "value": None,
            "message": f"FMU '{err.fmu_name}' {err.call} failed at t = {err.time:.6g} s: "
                       f"{detail}"}


class _FmuLogging:
    """Observer switching on the FMUs' logging (``fmi2SetDebugLogging``) at the start.

    fmpy instantiates with logging off; pythonfmu then drops the messages that
    explain a discarded step (e.g. the plant's divergence report).
    """

    def on_start(self, execution) -> None:
        for slave in execution.slaves.values():
            with contextlib.suppress(Exception):
                slave.fmu.fmi2SetDebugLogging(slave.component, 1, 0, None)

    def on_step(self, execution) -> None:
        """Nothing to do per step."""


def _simulate(system, outputs: Sequence[str], output_interval: float, stop: float,
              progress: bool | None, csv_path: Path) -> Result:
    """:meth:`CoSimulation.run` with the FMU-logging observer added."""
    H = system.base_step
    return CoSimulation(system).run(
        stop_time=stop, outputs=outputs, output_interval=max(1, round(output_interval / H))
        * H, progress=progress, csv_path=csv_path, observers=[_FmuLogging()])


def simulate_into(system, outputs: Sequence[str], output_interval: float, stop: float,
                  out: Path, progress: bool | None) -> tuple[Result, dict[str, Any] | None, Path]:
    """Run ``system`` to ``stop`` [s], streaming ``out/results.csv`` (moved into place at the end).

    Returns
    -------
    (Result, dict or None, Path)
        The result, the failure (time, quantity, value, message) if the run stopped early,
        and the CSV path.

    Raises
    ------
    CosimError
        If the run failed before its first step (earlier files are kept); its message ends
        with the FMU's own log line when there is one.
    """
    from .summary import publish

    staging = out / ".results.running.csv"
    log = _FmuLog(sys.stdout)
    err: CosimError | None = None
    try:
        with contextlib.redirect_stdout(log):
            result = _simulate(system, outputs, output_interval, stop, progress, staging)
    except CosimError as exc:
        err = exc
        result = exc.result
        if result is None or not math.isfinite(result.end_time) or \
                result.end_time <= system.start_time:
            with contextlib.suppress(OSError):  # keep the real error visible
                staging.unlink(missing_ok=True)
            detail = log.detail(exc.fmu_name)
            if detail is None:
                raise
            full = CosimError(exc.fmu_name, exc.call, exc.time, f"{exc.message}: {detail}",
                              status=exc.status)
            full.result = exc.result
            raise full from exc
    except BaseException:
        with contextlib.suppress(OSError):
            staging.unlink(missing_ok=True)
        raise
    csv = out / "results.csv"
    if staging.exists():
        publish(staging, csv)
    return result, _failure(err, result, log), csv


def run_system(ss, out_dir: str | Path, stop_time: float | None = None,
               progress: bool | None = None, plots: bool = True) -> RunOutcome:
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
    RunOutcome
        ``exit_code`` 1 if the run stopped before ``stop_time``.

    Raises
    ------
    ValueError
        Bad stop time or output interval (nothing is written).
    CosimError
        If the run failed before its first step (earlier files are kept).
    """
    from .plots import plot_run
    from .scene_system import controller_parameters, span_info
    from .summary import summarize, write_json

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    stop = ss.stop_time if stop_time is None else float(stop_time)
    if not (math.isfinite(stop) and stop > 0):
        raise ValueError(f"stop time: a finite number > 0 [s], got {stop!r}")
    result, failure, csv = simulate_into(ss.system, ss.outputs, ss.output_interval, stop, out,
                                         progress)
    scene = ss.scene
    spans = span_info(scene)
    n_sites = len(scene.plant.actuator_joints)
    ctrl = controller_parameters(scene)
    switch = ctrl["switch_on_time"] if ctrl["enabled"] else None
    summary = summarize(result.data, scene=scene.name, scene_file=scene.source, spans=spans,
                        n_sites=n_sites, stop_time=stop, step=ss.system.base_step,
                        output_interval=ss.output_interval, wall_time=result.wall_time,
                        real_time_factor=result.real_time_factor, end_time=result.end_time,
                        switch_on_time=switch, diverged=failure)
    summary["controller"] = ctrl
    summary["cosim"] = {k: v for k, v in vars(ss.settings).items()}
    files = [csv, write_json(summary, out / "summary.json")]
    if plots and len(result.data) > 1:
        files += plot_run(result.data, out, scene.plant.contact.clearance, spans, n_sites,
                          title=scene.name, switch_on_time=switch or None)
    if failure is not None:
        msg = (f"run stopped at t = {result.end_time:.6g} s of {stop:g} s: "
               f"{failure['message']}; partial results in {out}")
        return RunOutcome(EXIT_DIVERGED, msg, out, summary, tuple(files))
    pngs = [Path(f).name for f in files if str(f).endswith(".png")]
    where = f"results.csv, summary.json{' and plots ' + ', '.join(pngs) if pngs else ''} in {out}"
    msg = (f"{scene.name}: {result.end_time:g} s simulated in {result.wall_time:.1f} s "
           f"(real-time factor {result.real_time_factor:.3g}); {where}")
    return RunOutcome(EXIT_OK, msg, out, summary, tuple(files))


def scene_system_from_options(scene: str | os.PathLike, *, stop_time: float | None = None,
                              step: float | None = None, delay: float | None = None,
                              gain: float | None = None, sets: Sequence[str] = (),
                              fmu_dir: str | Path | None = None,
                              plant_fmu: str | Path | None = None,
                              controller_fmu: str | Path | None = None):
    """Load a scene with the command-line overrides and build its checked system.

    Parameters: as :func:`run_scene`.

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


def run_scene(scene: str | os.PathLike = "paper_closed_loop", *, stop_time: float | None = None,
              step: float | None = None, delay: float | None = None, gain: float | None = None,
              sets: Sequence[str] = (), out_dir: str | Path | None = None,
              fmu_dir: str | Path | None = None, progress: bool | None = None,
              plots: bool = True, plant_fmu: str | Path | None = None,
              controller_fmu: str | Path | None = None) -> RunOutcome:
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
    RunOutcome

    Raises
    ------
    ValueError
        Bad input (scene, keys, values, an FMU pair that does not fit), one line per problem.
    """
    ss = scene_system_from_options(scene, stop_time=stop_time, step=step, delay=delay, gain=gain,
                                   sets=sets, fmu_dir=fmu_dir, plant_fmu=plant_fmu,
                                   controller_fmu=controller_fmu)
    out = Path(out_dir) if out_dir is not None else Path("out") / ss.scene.name
    return run_system(ss, out, progress=progress, plots=plots)
