"""Parameter sweeps over controller gain x actuator delay x communication step.

``drillcosim sweep SCENE --gain LIST --delay LIST --step LIST`` simulates one
co-simulation per point (:func:`cosim.study.point.measure_point`), plus one
open-loop reference per step for the control benefit, and records each point
as it finishes in ``OUT/results.csv`` / ``results.parquet``
(:mod:`cosim.study.table`). Re-running the same sweep into the same folder
skips the finished points, so a killed sweep resumes where it stopped.

Executors: a local process pool (``spawn``; ``workers`` processes, default all
cores), an existing dask.distributed cluster (``scheduler``: an address or a
``distributed.Client``), or ``workers=0``: in this process, one after another.
A point that raises, or whose worker process dies, is recorded as an ``error``
row with its reason and never stops the sweep (``retry_errors`` re-runs them).
The verdicts (stable / unstable / undecided, :mod:`cosim.study.verdict`) are the table's,
computed from the finished rows whatever order they finished in.
"""

from __future__ import annotations

import json
import math
import multiprocessing
import os
import time
import warnings
from collections.abc import Callable, Iterator, Mapping, Sequence
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool
from dataclasses import dataclass, fields, replace
from pathlib import Path
from typing import Any, Protocol

from numpy.linalg import LinAlgError
from tqdm import tqdm

from drillcosim.cosim.master.errors import UserError
from drillcosim.cosim.scenario.build import build_system, scene_recipes
from drillcosim.cosim.scenario.config import (
    ConfigError,
    SceneConfig,
    check_key_path,
    load_config,
)
from drillcosim.cosim.scenario.scene_fmus import default_fmu_dir, ensure_recipes
from drillcosim.plant.signals import CONTROLLER, TOP_DRIVE

from .branch import branch_points
from .grid import DEFAULT_GAIN_KEY, Point, SweepSpec, check_gain_key
from .point import PointOptions, error_row, measure_point, point_config
from .table import ResultTable, notes, verdict_counts
from .verdict import scene_judging_window

__all__ = ["StudyPoint", "SweepOutcome", "SweepSpec", "check_points", "describe_components",
           "execute_points", "execute_sweep", "judging_note", "point_row", "sweep_spec"]

#: A point measurement: ``measure(**point.kwargs()) -> dict`` (module-level, picklable).
Measure = Callable[..., dict]


class StudyPoint(Protocol):
    """What the executors need of a point (:class:`cosim.study.grid.Point` is one).

    A point is frozen and picklable; ``key`` identifies it in its results table (a resumed
    study skips known keys), ``kwargs()`` are the measurement's arguments and ``identity()``
    the row's identity columns (``key`` included), written whatever the measurement returns.
    """

    @property
    def key(self) -> str: ...

    def kwargs(self) -> dict[str, Any]: ...

    def identity(self) -> dict[str, Any]: ...


@dataclass(frozen=True)
class SweepOutcome:
    """What :func:`execute_sweep` did, and the verdicts of the sweep's points.

    Attributes
    ----------
    folder : Path
    n_points : int
        Points of the sweep (including open-loop references).
    n_skipped : int
        Already in the table.
    n_run : int
    wall_time : float
        [s].
    counts : dict of str -> int
        Points of this sweep per verdict (:data:`cosim.study.verdict.VERDICTS`), from the
        table after the run: the same for any completion order and after a resume.
    notes : tuple of str
        One line each: points whose verdict differs from the linear prediction, points whose
        benefit cannot be judged (:func:`cosim.study.table.notes`).
    """

    folder: Path
    n_points: int
    n_skipped: int
    n_run: int
    wall_time: float
    counts: dict[str, int]
    notes: tuple[str, ...] = ()

    @property
    def n_errors(self) -> int:
        """Points recorded with status ``error``."""
        return self.counts.get("error", 0)

    def summary(self) -> str:
        """One line of verdict counts (a function of the table only)."""
        parts = [f"{n} {v}" for v, n in self.counts.items() if n]
        return (f"sweep: {self.n_points} points: {', '.join(parts) or 'none finished'}; table "
                f"{self.folder / 'results.csv'} and results.parquet")


