"""The master's native loop (chunks of steps in C) against its Python loop: the same numbers bit
for bit, the same errors (FMU, call, time, message, partial result), the same hooks.

Every comparison runs the same system twice, ``DRILLCOSIM_MASTER_LOOP=python`` (the Python
loop, the reference) and the default (the native loop, which must actually have run: a spy
counts its chunks).
"""

from __future__ import annotations

import ctypes
import math
from collections.abc import Callable

import numba
import numpy as np
import pytest

from drillcosim.cosim.master import native
from drillcosim.cosim.master.errors import CosimError
from drillcosim.cosim.master.execution import Execution
from drillcosim.cosim.master.limits import OutputLimit
from drillcosim.cosim.master.manipulators import InjectFault, ScheduledChange
from drillcosim.cosim.master.master import Master
from drillcosim.cosim.master.native.runner import LOOP_ENV, NativeLoop
from drillcosim.cosim.master.recorder import Recorder
from drillcosim.cosim.master.slave import CompiledCalls, Slave
from drillcosim.cosim.master.system import Connection, FmuSpec, SystemSpec
from support.required import missing

pytestmark = pytest.mark.needs_cc


@pytest.fixture
def chunks(monkeypatch):
    """Count the chunks the native loop runs (list of (first tick, stop tick))."""
    calls: list[tuple[int, int]] = []
    real = NativeLoop.run

    def spy(self, k_stop, observers, manipulators):
        calls.append((self.execution.tick, k_stop))
        return real(self, k_stop, observers, manipulators)

    monkeypatch.setattr(NativeLoop, "run", spy)
    return calls


def both(monkeypatch, chunks, run: Callable[[], object]) -> tuple[object, object]:
    """(Python loop outcome, native loop outcome) of ``run``; the native loop must run."""
    monkeypatch.setenv(LOOP_ENV, "python")
    reference = run()
    assert not chunks
    monkeypatch.setenv(LOOP_ENV, "auto")
    outcome = run()
    assert chunks, "the native loop did not run"
    return reference, outcome


def same(a: np.ndarray, b: np.ndarray) -> None:
    assert a.dtype == b.dtype and a.shape == b.shape
    assert np.array_equal(a.view(np.float64), b.view(np.float64), equal_nan=True)


def oscillator(fmus, algorithm: str, delay: float, period_b: int = 1) -> SystemSpec:
    """Two masses, linear-extrapolation and hold couplings, a fractional delay, multirate."""
    return SystemSpec(
        [FmuSpec("a", fmus["mt_mass"], {"m": 1.0, "kc": 2.0, "x0": 1.0, "h_max": 2e-3}),
         FmuSpec("b", fmus["mt_mass"], {"m": 2.0, "k": 0.5, "kc": 2.0, "h_max": 2e-3},
                 period_b)],
        [Connection("a.x", "b.x_other", coupling="linear", delay=delay),
         Connection("b.x", "a.x_other", delay=0.02)],
        0.01, algorithm)


def loop(fmus, algorithm: str, kh: float, delay_steps: int, ctrl_period: int = 1,
         plant: dict | None = None) -> SystemSpec:
    """Integrator x' = u under P control u = -K x, the delay on ctrl -> plant."""
    h = 0.01
    return SystemSpec(
        [FmuSpec("plant", fmus["mt_integrator"], {"x0": 1.0, **(plant or {})}),
         FmuSpec("ctrl", fmus["mt_gain"], {"k": kh / h}, ctrl_period)],
        [Connection("plant.x", "ctrl.u"),
         Connection("ctrl.y", "plant.u", delay=delay_steps * h)],
        h, algorithm, ("plant", "ctrl"))


