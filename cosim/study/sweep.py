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
from collections.abc import Callable, Iterator, Mapping, Sequence
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any, Protocol

from numpy.linalg import LinAlgError
from tqdm import tqdm

from drillcosim.cosim.master.errors import UserError
from drillcosim.cosim.scenario.build import scene_recipes
from drillcosim.cosim.scenario.config import key_paths, load_config
from drillcosim.cosim.scenario.scene_fmus import ensure_recipes

from .grid import DEFAULT_GAIN_KEY, Point, SweepSpec
from .point import PointOptions, default_gain_key, error_row, measure_point, point_config
from .table import ResultTable, notes, verdict_counts
from .verdict import scene_judging_window

__all__ = ["StudyPoint", "SweepOutcome", "SweepSpec", "execute_points", "execute_sweep",
           "judging_note", "point_row", "sweep_spec"]

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
                   meta: Mapping[str, Any] | None = None) -> int:
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


def _build_fmus(points: Sequence[Point]) -> None:
    """Build (or find cached) the project FMUs the points run (default folder), one point of
    each kind, so workers do not all build them at the same time."""
    recipes = {}
    for p in {p.kind: p for p in points}.values():
        kw = p.kwargs()
        config = point_config(p.scene, p.gain, p.delay, p.step, p.stop_time, kw["open_loop"],
                              kw["overrides"], p.gain_key)
        recipes.update({r.name: r for i, r in scene_recipes(config).items()
                        if i not in config.fmu_files})
    ensure_recipes(list(recipes.values()))


def execute_sweep(spec: SweepSpec, out_dir: str | os.PathLike, *, workers: int | None = None,
                  scheduler: Any = None, progress: bool | None = None,
                  measure: Measure = measure_point, retry_errors: bool = False) -> SweepOutcome:
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

    Returns
    -------
    SweepOutcome
    """
    wall0 = time.perf_counter()
    points = spec.points()
    table = ResultTable(out_dir)
    meta = {"spec": {k: (list(v) if isinstance(v, (list, tuple)) else v)
                     for k, v in asdict(spec).items()}, "n_points": len(points)}
    if spec.engine == "fmu" and scheduler is None and measure is measure_point:
        _build_fmus(points)  # once here, not by every worker at the same time
    n_run = execute_points(points, table, measure, workers=workers, scheduler=scheduler,
                           progress=progress, retry_errors=retry_errors,
                           meta={"sweep.json": meta})
    keys = {p.key for p in points}
    mine = [r for r in table.rows if r["key"] in keys]
    return SweepOutcome(Path(out_dir), len(points), len(points) - n_run, n_run,
                        time.perf_counter() - wall0, verdict_counts(mine), tuple(notes(mine)))


def sweep_spec(scene: str, gains: Sequence[float], delays: Sequence[float],
               steps: Sequence[float], stop_time: float | None, engine: str = "fmu",
               overrides: Mapping[str, Any] | None = None,
               options: Mapping[str, float] | None = None,
               gain_key: str | None = None) -> SweepSpec:
    """A checked :class:`SweepSpec`: the stop time defaults to the scene's, the gain key to
    :func:`cosim.study.point.default_gain_key`. A sweep of the strain gain runs the open-loop
    references (the control benefit); a sweep of another controller's gain has none (a
    top-drive controller in torque mode is the drive: without it the string is not driven).

    Raises
    ------
    UserError
        Bad values or combinations (e.g. a stop time some step does not divide), before
        anything runs.
    """
    over = key_paths(overrides)
    if stop_time is None:
        stop_time = load_config(scene, over).cosim.stop_time
    key = default_gain_key(scene, over) if gain_key is None else gain_key
    values = {}
    for what, seq, low in (("gains", gains, 0.0), ("delays", delays, 0.0), ("steps", steps, None)):
        vals = [float(v) for v in seq]
        if not vals or any(not math.isfinite(v) or (v < low if low is not None else v <= 0)
                           for v in vals):
            raise UserError(f"{what} = {list(seq)!r}: at least one finite value, each "
                            f"{'>= 0' if low is not None else '> 0'}")
        values[what] = sorted(set(vals))
    spec = SweepSpec(scene, values["gains"], values["delays"], values["steps"], float(stop_time),
                     engine, over, key == DEFAULT_GAIN_KEY, dict(options or {}), key)
    spec.points()                   # bad combinations fail here, before anything runs
    return spec


def judging_note(spec: SweepSpec) -> str:
    """One line when ``spec.stop_time`` is below the scene's judging window, else ``""``.

    See :func:`cosim.study.verdict.scene_judging_window`; closed-loop points of such a sweep
    that do not diverge are ``undecided``.
    """
    if spec.gain_key != DEFAULT_GAIN_KEY:
        return (f"the verdicts judge the strain loop's growth; a sweep of {spec.gain_key} is "
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
