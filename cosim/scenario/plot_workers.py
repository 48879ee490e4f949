"""The figures of a run drawn by worker processes, while it steps and in parallel.

:class:`PlotWorkers` starts its processes (``python -m drillcosim.cosim.scenario.plot_workers``)
when the run starts: each imports matplotlib while the master steps. :meth:`PlotWorkers.feed`
gives the run an observer (:class:`PlotFeed`) that copies the recorded rows, every 1/20 of the
run, into a file both sides map, and tells the workers how many there are. Each worker builds
its share of the figures (:data:`GROUPS`); once the rows reach :data:`LATE` of the run it
updates them with the rows so far, the time axis already the whole run's
(:meth:`.plots.RunFigure.update`), and draws the layer below their lines (axes, ticks, labels:
most of the cost) whenever their limits changed (:meth:`.plots.RunFigure.prepare`). When the
run stops, the feed hands over the last rows and the workers draw the final pictures (limits
reached: only the lines and above; else the whole figure) and encode them while this process
writes the rest of its results; :meth:`PlotWorkers.plot_run` then has them write their PNGs,
the same files :func:`.plots.plot_run` writes (rows other than those fed are fed first). A
worker that cannot do its share (it died, matplotlib is missing, it raised) leaves it to this
process, which draws it with :func:`.plots.plot_run` (and raises what that raises). With one
core, no workers: this process draws everything.

Protocol: pickled dicts on the worker's stdin, read by a thread as they come, in order:
``{"settings": <plot_run's keyword arguments>, "figures": <names>}``; ``{"rows": <file>,
"dtype": <descr>}`` (the structured rows, ``n`` of them valid); ``{"n": <rows>, "t_end": <s or
None>}`` (``t_end``: the time axis runs to it; None: these are all the rows); ``{"save":
<folder>}``. The worker answers the pickled list of the paths it wrote on stdout and exits 0.
"""

from __future__ import annotations

import os
import pickle
import subprocess
import sys
import tempfile
import threading
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["FIGURES", "GROUPS", "PlotFeed", "PlotWorkers"]

#: The figures of a run in :func:`.plots.plot_run`'s order (file names without ``.png``).
FIGURES = ("orbit", "deflection_contact", "actuators", "axial_torsional")
#: The figures each worker draws (about equal drawing times at the end of a run).
GROUPS = (("deflection_contact", "axial_torsional"), ("actuators", "orbit"))
#: Thread-count variables of the BLAS libraries numpy may load, set to 1 for the workers
#: (unless the user set them).
_ONE_THREAD = ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")
#: Longest wait for a worker's figures [s] (then this process draws them).
TIMEOUT = 600.0
#: Row updates the feed sends over a run.
UPDATES = 20
#: The workers draw the layer below the lines (:meth:`.plots.RunFigure.prepare`) once the rows
#: reach this fraction of the run (the limits are then mostly the final ones).
LATE = 0.7


