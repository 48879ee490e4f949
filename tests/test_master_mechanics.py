"""Master mechanics: exact time, split runs, state save/restore, errors, multirate,
result files and system validation."""

from __future__ import annotations

import csv
from collections import deque

import numpy as np
import pytest

from drillcosim.cosim.master.errors import CosimError, DivergenceError
from drillcosim.cosim.master.execution import Execution
from drillcosim.cosim.master.master import Master
from drillcosim.cosim.master.recorder import Recorder
from drillcosim.cosim.master.system import Connection, FmuSpec, SystemSpec, system_from_dict


class Trace:
    """Observer keeping (time, values) of some outputs after every step."""

    def __init__(self, refs):
        self.refs, self.rows = refs, []

    def on_step(self, ex):
        self.rows.append((ex.time, *(ex.get_real(r) for r in self.refs)))


def oscillator(fmus, algorithm="jacobi", delay=0.0):
    """Two-mass oscillator, linear coupling and a fractional delay: non-trivial floats."""
    return SystemSpec(
        [FmuSpec("a", fmus["mt_mass"], {"m": 1.0, "kc": 2.0, "x0": 1.0, "h_max": 2e-3}),
         FmuSpec("b", fmus["mt_mass"], {"m": 2.0, "k": 0.5, "kc": 2.0})],
        [Connection("a.x", "b.x_other", coupling="linear", delay=delay),
         Connection("b.x", "a.x_other", coupling="linear")],
        0.01, algorithm)


@pytest.mark.parametrize("algorithm", ["jacobi", "gauss_seidel"])
def test_split_run_equals_continuous_run_bit_for_bit(fmus, algorithm):
    refs = ["a.x", "a.v", "b.x"]
    runs = []
    for stops in ([2.0], [0.73, 2.0], [1.0, 1.0, 1.5, 2.0]):
        with Execution(oscillator(fmus, algorithm, delay=0.037), read_outputs=refs) as ex:
            trace = Trace(refs)
            ex.add_observer(trace)
            for stop in stops:
                ex.simulate_until(stop)
            runs.append(np.array(trace.rows))
    assert runs[0].shape == (200, 4)
    assert np.array_equal(runs[0], runs[1]) and np.array_equal(runs[0], runs[2])


def test_30000_steps_of_1ms_end_at_exactly_30s(fmus):
    system = SystemSpec([FmuSpec("i", fmus["mt_integrator"], {"u": 1.0})], base_step=1e-3)
    with Execution(system, read_outputs=["i.n_steps"]) as ex:
        rec = Recorder(["i.n_steps"], interval_ticks=1000)
        ex.add_observer(rec)
        ex.simulate_until(30.0)
        assert ex.tick == 30000
        assert ex.time == 30.0
        assert ex.get_real("i.n_steps") == 30000
        # every communication point is the float nearest to k * 1 ms
        assert np.array_equal(rec.data["time"], np.arange(31) * 1.0)
        assert ex.time_of(3) == 0.003 and ex.time_of(29999) == 29.999
    with pytest.raises(ValueError, match="multiple of base_step"):
        Execution(system).ticks_until(1.0005)


def test_state_restore_reproduces_run_including_delay_buffers(fmus):
    refs = ["a.x", "b.x", "b.v"]
    with Execution(oscillator(fmus, "jacobi", delay=0.123), read_outputs=refs) as ex:
        ex.simulate_until(0.5)
        state = ex.get_state()
        trace = Trace(refs)
        ex.add_observer(trace)
        ex.simulate_until(1.5)
        first = np.array(trace.rows)
        trace.rows.clear()
        ex.set_state(state)
        assert ex.time == 0.5
        ex.simulate_until(1.5)
        second = np.array(trace.rows)
        # restore twice from the same state (state is not consumed)
        trace.rows.clear()
        ex.set_state(state)
        ex.simulate_until(1.5)
        third = np.array(trace.rows)
    assert first.shape == (100, 4)
    assert np.array_equal(first, second) and np.array_equal(first, third)


def test_state_without_delay_buffers_would_differ(fmus):
    """Guard: the delay line really matters, so the test above checks the buffers."""
    with Execution(oscillator(fmus, "jacobi", delay=0.123), read_outputs=["b.x"]) as ex:
        ex.simulate_until(0.5)
        state = ex.get_state()
        ex.simulate_until(1.0)
        reference = ex.get_real("b.x")
        ex.set_state(state)
        for line in ex.algorithm.lines:
            line.reset(0.0)
        ex.simulate_until(1.0)
        assert ex.get_real("b.x") != reference


