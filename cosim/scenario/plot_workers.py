"""The figures of a run drawn by worker processes, in parallel, ready before the run ends.

:class:`PlotWorkers` starts its processes (``python -m drillcosim.cosim.scenario.plot_workers``)
when the run starts: each imports matplotlib while the master steps, then waits for its job on
stdin. After the run, :meth:`PlotWorkers.plot_run` hands each worker the recorded rows and its
share of the figures (:data:`GROUPS`), and they draw them at the same time, one figure group per
core, the same files :func:`.plots.plot_run` writes. A worker that cannot do its share (it
died, matplotlib is missing, it raised) leaves it to this process, which draws it with
:func:`.plots.plot_run` (and raises what that raises). With one core, no workers: this process
draws everything.

Protocol: the job is one pickled dict (the keyword arguments of :func:`.plots.plot_run`) on the
worker's stdin; the worker answers with the pickled list of the paths it wrote on stdout and
exits 0.
"""

from __future__ import annotations

import os
import pickle
import subprocess
import sys
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["FIGURES", "GROUPS", "PlotWorkers"]

#: The figures of a run in :func:`.plots.plot_run`'s order (file names without ``.png``).
FIGURES = ("orbit", "orbit_steady", "deflection_contact", "actuators", "axial_torsional")
#: The figures each worker draws (about equal drawing times).
GROUPS = (("deflection_contact", "orbit_steady", "axial_torsional"), ("actuators", "orbit"))
#: Longest wait for a worker's figures [s] (then this process draws them).
TIMEOUT = 600.0


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
        for _ in range(n):
            try:
                self.procs.append(subprocess.Popen(
                    [sys.executable, "-m", __name__], stdin=subprocess.PIPE,
                    stdout=subprocess.PIPE, stderr=subprocess.DEVNULL))
            except OSError:
                break

    def plot_run(self, data: np.ndarray, out_dir: str | Path, clearance: float,
                 spans: Mapping[int, Mapping] | None = None, n_sites: int = 2, title: str = "",
                 switch_on_time: float | None = None) -> list[Path]:
        """:func:`.plots.plot_run`, its figures drawn by the workers (see the module
        docstring); the paths in that function's order."""
        job: dict[str, Any] = {"data": data, "out_dir": str(out_dir), "clearance": clearance,
                               "spans": dict(spans) if spans else None, "n_sites": n_sites,
                               "title": title, "switch_on_time": switch_on_time}
        groups = GROUPS if len(self.procs) == len(GROUPS) else ()
        sent = []
        for proc, group in zip(self.procs, groups):
            try:
                pickle.dump({**job, "figures": group}, proc.stdin, pickle.HIGHEST_PROTOCOL)
                proc.stdin.flush()          # the whole job is there; communicate() closes it
                sent.append((proc, group))
            except OSError:      # the worker is gone
                pass
        done: list[Path] = []
        left = list(FIGURES)
        for proc, group in sent:
            paths = self._answer(proc)
            if paths is not None:
                done += paths
                left = [name for name in left if name not in group]
        if left:
            from .plots import plot_run

            done += plot_run(**job, figures=left)
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
        """Stop the workers still running (a run that ended without figures) and reap them."""
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
        self.procs = []

    def __enter__(self) -> PlotWorkers:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def main() -> int:
    """Worker: import the plotting code, read one job, draw it, answer the paths."""
    from .plots import plot_run

    job = pickle.load(sys.stdin.buffer)
    paths = plot_run(**job)
    pickle.dump([str(p) for p in paths], sys.stdout.buffer)
    sys.stdout.buffer.flush()
    return 0


if __name__ == "__main__":
    sys.exit(main())