def point_row(point: StudyPoint, measure: Measure = measure_point) -> dict[str, Any]:
    """Run a point and return its full table row; exceptions become an ``error`` row.

    Module-level and free of closures, so it pickles to process-pool and dask
    workers. ``point`` is a :class:`cosim.study.grid.Point` or any :class:`StudyPoint`.
    """
    started = _worker_startup()
    wall0 = time.perf_counter()
    try:
        row = dict(measure(**point.kwargs()))
    except Exception as exc:  # one bad point never stops the sweep
        row = error_row(exc, time.perf_counter() - wall0)
    row["worker_startup"] = started
    row.update(point.identity())
    return row


#: This process has run a point already (:func:`_worker_startup`).
_STARTED = False


def _worker_startup() -> float:
    """Seconds from this process's start to its first point (interpreter, imports, unpickling
    the point) [s]; NaN for its later points and where the start time is unknown."""
    global _STARTED
    if _STARTED:
        return math.nan
    _STARTED = True
    try:
        import psutil  # a dependency of dask.distributed

        return time.time() - psutil.Process().create_time()
    except Exception:  # noqa: BLE001 - no psutil, or no process table: unknown
        return math.nan


def _lost_row(point: StudyPoint, reason: str) -> dict[str, Any]:
    row = {"status": "error", "reason": reason}
    row.update(point.identity())
    return row


def _local(points: Sequence[StudyPoint], measure: Measure, workers: int
           ) -> Iterator[dict[str, Any]]:
    """Process pool; a dead worker breaks the pool: restart it, retry each point once."""
    attempts: dict[str, int] = {}
    todo: list[StudyPoint] = list(points)
    while todo:
        pool = ProcessPoolExecutor(max_workers=min(workers, len(todo)),
                                   mp_context=multiprocessing.get_context("spawn"))
        futures = {pool.submit(point_row, p, measure): p for p in todo}
        todo = []
        try:
            pending = set(futures)
            while pending:
                done, pending = wait(pending, return_when=FIRST_COMPLETED)
                for fut in done:
                    p = futures[fut]
                    try:
                        yield fut.result()
                    except BrokenProcessPool:
                        attempts[p.key] = attempts.get(p.key, 0) + 1
                        if attempts[p.key] >= 2:
                            yield _lost_row(p, "worker process died (twice) running this "
                                               "point")
                        else:
                            todo.append(p)
                    except Exception as exc:  # e.g. unpicklable result
                        yield _lost_row(p, f"{type(exc).__name__}: {exc}")
        finally:
            pool.shutdown(wait=True, cancel_futures=True)


def _dask(points: Sequence[StudyPoint], measure: Measure, scheduler: Any
          ) -> Iterator[dict[str, Any]]:
    from distributed import Client, as_completed

    client = scheduler if isinstance(scheduler, Client) else Client(scheduler)
    try:
        futures = {client.submit(point_row, p, measure, pure=False): p for p in points}
        for fut in as_completed(futures):
            p = futures[fut]
            try:
                yield fut.result()
            except Exception as exc:  # worker lost, cancelled, ...
                yield _lost_row(p, f"{type(exc).__name__}: {exc}")
    finally:
        if client is not scheduler:
            client.close()


def _inline(points: Sequence[StudyPoint], measure: Measure) -> Iterator[dict[str, Any]]:
    global _STARTED
    _STARTED = True                 # this process is no worker: no worker start-up
    for p in points:
        yield point_row(p, measure)