class PlotWorkers:
    """Worker processes for the figures of one run; :meth:`close` them (a context manager).

    Parameters
    ----------
    workers : int, optional
        Processes (default: one per figure group, at most the number of cores; 0 with one core).
    """

    def __init__(self, workers: int | None = None):
        n = min(len(GROUPS), os.cpu_count() or 1) if workers is None else int(workers)
        if n < 2:
            n = 0
        self.procs: list[subprocess.Popen] = []
        # one BLAS thread: the figures need none, and OpenBLAS's thread pool costs each worker
        # ~0.1 s of CPU at numpy's import (CPU the run loses on 2 cores; docs/performance.md)
        env = {**os.environ, **{k: os.environ.get(k, "1") for k in _ONE_THREAD}}
        for _ in range(n):
            try:
                self.procs.append(subprocess.Popen(
                    [sys.executable, "-m", __name__], stdin=subprocess.PIPE,
                    stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, env=env))
            except OSError:
                break
        self.groups = GROUPS if len(self.procs) == len(GROUPS) else ()
        self._alive = [True] * len(self.groups)
        self._settings: dict[str, Any] | None = None
        self._rows: np.memmap | None = None      # the rows file, mapped
        self._fed = 0                             # its valid rows
        self._files: list[str] = []

    # -- messages ----------------------------------------------------------------
    def _send(self, message: Mapping[str, Any], per_worker: Mapping[int, Any] | None = None
              ) -> None:
        for k, proc in enumerate(self.procs[:len(self.groups)]):
            if not self._alive[k]:
                continue
            msg = {**message, **(per_worker[k] if per_worker else {})}
            try:
                proc.stdin.write(pickle.dumps(msg, pickle.HIGHEST_PROTOCOL))
                proc.stdin.flush()
            except (OSError, ValueError):       # the worker is gone
                self._alive[k] = False

    def _begin(self, settings: Mapping[str, Any]) -> None:
        self._settings = dict(settings)
        self._send({"settings": self._settings},
                   {k: {"figures": g} for k, g in enumerate(self.groups)})

    def _new_rows_file(self, dtype: np.dtype, capacity: int) -> None:
        fd, name = tempfile.mkstemp(prefix="drillcosim_rows_", suffix=".bin")
        os.close(fd)
        self._files.append(name)
        self._rows = np.memmap(name, dtype=dtype, mode="w+", shape=(max(capacity, 1),))
        self._fed = 0
        self._send({"rows": name, "dtype": dtype.descr})

    def _feed(self, rows: np.ndarray, t_end: float | None) -> None:
        """Append ``rows`` to the rows file (if they fit) and tell the workers."""
        n = self._fed + len(rows)
        if self._rows is None or n > len(self._rows):
            return
        self._rows[self._fed:n] = rows
        self._fed = n
        self._send({"n": n, "t_end": t_end})

    def feed(self, settings: Mapping[str, Any], stop_time: float) -> PlotFeed | None:
        """An observer for the run (:class:`PlotFeed`) that streams its recorded rows to the
        workers, which draw the figures of :func:`.plots.plot_run` with ``settings`` (its
        keyword arguments) as the rows come; None without workers."""
        if not self.groups:
            return None
        self._begin(settings)
        return PlotFeed(self, stop_time)

    def plot_run(self, data: np.ndarray, out_dir: str | Path, clearance: float,
                 spans: Mapping[int, Mapping] | None = None, n_sites: int = 2, title: str = "",
                 switch_on_time: float | None = None, baseline: str | None = None,
                 revolution: float | None = None) -> list[Path]:
        """:func:`.plots.plot_run`, its figures drawn by the workers (see the module
        docstring); the paths in that function's order."""
        settings = {"clearance": clearance, "spans": dict(spans) if spans else None,
                    "n_sites": n_sites, "title": title, "switch_on_time": switch_on_time,
                    "baseline": baseline, "revolution": revolution}
        sent = []
        if self.groups:
            if self._settings != settings:
                self._begin(settings)
                self._rows = None
            fed = self._rows is not None and self._rows.dtype == data.dtype and \
                self._fed == len(data) and \
                np.array_equal(self._rows[:len(data)].view(np.uint8), data.view(np.uint8))
            if not fed:
                self._new_rows_file(data.dtype, len(data))
                self._feed(data, None)
            self._send({"save": str(out_dir)})
            sent = [(proc, group) for proc, group, alive
                    in zip(self.procs, self.groups, self._alive) if alive]
        done: list[Path] = []
        left = list(FIGURES)
        for proc, group in sent:
            paths = self._answer(proc)
            if paths is not None:
                done += paths
                left = [name for name in left if name not in group]
        if left:
            from .plots import plot_run

            done += plot_run(data, out_dir, **settings, figures=left)
        order = {f"{name}.png": k for k, name in enumerate(FIGURES)}
        return sorted(done, key=lambda p: order.get(p.name, len(order)))

    @staticmethod
    def _answer(proc: subprocess.Popen) -> list[Path] | None:
        try:
            out, _ = proc.communicate(timeout=TIMEOUT)
            if proc.returncode != 0:
                return None
            return [Path(p) for p in pickle.loads(out)]
        except (subprocess.TimeoutExpired, pickle.UnpicklingError, EOFError, ValueError,
                TypeError):
            proc.kill()
            return None

    def close(self) -> None:
        """Stop the workers still running (a run that ended without figures), reap them and
        remove the rows files."""
        for proc in self.procs:
            if proc.poll() is None:
                proc.kill()
            proc.wait()
            for stream in (proc.stdin, proc.stdout):
                if stream is not None and not stream.closed:
                    try:
                        stream.close()
                    except OSError:      # unwritten job bytes of a worker that is gone
                        pass
        self.procs, self.groups, self._rows = [], (), None
        for name in self._files:
            try:
                os.unlink(name)
            except OSError:
                pass
        self._files = []

    def __enter__(self) -> PlotWorkers:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