# --- errors -------------------------------------------------------------------------
def plant_loop(fmus, plant_params, h=0.01):
    return SystemSpec(
        [FmuSpec("plant", fmus["mt_integrator"], {"x0": 1.0, **plant_params}),
         FmuSpec("ctrl", fmus["mt_gain"], {"k": 1.0})],
        [Connection("plant.x", "ctrl.u"), Connection("ctrl.y", "plant.u")], h)


def test_discard_names_fmu_call_time_and_keeps_data(fmus, tmp_path):
    out = tmp_path / "run.csv"
    with pytest.raises(CosimError) as info:
        Master(plant_loop(fmus, {"fail_at_time": 0.5})).simulate(
            1.0, outputs=["plant.x"], csv_path=out, flush_every=7)
    err = info.value
    assert (err.fmu_name, err.call, err.status) == ("plant", "fmi2DoStep", 2)
    assert err.time == 0.5
    assert "plant" in str(err) and "fmi2DoStep" in str(err) and "t = 0.5 s" in str(err)
    data = err.result.data
    assert data["time"][-1] == 0.5 and len(data) == 51
    x = [1.0, 0.99]  # Jacobi, K H = 0.01: x_{k+1} = x_k - 0.01 x_{k-1}
    while len(x) < 51:
        x.append(x[-1] - 0.01 * x[-2])
    np.testing.assert_allclose(data["plant.x"], x, rtol=1e-12)
    rows = list(csv.reader(out.open()))
    assert rows[0] == ["time", "plant.x"] and len(rows) == 52
    assert float(rows[-1][0]) == 0.5 and float(rows[-1][1]) == data["plant.x"][-1]


def test_exception_in_fmu_is_reported_as_error(fmus, capfd):
    """The FMU's own message (a Python exception in its doStep, logged through the FMI logger
    callback) ends the error, on one line; nothing is printed."""
    with pytest.raises(CosimError) as info:
        Master(plant_loop(fmus, {"fail_at_time": 0.2, "fail_mode": 1})).simulate(
            1.0, outputs=["plant.x"])
    assert info.value.call == "fmi2DoStep" and info.value.status in (3, 4)
    assert info.value.time == pytest.approx(0.2)
    assert info.value.result.data["time"][-1] == pytest.approx(0.2)
    assert info.value.fmu_message == ("plant: Python exception in fmi2DoStep: RuntimeError: "
                                      "injected failure")
    assert str(info.value).endswith(info.value.fmu_message) and "\n" not in str(info.value)
    assert capfd.readouterr().out == ""


def test_fmu_messages_reach_their_own_execution_through_the_logger_callback(fmus, caplog):
    """fmpy's logger proxy is one global of the process: another logger installed after the
    FMUs were instantiated (as a test or another tool may do) does not steal their messages,
    and two executions with equally named instances keep their messages apart."""
    import ctypes

    from fmpy.fmi2 import fmi2CallbackFunctions, fmi2CallbackLoggerTYPE
    from fmpy.logging import addLoggerProxy

    stolen = []
    other = fmi2CallbackFunctions()
    other.logger = fmi2CallbackLoggerTYPE(lambda *args: stolen.append(args))
    failing = Execution(plant_loop(fmus, {"fail_at_time": 0.05, "fail_mode": 1}))
    healthy = Execution(plant_loop(fmus, {}))
    with failing, healthy, caplog.at_level("DEBUG", "drillcosim.cosim.master.fmi_log"):
        failing.initialize()
        healthy.initialize()
        addLoggerProxy(ctypes.byref(other))          # someone re-points the global proxy
        with pytest.raises(CosimError, match="RuntimeError: injected failure"):
            failing.simulate_until(0.1)
        healthy.simulate_until(0.1)
        assert healthy.slaves["plant"].log.messages == deque()
        assert [m[0] for m in failing.slaves["plant"].log.messages] == [3]
    assert stolen == []
    assert any("injected failure" in r.getMessage() for r in caplog.records)


def test_non_finite_output_stops_with_divergence(fmus):
    system = plant_loop(fmus, {"nan_at_time": 0.3})
    with Execution(system) as ex, pytest.raises(DivergenceError) as info:
        ex.simulate_until(1.0)
    assert info.value.quantity == "plant.x" and np.isnan(info.value.value)
    assert info.value.time == pytest.approx(0.31)
    res = Master(system).simulate(1.0, outputs=["plant.x", "ctrl.y"])
    assert res.diverged is not None and res.diverged.quantity == "plant.x"
    assert res.diverged.time == pytest.approx(0.31)
    assert res.data["time"][-1] == pytest.approx(0.30) and np.isfinite(res.data["plant.x"]).all()