def execute_points(points: Sequence[StudyPoint], table: ResultTable, measure: Measure, *,
                   workers: int | None = None, scheduler: Any = None,
                   progress: bool | None = None, retry_errors: bool = False, desc: str = "sweep",
                   meta: Mapping[str, Any] | None = None,
                   prepare: Callable[[list], list] | None = None) -> int:
    """Run the points not yet in ``table`` and append each row as it finishes.

    Holds the table folder's lock (:meth:`ResultTable.lock`) while running; the table is
    re-read and repaired under it first, so a killed study resumes where it stopped.

    Parameters
    ----------
    points : sequence of StudyPoint
    table : ResultTable
        Any :class:`ResultTable` (sub)class; the rows' derived columns are its own.
    measure : callable
        The points' measurement (module-level, picklable): ``measure(**point.kwargs())``.
    workers, scheduler, progress, retry_errors
        As for :func:`execute_sweep`.
    desc : str
        Progress bar label.
    meta : mapping, optional
        ``{file name: JSON-ready content}`` written into the table's folder once the lock
        is held (the study's description, e.g. ``sweep.json``).
    prepare : callable, optional
        Applied to the points still to run before they are dispatched (e.g.
        :func:`cosim.study.branch.branch_points`).

    Returns
    -------
    int
        Points run (the others were in the table already).
    """
    lock = table.lock()
    try:
        for name, content in (meta or {}).items():
            (table.folder / name).write_text(json.dumps(content, indent=2, default=str) + "\n")
        table.rows = table.load(repair=True)     # re-read and repaired under the lock
        done = table.keys(include_errors=not retry_errors)
        todo = [p for p in points if p.key not in done]
        if prepare is not None and todo:
            todo = prepare(todo)
        n_workers = (os.cpu_count() or 1) if workers is None else int(workers)
        if scheduler is not None:
            rows = _dask(todo, measure, scheduler)
        elif n_workers == 0 or not todo:
            rows = _inline(todo, measure)
        else:
            rows = _local(todo, measure, n_workers)
        bar = tqdm(total=len(points), initial=len(points) - len(todo), unit="point",
                   desc=desc, disable=None if progress is None else not progress)
        try:
            for row in rows:
                table.append(row)
                bar.update(1)
        finally:
            bar.close()
    finally:
        lock.close()
    return len(todo)


