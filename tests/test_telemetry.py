"""Telemetry: where a run's stepping loop spends its time (per component: steps, mean and
longest step, exchange calls; the master's own share; the real-time factor), in both loops of
the master, in summary.json and in ``drillcosim run --profile``; a sweep's point times split
into start-up and stepping."""

from __future__ import annotations

import ctypes
import json
import math
import time

import numpy as np
import pytest

from drillcosim.cosim.master.master import Master
from drillcosim.cosim.master.native.runner import LOOP_ENV, NativeLoop
from drillcosim.cosim.master.slave import CompiledCalls, Slave
from drillcosim.cosim.master.system import Connection, FmuSpec, SystemSpec

SLEEP = 2e-3     # s: what the sleepy component's step costs at least
_STEP = ctypes.CFUNCTYPE(ctypes.c_int, ctypes.c_void_p, ctypes.c_double, ctypes.c_double)


class Sleepy(Slave):
    """x' = u in process; every step sleeps :data:`SLEEP` (in Python, or in a C-callable step
    for the native loop: a ctypes callback)."""

    def __init__(self, name: str, compiled: bool):
        self.name, self.compiled = name, compiled
        self.ctx = np.zeros(2)                  # [u, x]
        self._step = _STEP(self._c_step)

    def _c_step(self, context, t, h) -> int:
        return self.do_step(t, h)

    def check_variable(self, name, causalities):
        if name not in ("u", "x"):
            raise ValueError(f"no variable {name!r}")

    def instantiate(self, start_time, stop_time):
        pass

    def bind(self, outputs, y, offset, inputs, u):
        self.outs, self.ins = [1 for _ in outputs], [0 for _ in inputs]
        self.y, self.offset, self.u = y, offset, u

    def write_inputs(self):
        for i, slot in enumerate(self.ins):
            self.ctx[slot] = self.u[i]
        return 0

    def do_step(self, t, h):
        time.sleep(SLEEP)
        self.ctx[1] += self.ctx[0] * h
        return 0

    def read_outputs(self):
        for i, slot in enumerate(self.outs):
            self.y[self.offset + i] = self.ctx[slot]
        return 0

    def native_calls(self):
        if not self.compiled:
            return None
        data = self.ctx.ctypes.data
        return CompiledCalls(ctypes.cast(self._step, ctypes.c_void_p).value, data, data,
                             tuple(self.ins), data, tuple(self.outs))

    def get_real(self, name, time):
        return float(self.ctx[1])

    def set_value(self, name, value, time):
        self.ctx[1] = value

    def close(self):
        pass


@pytest.mark.parametrize("loop", ["python", "native"])
def test_component_times_add_up_to_what_the_components_spent(fmus, monkeypatch, loop):
    """A sleepy component stepping every 2nd tick next to a fast FMU: its steps are counted
    (ticks / period), each takes at least the sleep; the components' and the master's shares
    add up to the loop's wall time; the native loop's numbers come from its C clock."""
    chunks = []
    real = NativeLoop.run

    def spy(self, *args):
        chunks.append(1)
        return real(self, *args)

    monkeypatch.setattr(NativeLoop, "run", spy)
    monkeypatch.setenv(LOOP_ENV, "python" if loop == "python" else "auto")
    h, n = 0.01, 40
    system = SystemSpec([FmuSpec("fast", fmus["mt_gain"], {"k": 0.5}),
                         FmuSpec("slow", fmus["mt_integrator"], {}, 2)],
                        [Connection("slow.x", "fast.u"), Connection("fast.y", "slow.u")], h,
                        "gauss_seidel", ("fast", "slow"))
    res = Master(system, {"slow": Sleepy("slow", loop == "native")}).simulate(
        n * h, outputs=["slow.x"])
    assert bool(chunks) == (loop == "native")
    p = res.profile()
    slow, fast = p["components"]["slow"], p["components"]["fast"]
    assert (slow["steps"], fast["steps"]) == (n // 2, n)
    assert SLEEP <= slow["step_mean_s"] <= slow["step_max_s"] < 1.0
    assert slow["step_mean_s"] * slow["steps"] <= slow["total_s"] <= res.wall_time
    assert 0 < fast["step_mean_s"] <= fast["step_max_s"]
    assert slow["share"] >= n // 2 * SLEEP / res.wall_time - 1e-12
    shares = sum(c["share"] for c in p["components"].values()) + p["master_share"]
    assert shares == pytest.approx(1.0, abs=1e-12) and 0 <= p["master_share"] < 1
    assert p["real_time_factor"] == pytest.approx(n * h / res.wall_time)


def test_summary_and_profile_of_a_scene_run(tmp_path, capsys) -> None:
    """``drillcosim run --profile``: the table names each component, and summary.json holds the
    same numbers; every component stepped once per step of the run."""
    from drillcosim.cosim.cli import main

    out = tmp_path / "run"
    assert main(["run", "paper_closed_loop", "--stop-time", "0.1", "--engine", "inprocess",
                 "--no-plots", "--no-progress", "--profile", "--out", str(out)]) == 0
    table = capsys.readouterr().out
    summary = json.loads((out / "summary.json").read_text())
    tel = summary["telemetry"]
    assert set(tel["components"]) == {"plant", "controller"}
    for name, c in tel["components"].items():
        assert c["steps"] == round(0.1 / summary["step_s"]), name
        line = next(row for row in table.splitlines() if row.startswith(name))
        assert f"{1e6 * c['step_mean_s']:.2f}" in line.split(), line
    assert "master" in table and f"{tel['real_time_factor']:.3g}" in table
    assert tel["real_time_factor"] == pytest.approx(summary["real_time_factor"])


def test_sweep_points_split_their_wall_time(tmp_path) -> None:
    """A sweep row's wall time holds its start-up (build, instantiate, initialize) and its
    stepping (the master's loop); a pool worker's first point records the worker's start-up."""
    from drillcosim.cosim.study.sweep import SweepSpec, execute_sweep
    from drillcosim.cosim.study.table import read_table

    spec = SweepSpec("paper_closed_loop", [1e8], [0.0, 1e-4], [1e-3], 0.2, "inprocess",
                     {"cosim": {"output_interval": 1e-3}})
    execute_sweep(spec, tmp_path, workers=1, progress=False)
    rows = read_table(tmp_path)
    assert len(rows) == 3
    for r in rows:
        assert r["status"] == "ok"
        assert 0 < r["startup_time"] and 0 < r["stepping_time"]
        assert r["startup_time"] + r["stepping_time"] <= r["wall_time"]
    first = [r for r in rows if math.isfinite(r["worker_startup"])]
    assert len(first) == 1 and 0 < first[0]["worker_startup"] < 120