def test_unwritable_output_directory_fails_before_running(fmus, tmp_path):
    blocker = tmp_path / "not_a_dir"
    blocker.write_text("x")
    target = blocker / "out.csv"
    with pytest.raises(OSError, match="cannot write results to .*out.csv"):
        Master(plant_loop(fmus, {})).simulate(0.1, outputs=["plant.x"], csv_path=target)


def test_earlier_result_file_survives_until_new_one_is_complete(fmus, tmp_path):
    out = tmp_path / "res.csv"
    out.write_text("earlier result\n")
    seen = []

    class Peek:
        def on_step(self, ex):
            if ex.tick % 25 == 0:
                seen.append(out.read_text())

    system = plant_loop(fmus, {})
    with Execution(system, read_outputs=["plant.x"]) as ex:
        rec = Recorder(["plant.x"], csv_path=out, flush_every=10)
        ex.add_observer(rec)
        ex.add_observer(Peek())
        ex.simulate_until(1.0)
        rec.close()
    assert seen and all(s == "earlier result\n" for s in seen)
    rows = list(csv.reader(out.open()))
    assert len(rows) == 102 and float(rows[-1][0]) == 1.0
    assert not [p for p in tmp_path.iterdir() if p.name != "res.csv"]
    # a run failing before its first row leaves the earlier file untouched
    out.write_text("earlier result\n")
    bad = SystemSpec([FmuSpec("plant", fmus["mt_integrator"], {"x_0": 1.0})], base_step=0.1)
    with pytest.raises(ValueError, match="no variable 'x_0' \\(did you mean 'x0'"):
        Master(bad).simulate(1.0, outputs=["plant.x"], csv_path=out)
    assert out.read_text() == "earlier result\n"


def test_result_array_has_fmpy_result_layout(fmus):
    """Structured array, 'time' first: the layout fmpy.util.plot_result takes."""
    res = Master(plant_loop(fmus, {})).simulate(0.2, outputs=["plant.x", "ctrl.y"],
                                                  output_interval=0.05)
    assert res.data.dtype.names == ("time", "plant.x", "ctrl.y")
    np.testing.assert_allclose(res.data["time"], [0, 0.05, 0.1, 0.15, 0.2])
    assert res.wall_time > 0 and res.real_time_factor > 0 and res.end_time == 0.2


# --- multirate ------------------------------------------------------------------------
@pytest.mark.parametrize("algorithm", ["jacobi", "gauss_seidel"])
def test_multirate_fmu_steps_every_third_tick_with_3h(fmus, algorithm):
    H = 0.01
    system = SystemSpec(
        [FmuSpec("fast", fmus["mt_integrator"], {"u": 1.0}),
         FmuSpec("slow", fmus["mt_integrator"], {"u": 1.0}, sample_period_ticks=3)],
        [], H, algorithm)
    refs = ["slow.n_steps", "slow.last_h", "fast.n_steps", "slow.x"]
    res = Master(system).simulate(0.3, outputs=refs)
    k = np.arange(31)
    # Jacobi publishes a slow FMU's outputs when time reaches its communication
    # point; Gauss-Seidel as soon as it has stepped (ahead of the others).
    expected = k // 3 if algorithm == "jacobi" else -(-k // 3)
    assert np.array_equal(res.data["slow.n_steps"], expected)
    assert np.array_equal(res.data["fast.n_steps"], k)
    assert np.all(res.data["slow.last_h"][expected > 0] == 3 * H)
    np.testing.assert_allclose(res.data["slow.x"], expected * 3 * H, atol=1e-14)