def _jsonable(value: Any) -> Any:
    if isinstance(value, Mapping):
        return {str(k): _jsonable(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_jsonable(v) for v in value]
    return value


def _build_fmus(points: Sequence[Point]) -> None:
    """Build (or find cached) the project FMUs the points run (default folder), once each, so
    workers do not all build them at the same time."""
    recipes = {}
    for p in points:
        config = p.config if p.config is not None else point_config(
            p.scene, p.gain, p.delay, p.step, p.stop_time, p.kind == "open_loop",
            json.loads(p.overrides) if p.overrides else None, p.gain_key)
        recipes.update({r.name: r for i, r in scene_recipes(config).items()
                        if i not in config.fmu_files})
    ensure_recipes(list(recipes.values()))


def check_points(points: Sequence[Point], engine: str) -> None:
    """Build every point's system (engine ``fmu``; ``inprocess``: the first point of each kind)
    as the measurement will, without running it: a problem the user must fix (FMUs that do not
    fit, an unknown or out-of-range parameter of a foreign FMU, a value a key cannot take)
    raises its :class:`UserError` here, before any point runs. The FMUs must be built
    (:func:`_build_fmus`): they are taken from the default folder as they are."""
    firsts: dict[str, Point] = {}
    for p in points:
        firsts.setdefault(p.kind, p)
    todo = points if engine == "fmu" else list(firsts.values())
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the run itself warns (InterfaceWarning), once
        for p in todo:
            if p.config is not None:
                built = build_system(p.config, engine, fmu_dir=default_fmu_dir())
                for slave in built.slaves.values():
                    slave.close()


def execute_sweep(spec: SweepSpec, out_dir: str | os.PathLike, *, workers: int | None = None,
                  scheduler: Any = None, progress: bool | None = None,
                  measure: Measure = measure_point, retry_errors: bool = False,
                  branch: bool = True) -> SweepOutcome:
    """Run (or resume) a sweep and record every point in ``out_dir``.

    Parameters
    ----------
    spec : SweepSpec
    out_dir : path-like
        Results folder (``results.csv``, ``results.parquet``, ``sweep.json``).
    workers : int, optional
        Local processes (default: all cores, ``os.cpu_count()``); ``0`` runs the
        points in this process.
    scheduler : str or distributed.Client, optional
        Submit to this dask.distributed cluster instead of a local pool.
    progress : bool or None
        Progress bar counting points (None: only on a TTY).
    measure : callable
        Point measurement (module-level, picklable), default :func:`measure_point`.
    retry_errors : bool
        Re-run points recorded as ``error``.
    branch : bool
        Closed-loop points identical up to the controller's switch-on continue from one
        checkpoint of that prefix per group, run here first (:mod:`.branch`; same numbers).

    Returns
    -------
    SweepOutcome
    """
    wall0 = time.perf_counter()
    points = spec.points()
    table = ResultTable(out_dir)
    meta = {"spec": {f.name: _jsonable(getattr(spec, f.name)) for f in fields(spec)
                     if f.name != "base"},
            "n_points": len(points), "gain_key": spec.gain_key,
            "vary": [key for key, _values in spec.vary]}
    if measure is measure_point:
        if spec.engine == "fmu":
            _build_fmus(points)  # once here, not by every worker at the same time
        check_points(points, spec.engine)  # a problem the user must fix: before any point
        if spec.base is not None:
            meta["components"] = describe_components(spec.base, spec.engine)
    n_run = execute_points(points, table, measure, workers=workers, scheduler=scheduler,
                           progress=progress, retry_errors=retry_errors,
                           meta={"sweep.json": meta},
                           prepare=branch_points if branch and measure is measure_point
                           else None)
    keys = {p.key for p in points}
    mine = [r for r in table.rows if r["key"] in keys]
    return SweepOutcome(Path(out_dir), len(points), len(points) - n_run, n_run,
                        time.perf_counter() - wall0, verdict_counts(mine), tuple(notes(mine)))


def sweep_spec(scene: str | Path, gains: Sequence[float] | None = None,
               delays: Sequence[float] | None = None, steps: Sequence[float] | None = None,
               stop_time: float | None = None, engine: str = "fmu",
               overrides: Mapping[str, Any] | None = None,
               options: Mapping[str, float] | None = None, gain_key: str | None = None,
               vary: Mapping[str, Sequence[Any]] | None = None, *,
               plant_fmu: str | Path | None = None,
               controller_fmu: str | Path | None = None) -> SweepSpec:
    """The sweep, planned once: the scene with ``overrides`` validated into its base
    configuration, and every point's configuration derived from it (each value validated
    once, here: a bad one is a :class:`UserError` before anything runs).

    Parameters
    ----------
    scene : str or path
    gains, delays, steps : sequences of float, optional
        Values of the gain key, of ``cosim.actuator_delay`` [s] and of ``cosim.step`` [s]
        (the shortcuts of ``vary``); default: no gain axis (the scene's gain), the scene's
        delay and step.
    stop_time : float, optional
        [s]; default the scene's.
    engine : {"fmu", "inprocess"}
    overrides : mapping, optional
        Scene keys by key path for every point.
    options : mapping, optional
        Point metric options (:class:`cosim.study.point.PointOptions`).
    gain_key : str, optional
        The key ``gains`` set; default :func:`cosim.study.point.default_gain_key`.
    vary : mapping of str -> sequence, optional
        Further axes by key path (any scene key: ``controller.parameters.kd``,
        ``cosim.controller_sample_period``, ...); the gain key, ``cosim.actuator_delay`` and
        ``cosim.step`` are the shortcuts' axes.
    plant_fmu, controller_fmu : path-like, optional
        FMU files (any maker) instead of the project's, as for :func:`drillcosim.simulate`.

    Raises
    ------
    UserError
        Bad values or combinations, before anything runs.
    """
    base = load_config(scene, overrides, plant_fmu=plant_fmu, controller_fmu=controller_fmu)
    if stop_time is None:
        stop_time = base.cosim.stop_time
    if gain_key is None:
        instances = base.instances
        gain_key = (f"{TOP_DRIVE}.p_gain" if TOP_DRIVE in instances and
                    CONTROLLER not in instances else DEFAULT_GAIN_KEY)
    check_gain_key(gain_key)
    axes: dict[str, list[Any]] = {}
    for key, values in (vary or {}).items():
        check_key_path(key, "--vary")
        if isinstance(values, (str, bytes)) or not hasattr(values, "__iter__"):
            raise UserError(f"--vary {key}: a list of values, got {values!r}")
        axes[key] = list(dict.fromkeys(values))
        if not axes[key]:
            raise UserError(f"--vary {key}: at least one value")
    shortcuts = {gain_key: gains, "cosim.actuator_delay": delays, "cosim.step": steps}
    for key, given in shortcuts.items():
        if key in axes and given is not None:
            raise UserError(f"{key} is given twice (--vary and its shortcut)")
    values = {key: axes.pop(key, None if given is None else list(given))
              for key, given in shortcuts.items()}
    for key, given in values.items():
        if given is not None and not given:
            raise UserError(f"{key}: at least one value")
    spec = SweepSpec(
        str(scene), sorted(set(values[gain_key] or ())),
        sorted(set(values["cosim.actuator_delay"] or [base.cosim.actuator_delay])),
        sorted(set(values["cosim.step"] or [base.cosim.step])), float(stop_time), engine,
        dict(base.overrides), True, dict(options or {}), gain_key,
        tuple((k, tuple(v)) for k, v in axes.items()), base)
    spec = replace(spec, open_loop=spec.table == CONTROLLER)
    try:
        spec.points()  # every point's configuration, validated here
    except ConfigError as exc:
        raise UserError(f"sweep point: {exc}") from None
    return spec


def describe_components(config: SceneConfig, engine: str) -> dict[str, Any]:
    """What runs a configuration, per instance: the FMU file, its GUID, model name and
    generation tool, the drillcosim version that runs it and the parameters the system sets
    (engine ``fmu``; ``inprocess``: the law or plant and its parameters)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        built = build_system(config, engine, fmu_dir=default_fmu_dir())
    out = built.components()
    for slave in built.slaves.values():
        slave.close()
    return out


def judging_note(spec: SweepSpec) -> str:
    """One line when ``spec.stop_time`` is below the scene's judging window, else ``""``.

    See :func:`cosim.study.verdict.scene_judging_window`; closed-loop points of such a sweep
    that do not diverge are ``undecided``.
    """
    if spec.table != CONTROLLER:
        what = spec.gain_key if spec.gains else f"the {spec.table}"
        return (f"the verdicts judge the strain loop's growth; a sweep of {what} is "
                "read from its stick_slip_severity / stick_fraction columns (--maps: "
                "stick_slip_map.png); its points are 'undecided'")
    opts = PointOptions.from_kwargs(dict(spec.options))
    try:
        window = scene_judging_window(spec.scene, spec.overrides, opts.highpass,
                                      opts.fit_fraction)
    except (ValueError, LinAlgError) as exc:
        return f"no judging window for {spec.scene} ({exc}); growth verdicts are unchecked"
    if spec.stop_time >= window.min_stop_time:
        return ""
    return (f"stop time {spec.stop_time:g} s is below the {window.min_stop_time:.3g} s needed "
            f"to judge growth in {spec.scene} ({window.describe()}): closed-loop points that do "
            "not diverge will be 'undecided'")