@pytest.mark.parametrize("algorithm", ["jacobi", "gauss_seidel"])
@pytest.mark.parametrize("delay,period_b", [(0.0, 1), (0.037, 1), (0.03, 3), (0.045, 2)])
def test_oscillator_native_equals_python_bit_for_bit(fmus, monkeypatch, chunks, algorithm,
                                                     delay, period_b):
    outputs = ["a.x", "a.v", "b.x", "b.v"]
    ref, got = both(monkeypatch, chunks, lambda: Master(
        oscillator(fmus, algorithm, delay, period_b)).simulate(3.0, outputs=outputs,
                                                               output_ticks=3))
    assert len(ref.data) == 101
    same(ref.data, got.data)
    assert ref.end_time == got.end_time == 3.0


@pytest.mark.parametrize("algorithm", ["jacobi", "gauss_seidel"])
@pytest.mark.parametrize("delay_steps,ctrl_period", [(0, 1), (2, 1), (3, 2), (1, 3)])
def test_delayed_loop_native_equals_python_bit_for_bit(fmus, monkeypatch, chunks, algorithm,
                                                       delay_steps, ctrl_period):
    outputs = ["plant.x", "plant.n_steps", "plant.last_h", "ctrl.y", "ctrl.n_steps"]
    ref, got = both(monkeypatch, chunks, lambda: Master(
        loop(fmus, algorithm, 0.3, delay_steps, ctrl_period)).simulate(5.0, outputs=outputs))
    same(ref.data, got.data)
    # the multirate controller stepped every ctrl_period ticks; Gauss-Seidel reads a step's
    # outputs at once, Jacobi at its end (tick 498 + 3 > 500 is not read)
    read = -(-500 // ctrl_period) if algorithm == "gauss_seidel" else 500 // ctrl_period
    assert got.data["ctrl.n_steps"][-1] == read


def test_split_runs_and_state_restore_native_equal_one_python_run(fmus, monkeypatch, chunks):
    refs = ["a.x", "b.x", "b.v"]

    def run():
        with Execution(oscillator(fmus, "jacobi", 0.123, 2), read_outputs=refs) as ex:
            rec = Recorder(refs)
            ex.add_observer(rec)
            ex.simulate_until(0.5)
            state = ex.get_state()
            for stop in (0.73, 1.0, 1.5):
                ex.simulate_until(stop)
            first = rec.data[51:]         # rows of (0.5, 1.5]
            ex.set_state(state)
            ex.simulate_until(1.5)
            return np.concatenate([first, rec.data[151:]])

    ref, got = both(monkeypatch, chunks, run)
    assert len(ref) == 200
    same(ref[:100], ref[100:])            # the restored run repeats the first
    same(ref, got)


@pytest.mark.parametrize("kind", ["discard", "error", "nan"])
@pytest.mark.parametrize("algorithm", ["jacobi", "gauss_seidel"])
def test_failure_inside_a_chunk_is_reported_as_in_python(fmus, monkeypatch, chunks, tmp_path,
                                                         kind, algorithm):
    plant = {"discard": {"fail_at_time": 1.23}, "error": {"fail_at_time": 1.23, "fail_mode": 1},
             "nan": {"nan_at_time": 1.23}}[kind]

    def run():
        csv = tmp_path / f"run-{len(chunks)}.csv"
        master = Master(loop(fmus, algorithm, 0.3, 1, plant=plant))
        kwargs = {"outputs": ["plant.x", "ctrl.y"], "csv_path": csv, "flush_every": 7}
        if kind == "nan":       # a divergence ends the run with its result
            result = master.simulate(3.0, **kwargs)
            return result.diverged, result, csv.read_text()
        with pytest.raises(CosimError) as info:
            master.simulate(3.0, **kwargs)
        return info.value, info.value.result, csv.read_text()

    (ref, ref_res, ref_csv), (got, got_res, got_csv) = both(monkeypatch, chunks, run)
    if kind == "nan":
        assert (got.time, got.quantity) == (ref.time, ref.quantity) == (got.time, "plant.x")
        assert math.isnan(got.value) and math.isnan(ref.value)
        assert got.time == pytest.approx(1.24)
    else:
        assert type(ref) is type(got) is CosimError
        assert (got.fmu_name, got.call, got.time, got.status, got.fmu_message) == \
            (ref.fmu_name, ref.call, ref.time, ref.status, ref.fmu_message)
        assert str(got) == str(ref) and got.time == pytest.approx(1.23)
    same(ref_res.data, got_res.data)
    assert got_res.end_time == ref_res.end_time
    assert got_csv == ref_csv and got_csv.count("\n") == len(got_res.data) + 1


def test_output_limit_stops_as_in_python(fmus, monkeypatch, chunks):
    # K H = 1.03 x the Levin-May bound for m = 2: the loop grows; the limit stops it
    def run():
        return Master(loop(fmus, "gauss_seidel", 0.64, 2)).simulate(
            20.0, outputs=["plant.x"], observers=[OutputLimit(["plant.x"], 5.0)])

    ref, got = both(monkeypatch, chunks, run)
    assert got.diverged == ref.diverged and got.diverged.quantity == "plant.x"
    assert abs(got.diverged.value) > 5.0 and math.isfinite(got.diverged.value)
    same(ref.data, got.data)
    assert got.end_time == got.diverged.time < 20.0
    assert got.data["time"][-1] < got.diverged.time  # the recorder comes after the limit


def test_manipulators_act_between_chunks_as_in_python(fmus, monkeypatch, chunks):
    def run():
        system = SystemSpec([FmuSpec("i", fmus["mt_integrator"]),
                             FmuSpec("j", fmus["mt_integrator"], {"u": 1.0})], base_step=0.01)
        with Execution(system, read_outputs=["i.x", "j.x"]) as ex:
            ex.add_manipulator(ScheduledChange(0.25, "i.u", 2.0))
            fault = InjectFault(0.5, "j.u", -3.0, stop=0.57, restore=0.5)
            ex.add_manipulator(fault)
            rec = Recorder(["i.x", "j.x"])
            ex.add_observer(rec)
            ex.simulate_until(1.0)
            return rec.data, fault.applied

    (ref, ref_applied), (got, got_applied) = both(monkeypatch, chunks, run)
    same(ref, got)
    assert got_applied == ref_applied == 7
    np.testing.assert_allclose(got["i.x"][-1], 1.5, rtol=1e-12)


def test_progress_bar_updates_at_the_same_ticks(fmus, monkeypatch, chunks, capsys):
    seen: dict[str, list[float]] = {}

    class Shown:
        """A strided observer like the progress bar: records the times it acts at."""

        stride_ticks = 7

        def __init__(self, key):
            self.key = key
            seen[key] = []

        def on_step(self, ex):
            if ex.tick % self.stride_ticks == 0:
                seen[self.key].append(ex.time)

    def run():
        key = "native" if "python" in seen else "python"
        return Master(oscillator(fmus, "jacobi", 0.0)).simulate(
            2.0, outputs=["a.x"], observers=[Shown(key)], progress=True)

    both(monkeypatch, chunks, run)
    assert seen["native"] == seen["python"] and len(seen["native"]) == 200 // 7
    err = capsys.readouterr().err
    assert err.count("2.000/2.000 s") == 2 and "RTF" in err


def test_a_general_observer_keeps_the_python_loop(fmus, monkeypatch, chunks):
    class Peek:
        def on_step(self, ex):
            pass

    Master(oscillator(fmus, "jacobi", 0.0)).simulate(0.5, outputs=["a.x"], observers=[Peek()])
    assert not chunks


def test_the_library_is_built_into_the_user_cache(tmp_path, monkeypatch):
    monkeypatch.setenv("DRILLCOSIM_CACHE", str(tmp_path))
    path = native.library_path()
    assert path.parent == tmp_path / "master" and not path.exists()
    lib = native.library()
    assert lib is not None and path.is_file()
    assert native.library() is lib


# --- a compiled in-process slave (contract item 10, CompiledCalls) ---------------------------
U, X, N, FAIL_AT, PY_EVERY, N_PY = range(6)
LEAVE_TO_PYTHON = 1


@numba.cfunc(numba.types.int32(numba.types.voidptr, numba.types.float64,
                               numba.types.float64), nopython=True)
def _integrate(context, t, h):
    c = numba.carray(context, 6, dtype=np.float64)
    if 0.0 <= c[FAIL_AT] <= t + 1e-12:
        return 7
    if c[PY_EVERY] > 0 and c[N] % c[PY_EVERY] == c[PY_EVERY] - 1:
        return LEAVE_TO_PYTHON             # this step is done in Python (nothing changed)
    c[X] = c[X] + c[U] * h
    c[N] += 1.0
    return 0


class CompiledIntegrator(Slave):
    """x' = u in process, its step compiled (the arithmetic of mt_integrator / mt_compiled)."""

    can_get_set_state = True

    def __init__(self, name: str, x0: float = 0.0, fail_at: float = -1.0,
                 python_every: int = 0):
        self.name = name
        self.ctx = np.array([0.0, x0, 0.0, fail_at, python_every, 0.0])
        self.names = {"u": U, "x": X, "n_steps": N, "n_python": N_PY}
        self.problem = None

    def check_variable(self, name, causalities):
        if name not in self.names:
            raise ValueError(f"no variable {name!r}")

    def instantiate(self, start_time, stop_time):
        pass

    def bind(self, outputs, y, offset, inputs, u):
        self.outs = [self.names[n] for n in outputs]
        self.ins = [self.names[n] for n in inputs]
        self.y, self.offset, self.u = y, offset, u

    def write_inputs(self):
        for i, slot in enumerate(self.ins):
            self.ctx[slot] = self.u[i]
        return 0

    def do_step(self, t, h):
        code = _integrate.ctypes(ctypes.c_void_p(self.ctx.ctypes.data), t, h)
        return 0 if code == 0 else self.native_step_failed(code, t, h)

    def read_outputs(self):
        for i, slot in enumerate(self.outs):
            self.y[self.offset + i] = self.ctx[slot]
        return 0

    def native_calls(self):
        data = self.ctx.ctypes.data
        return CompiledCalls(_integrate.address, data, data, tuple(self.ins), data,
                             tuple(self.outs))

    def native_step_failed(self, code, t, h):
        if code == LEAVE_TO_PYTHON:        # the step in Python, as the compiled one would
            c = self.ctx
            c[X] = c[X] + c[U] * h
            c[N] += 1.0
            c[N_PY] += 1.0
            return 0
        self.problem = f"{self.name}: step failed at t = {t!r} s (code {code})"
        return 2

    def take_problem(self):
        problem, self.problem = self.problem, None
        return problem

    def get_real(self, name, time):
        return float(self.ctx[self.names[name]])

    def set_value(self, name, value, time):
        self.ctx[self.names[name]] = value

    def get_state(self, time):
        return self.ctx.copy()

    def set_state(self, state, time):
        self.ctx[:] = state

    def close(self):
        pass


@pytest.mark.parametrize("algorithm", ["jacobi", "gauss_seidel"])
def test_compiled_in_process_slaves_equal_the_compiled_fmus(fmus, monkeypatch, chunks,
                                                            algorithm):
    """Two integrators coupled u_a = x_b, u_b = -x_a (delay 2 steps, b every 2nd tick): in
    process with their compiled steps called from C, and as mt_compiled FMUs."""
    def system(path):
        return SystemSpec(
            [FmuSpec("a", path, {"x0": 1.0}), FmuSpec("b", path, {}, 2)],
            [Connection("a.x", "b.u", delay=0.02), Connection("b.x", "a.u")],
            0.01, algorithm)

    outputs = ["a.x", "b.x", "a.n_steps", "b.n_steps"]

    def in_process():
        slaves = {"a": CompiledIntegrator("a", 1.0), "b": CompiledIntegrator("b")}
        return Master(system(fmus["mt_integrator"]), slaves).simulate(2.0, outputs=outputs)

    ref, got = both(monkeypatch, chunks, in_process)
    same(ref.data, got.data)
    assert got.data["b.n_steps"][-1] == 100
    # the same arithmetic through the FMUs (Python loop; mt_integrator steps in Python)
    monkeypatch.setenv(LOOP_ENV, "python")
    via_fmus = Master(system(fmus["mt_integrator"])).simulate(2.0, outputs=outputs)
    same(via_fmus.data, got.data)


@pytest.mark.parametrize("algorithm", ["jacobi", "gauss_seidel"])
def test_a_compiled_step_left_to_python_goes_on_in_the_chunk(fmus, monkeypatch, chunks,
                                                              algorithm):
    """Every 3rd step of a (every 5th of b) the compiled step leaves to Python: the Python loop
    and the native loop (which settles that step in Python and goes on after it, mid-tick) give
    the same numbers."""
    def run():
        slaves = {"a": CompiledIntegrator("a", 1.0, python_every=3),
                  "b": CompiledIntegrator("b", python_every=5)}
        system = SystemSpec([FmuSpec("a", fmus["mt_integrator"]),
                             FmuSpec("b", fmus["mt_integrator"], {}, 2)],
                            [Connection("a.x", "b.u"), Connection("b.x", "a.u", delay=0.03)],
                            0.01, algorithm)
        return Master(system, slaves).simulate(1.0, outputs=["a.x", "b.x", "a.n_python",
                                                             "b.n_python", "a.n_steps"])

    ref, got = both(monkeypatch, chunks, run)
    same(ref.data, got.data)
    assert got.data["a.n_steps"][-1] == 100
    assert got.data["a.n_python"][-1] == 33 and got.data["b.n_python"][-1] == 10


def test_a_failed_compiled_step_is_reported_as_in_python(fmus, monkeypatch, chunks):
    def run():
        slaves = {"a": CompiledIntegrator("a", 1.0, fail_at=0.5), "b": CompiledIntegrator("b")}
        system = SystemSpec([FmuSpec("a", fmus["mt_integrator"]),
                             FmuSpec("b", fmus["mt_integrator"])],
                            [Connection("a.x", "b.u"), Connection("b.x", "a.u")], 0.01)
        with pytest.raises(CosimError) as info:
            Master(system, slaves).simulate(1.0, outputs=["a.x", "b.x"])
        return info.value

    ref, got = both(monkeypatch, chunks, run)
    assert str(got) == str(ref) and got.call == "fmi2DoStep" and got.time == 0.5
    assert got.fmu_message == "a: step failed at t = 0.5 s (code 7)"
    same(ref.result.data, got.result.data)


# --- the real closed loop through the project's FMUs -----------------------------------------
@pytest.mark.parametrize("cosim", [
    {},                                                       # the scene: Gauss-Seidel, H
    {"algorithm": "jacobi", "step": 1e-4, "actuator_delay": 5e-4},
    {"actuator_delay": 7.5e-4, "sensor_delay": 2.5e-4, "controller_sample_period": 5e-4},
])
def test_closed_loop_fmus_native_equals_python_bit_for_bit(project_fmus, monkeypatch, chunks,
                                                           cosim):
    from drillcosim.cosim.scenario.build import build_system
    from drillcosim.cosim.scenario.config import load_config

    over = {"cosim.stop_time": 0.05, **{f"cosim.{k}": v for k, v in cosim.items()}}
    ss = build_system(load_config("paper_closed_loop", over), "fmu",
                      fmu_dir=project_fmus["DrillstringPlant"].parent)

    def run():
        return Master(ss.system).simulate(outputs=ss.outputs,
                                          output_ticks=ss.config.cosim.output_ticks)

    ref, got = both(monkeypatch, chunks, run)
    assert len(got.data) == 51 and got.diverged is None
    same(ref.data, got.data)
    forces = [o for o in ss.outputs if "force" in o and o.startswith("controller.")]
    assert forces and np.abs(got.data[forces[0]]).max() > 0     # the loop is closed


_SANITIZED_RUN = """
import sys
from pathlib import Path
from drillcosim.cosim.master import native
native.library_path = lambda: Path(sys.argv[1])     # the sanitized build, no rebuild
from drillcosim.cosim.master.master import Master
from drillcosim.cosim.master.system import Connection, FmuSpec, SystemSpec
fmu = sys.argv[2]
system = SystemSpec(
    [FmuSpec("a", fmu, {"m": 1.0, "kc": 2.0, "x0": 1.0}),
     FmuSpec("b", fmu, {"m": 2.0, "k": 0.5, "kc": 2.0}, 3)],
    [Connection("a.x", "b.x_other", coupling="linear", delay=0.037),
     Connection("b.x", "a.x_other", delay=0.02)], 0.01, sys.argv[3])
result = Master(system).simulate(2.0, outputs=["a.x", "b.x"], output_ticks=3)
assert native.library() is not None
print(repr(result.data["a.x"].tolist()))
"""


@pytest.mark.parametrize("algorithm", ["jacobi", "gauss_seidel"])
def test_the_loop_runs_clean_under_address_and_undefined_sanitizers(fmus, tmp_path, algorithm):
    """steps.c built with clang -fsanitize=address,undefined (aborting on any finding) runs a
    delayed, extrapolated, multirate system with the same numbers as the normal build."""
    import os
    import shutil
    import subprocess
    import sys

    clang = shutil.which("clang")
    if clang is None:
        missing("clang-asan", "clang is not on PATH")
    runtime = subprocess.run([clang, "-print-file-name=libclang_rt.asan-x86_64.so"],
                             capture_output=True, text=True).stdout.strip()
    if not os.path.isfile(runtime):
        missing("clang-asan", "clang's address-sanitizer runtime is not installed")
    lib = tmp_path / "steps_sanitized.so"
    subprocess.run([clang, "-std=c99", "-O1", "-g", "-Wall", "-Wextra", "-Werror", "-shared",
                    "-fPIC", "-ffp-contract=off", "-fsanitize=address,undefined",
                    "-fno-sanitize-recover=all", *map(str, native.SOURCES), "-o", str(lib), "-lm"],
                   check=True)
    env = dict(os.environ, LD_PRELOAD=runtime, ASAN_OPTIONS="detect_leaks=0")
    env.pop(LOOP_ENV, None)
    args = [sys.executable, "-c", _SANITIZED_RUN, str(lib), str(fmus["mt_mass"]), algorithm]
    sanitized = subprocess.run(args, env=env, capture_output=True, text=True, timeout=300)
    assert sanitized.returncode == 0, sanitized.stderr[-3000:]
    plain = subprocess.run([*args[:3], str(native.library_path()), *args[4:]],
                           capture_output=True, text=True, timeout=300,
                           env={k: v for k, v in os.environ.items() if k != LOOP_ENV})
    assert plain.returncode == 0, plain.stderr[-3000:]
    assert sanitized.stdout == plain.stdout and sanitized.stdout.count(",") == 66


def test_csv_rows_made_in_c_equal_numpy_savetxt():
    """The recorder's writer thread makes its text in C (rows.c): the same as
    numpy.savetxt(fmt="%.17g", delimiter=","), for every kind of double."""
    import io

    from drillcosim.cosim.master.recorder import CsvWriter

    rng = np.random.default_rng(3)
    bits = rng.integers(0, 2**63, size=40000, dtype=np.uint64) * np.uint64(2) + \
        rng.integers(0, 2, size=40000, dtype=np.uint64)
    values = bits.view(np.float64)                         # every exponent, both signs, NaN
    special = [0.0, -0.0, 5e-324, -2.2250738585072014e-308, 1.7976931348623157e308,
               math.inf, -math.inf, math.nan, -math.nan, 0.1, 1e16, 1e17, 1e-5, 1e-4, 30.0]
    rows = np.concatenate([values, rng.standard_normal(9985) * 1e3, special]).reshape(-1, 25)
    text = io.StringIO()
    writer = CsvWriter(text, native.library().dcs_format_rows)
    writer.submit(rows[:1000])
    writer.submit(rows[1000:])
    writer.close()
    reference = io.StringIO()
    np.savetxt(reference, rows, delimiter=",", fmt="%.17g")
    assert text.getvalue() == reference.getvalue()