def test_multirate_consumer_holds_slow_output(fmus):
    """A fast probe of a period-4 source sees its value held for 4 ticks (Jacobi)."""
    system = SystemSpec(
        [FmuSpec("src", fmus["mt_source"], {"omega": 2.0}, sample_period_ticks=4),
         FmuSpec("probe", fmus["mt_gain"], {"k": -1.0})],
        [Connection("src.y", "probe.u")], 0.01, "jacobi")
    res = Master(system).simulate(0.4, outputs=["probe.y"])
    k = np.arange(41)
    # probe(t_k) echoes the input set at t_{k-1}: src at the last multiple of 4 <= k-1
    held = np.sin(2.0 * 0.01 * 4 * (np.maximum(k - 1, 0) // 4))
    np.testing.assert_allclose(res.data["probe.y"], held, atol=1e-14)


# --- system description -------------------------------------------------------------
def test_system_from_dict_and_validation(tmp_path):
    d = {"step": 1e-3, "stop_time": 2.0, "algorithm": "gauss_seidel", "order": ["c", "p"],
         "coupling": "linear",
         "fmus": {"p": {"path": "p.fmu", "parameters": {"k": 2}},
                  "c": {"path": "c.fmu", "sample_period": 5e-3}},
         "connections": [{"source": "p.x", "target": "c.u", "delay": 0.01},
                         {"source": "c.y", "target": "p.u", "coupling": "zoh"}]}
    s = system_from_dict(d, base_dir=tmp_path)
    assert s.fmu("c").sample_period_ticks == 5 and s.fmu("p").path == tmp_path / "p.fmu"
    assert [c.coupling for c in s.connections] == ["linear", "zoh"]
    assert s.stepping_order == ("c", "p") and s.stop_time == 2.0
    with pytest.raises(ValueError, match="did you mean 'stop_time'"):
        system_from_dict({**d, "stoptime": 1.0})
    with pytest.raises(ValueError, match="did you mean 'sample_period'"):
        system_from_dict({**d, "fmus": {"p": {"path": "p", "sample_perod": 1e-3}}})
    with pytest.raises(ValueError, match="sample_period.*integer multiple"):
        system_from_dict({**d, "fmus": {"p": {"path": "p", "sample_period": 1.5e-3}}})
    with pytest.raises(ValueError, match="did you mean 'gauss_seidel'"):
        system_from_dict({**d, "algorithm": "gauss-seidel"})


@pytest.mark.parametrize("make,match", [
    (lambda: FmuSpec("a.b", "x.fmu"), "FmuSpec.name"),
    (lambda: FmuSpec("a", "x.fmu", sample_period_ticks=0), "sample_period_ticks.*>= 1"),
    (lambda: Connection("a.x", "b.u", delay=-1.0), "delay.*>= 0"),
    (lambda: Connection("ax", "b.u"), "Connection.source"),
    (lambda: Connection("a.x", "b.u", coupling="cubic"), "coupling"),
    (lambda: SystemSpec([FmuSpec("a", "x")], base_step=0.0), "base_step.*> 0"),
    (lambda: SystemSpec([FmuSpec("a", "x")], [Connection("a.x", "q.u")]), "unknown FMU 'q'"),
    (lambda: SystemSpec([FmuSpec("a", "x"), FmuSpec("a", "y")]), "unique"),
    (lambda: SystemSpec([FmuSpec("a", "x")], order=["b"]), "SystemSpec.order"),
])
def test_invalid_specs_name_the_field(make, match):
    with pytest.raises(ValueError, match=match):
        make()


# --- hooks ------------------------------------------------------------------------------
def test_scheduled_change_manipulator_and_late_observer(fmus):
    from drillcosim.cosim.master.manipulators import ScheduledChange

    system = SystemSpec([FmuSpec("i", fmus["mt_integrator"])], base_step=0.01)
    with Execution(system, read_outputs=["i.x"]) as ex:
        ex.add_manipulator(ScheduledChange(0.25, "i.u", 2.0))
        ex.simulate_until(0.2)
        rec = Recorder(["i.x"])  # added after initialisation: still resolves its sources
        ex.add_observer(rec)
        ex.simulate_until(1.0)
        # x' = 2 from t = 0.25 on
        np.testing.assert_allclose(ex.get_real("i.x"), 2.0 * 0.75, rtol=1e-12)
        np.testing.assert_allclose(rec.data["i.x"], 2.0 * np.maximum(rec.data["time"] - 0.25,
                                                                     0.0), atol=1e-12)


def test_streaming_csv_keeps_memory_flat(fmus, tmp_path):
    out = tmp_path / "stream.csv"
    system = SystemSpec([FmuSpec("i", fmus["mt_integrator"], {"u": 1.0})], base_step=0.01)
    with Execution(system, read_outputs=["i.x"]) as ex:
        rec = Recorder(["i.x"], csv_path=out, flush_every=16, keep_in_memory=False)
        ex.add_observer(rec)
        ex.simulate_until(1.0)
        assert len(rec.data) < 16 and rec.n_rows == 101
        rec.close()
    data = np.loadtxt(out, delimiter=",", skiprows=1)
    assert data.shape == (101, 2)
    np.testing.assert_allclose(data[:, 1], data[:, 0], atol=1e-12)


def test_progress_bar_shows_real_time_factor(fmus, capsys):
    system = SystemSpec([FmuSpec("i", fmus["mt_integrator"])], base_step=0.01)
    Master(system).simulate(1.0, progress=True)
    err = capsys.readouterr().err
    assert "RTF" in err and "1.000/1.000 s" in err
    Master(system).simulate(1.0, progress=None)  # not a TTY under pytest: silent
    assert capsys.readouterr().err == ""