class PlotFeed:
    """Observer of a run (``on_start``, ``on_step`` every :attr:`stride_ticks`, ``on_stop``)
    that streams the rows of its :class:`~cosim.master.recorder.Recorder` to the workers
    (:meth:`PlotWorkers.feed`); it only reads."""

    def __init__(self, workers: PlotWorkers, stop_time: float):
        self.workers = workers
        self.stop_time = float(stop_time)
        self.recorder = None

    def on_start(self, execution) -> None:
        """Find the run's recorder, size the rows file for the whole run."""
        from drillcosim.cosim.master.recorder import Recorder

        self.recorder = next((o for o in execution.observers if isinstance(o, Recorder)), None)
        span_ticks = max(1, round((self.stop_time - execution.time) / execution.base_step))
        #: the rows are sent at ticks that are multiples of this (~:data:`UPDATES` times)
        self.stride_ticks = max(1, span_ticks // UPDATES)
        if self.recorder is not None:
            capacity = span_ticks // self.recorder.interval_ticks + 2
            self.workers._new_rows_file(self.recorder.dtype, capacity)

    def _send(self, t_end: float | None) -> None:
        if self.recorder is not None:
            self.workers._feed(self.recorder.rows_since(self.workers._fed), t_end)

    def on_step(self, execution) -> None:
        """The rows so far, the time axis to the stop time."""
        if execution.tick % self.stride_ticks == 0:
            self._send(self.stop_time)

    def on_stop(self, execution) -> None:
        """All the rows: the workers draw the final figures."""
        self._send(None)


def _reader(state: dict[str, Any], ready: threading.Condition) -> None:
    """Read the messages from stdin into ``state`` (the newest wins; ``"gen"`` counts them)."""
    stream = sys.stdin.buffer
    while True:
        try:
            msg = pickle.load(stream)
        except (EOFError, OSError, pickle.UnpicklingError):
            msg = {"eof": True}
        with ready:
            state.update(msg)
            state["gen"] += 1
            ready.notify()
        if "eof" in msg:
            return


def main() -> int:
    """Worker: read the messages as they come (a thread), import the plotting code, draw the
    figures whenever new rows are there, write them when asked; answer the paths."""
    if hasattr(os, "nice"):
        # below the run: on 2 cores the workers' imports and early draws otherwise take CPU
        # from the master (main job with plots, 30 s, quiet machine: 2.67-2.89 s at nice 10
        # vs 3.00-3.29 s at 0, 2.42-2.61 s without plots; docs/performance.md)
        os.nice(10)
    state: dict[str, Any] = {"gen": 0, "n": 0, "t_end": None}
    ready = threading.Condition()
    threading.Thread(target=_reader, args=(state, ready), daemon=True).start()
    from .plots import run_figures

    figures, rows, drawn, pngs = None, None, -1, None
    while True:
        with ready:
            while state["gen"] == drawn:
                ready.wait()
            snap = dict(state)
        if snap.get("save") is not None and pngs is not None and pngs[0] == snap["rows"]:
            break                                  # the final pictures are drawn
        if "eof" in snap and snap.get("save") is None:
            return 1                               # no figures wanted (the run failed)
        drawn = snap["gen"]
        if snap.get("rows") is None or snap["n"] < 2 or "settings" not in snap:
            continue
        if rows is None or rows.filename != os.path.abspath(snap["rows"]):
            rows = np.memmap(snap["rows"], dtype=np.dtype(snap["dtype"]), mode="r")
        data = np.array(rows[:snap["n"]])
        key = (snap["settings"], snap["rows"])
        if figures is None or figures[0][0] is not key[0] or figures[0][1] != key[1]:
            figures = (key, run_figures(data, **snap["settings"], figures=snap["figures"]))
        final = snap["t_end"] is None
        t = data["time"]
        if not final and t[-1] < t[0] + LATE * (snap["t_end"] - t[0]):
            continue                               # the limits are not near the final ones
        made = {}
        for name, fig in figures[1].items():
            fig.update(data, snap["t_end"])
            if final:
                made[name] = fig.png()
                continue
            fig.prepare()
            with ready:
                if state["gen"] != drawn:
                    break                          # newer rows: draw those
        if final:
            pngs = (snap["rows"], made)
            if snap.get("save") is not None:
                drawn = -1                         # save them now
    out = Path(snap["save"])
    paths = [figures[1][name].save(out / f"{name}.png", png) for name, png in pngs[1].items()]
    sys.stdout.buffer.write(pickle.dumps([str(p) for p in paths]))
    sys.stdout.buffer.flush()
    os._exit(0)          # the files are written: no interpreter teardown


if __name__ == "__main__":
    sys.exit(main())
