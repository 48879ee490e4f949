"""Reliability: determinism and independent instances.

* The same scene and parameters give bit-identical results run to run: two fmpy
  runs of the plant FMU (default stable step, i.e. the eigenvalue estimate
  included), and the master with plant + controller (``drillcosim run``'s
  ``drillcosim.simulate``); a run in a worker process (``ProcessPoolExecutor``, spawn) equals
  the in-process run bit for bit.
* Two instances with different parameters in one process share no state: their
  interleaved steps equal their solo runs, for the plant and for the controller.
"""

from __future__ import annotations

import math
import multiprocessing
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np
import pytest

from support.fuzz_fmi import Harness

STEPS = 40


@pytest.fixture(scope="module")
def fmu_paths(project_fmus: dict[str, Path]) -> dict[str, str]:
    return {name: str(path) for name, path in project_fmus.items()}


def _inputs(h: Harness, k: int) -> list[float]:
    scale = 2e3 if h.is_plant else 1e-6
    return [scale * math.sin(0.37 * k + 1.3 * i) for i in range(len(h.inputs))]


class Run:
    """One initialized instance stepping with deterministic inputs."""

    def __init__(self, h: Harness, params: dict[str, float], fast: bool) -> None:
        self.h = h
        self.k = 0
        self.rows: list[list[float]] = []
        s = self.s = h.new(logging_on=False)
        s.setupExperiment(startTime=0.0)
        s.enterInitializationMode()
        if fast:
            h.fast_parameters(s)
        for name, value in params.items():
            v = h.by_name[name]
            if v.type == "Integer":
                s.setInteger([v.valueReference], [int(value)])
            else:
                s.setReal([v.valueReference], [value])
        s.exitInitializationMode()
        self.rows.append(s.getReal(h.outputs))

    def step(self) -> None:
        self.s.setReal(self.h.inputs, _inputs(self.h, self.k))
        self.s.doStep(self.k * 1e-3, 1e-3)
        self.k += 1
        self.rows.append(self.s.getReal(self.h.outputs))

    def finish(self) -> np.ndarray:
        self.s.terminate()
        self.s.freeInstance()
        return np.array(self.rows)


def solo_run(fmu: str, params: dict[str, float], fast: bool = True,
             steps: int = STEPS) -> np.ndarray:
    """Outputs of one instance alone (module-level: picklable for worker processes)."""
    run = Run(Harness(fmu), params, fast)
    for _ in range(steps):
        run.step()
    return run.finish()


def _bit_equal(a: np.ndarray, b: np.ndarray) -> bool:
    return a.shape == b.shape and a.tobytes() == b.tobytes()


def _spawn_pool() -> ProcessPoolExecutor:
    # spawn: never fork a process whose embedded FMU Python state owns threads
    return ProcessPoolExecutor(max_workers=1, mp_context=multiprocessing.get_context("spawn"))


@pytest.mark.slow
def test_plant_fmu_runs_are_bit_identical_in_process_and_in_a_worker(fmu_paths) -> None:
    fmu = fmu_paths["DrillstringPlant"]
    params = {"top_drive.rotary_speed": 15.0, "bit.displacement_amplitude": 0.004}
    first = solo_run(fmu, params, fast=False)
    second = solo_run(fmu, params, fast=False)
    with _spawn_pool() as pool:
        worker = pool.submit(solo_run, fmu, params, False).result(timeout=600)
    assert np.all(np.isfinite(first)) and np.any(first[-1] != first[1])
    assert _bit_equal(first, second)
    assert _bit_equal(first, worker)


def test_controller_fmu_runs_are_bit_identical_in_process_and_in_a_worker(fmu_paths) -> None:
    fmu = fmu_paths["StrainController"]
    params = {"gain": 3e9, "lag_time_constant": 0.005}
    first = solo_run(fmu, params)
    with _spawn_pool() as pool:
        worker = pool.submit(solo_run, fmu, params).result(timeout=300)
    assert _bit_equal(first, solo_run(fmu, params)) and _bit_equal(first, worker)


def scene_run(out_dir: str, fmu_dir: str) -> bytes:
    """``drillcosim run`` (plant + controller through the master): results.csv bytes."""
    from drillcosim import simulate

    res = simulate("paper_closed_loop", stop_time=0.01, fmu_dir=fmu_dir)
    res.save(out_dir, plots=False)
    assert res.completed, res.message()
    return (Path(out_dir) / "results.csv").read_bytes()


@pytest.mark.slow
def test_master_plant_and_controller_bit_identical_in_process_and_in_a_worker(
        fmu_paths, tmp_path: Path) -> None:
    fmu_dir = str(Path(fmu_paths["DrillstringPlant"]).parent)
    first = scene_run(str(tmp_path / "a"), fmu_dir)
    second = scene_run(str(tmp_path / "b"), fmu_dir)
    with _spawn_pool() as pool:
        worker = pool.submit(scene_run, str(tmp_path / "c"), fmu_dir).result(timeout=900)
    assert first.count(b"\n") > 10
    assert first == second
    assert first == worker


@pytest.mark.parametrize("name, params_a, params_b", [
    ("DrillstringPlant",
     {"top_drive.rotary_speed": 20.0},
     {"top_drive.rotary_speed": 12.0, "contact.stiffness": 5e6, "damping.axial_ratio": 0.02,
      "unbalance.moment": 0.3}),
    ("StrainController",
     {"gain": 1e9, "lag_time_constant": 0.01},
     {"gain": 2e9, "lag_time_constant": 0.02, "mode": 1, "force_limit": 1500.0}),
])
def test_two_instances_with_different_parameters_share_no_state(
        fmu_paths, name: str, params_a: dict, params_b: dict) -> None:
    fmu = fmu_paths[name]
    solo_a = solo_run(fmu, params_a)
    solo_b = solo_run(fmu, params_b)
    assert not np.array_equal(solo_a, solo_b)
    h = Harness(fmu)
    a = Run(h, params_a, fast=True)
    b = Run(h, params_b, fast=True)  # instantiated and initialized after a
    for k in range(STEPS):
        a.step()
        b.step()
        if k % 7 == 3:  # uneven interleaving: b takes an extra turn via a saved state
            state = b.s.getFMUstate()
            b.s.setFMUstate(state)
            b.s.freeFMUstate(state)
    inter_a, inter_b = a.finish(), b.finish()
    assert _bit_equal(inter_a, solo_a)
    assert _bit_equal(inter_b, solo_b)


def test_freeing_one_instance_leaves_the_other_intact(fmu_paths) -> None:
    fmu = fmu_paths["DrillstringPlant"]
    params = {"top_drive.rotary_speed": 18.0}
    solo = solo_run(fmu, params)
    h = Harness(fmu)
    a = Run(h, params, fast=True)
    for _ in range(STEPS // 2):
        a.step()
    other = Run(h, {"top_drive.rotary_speed": 5.0}, fast=True)
    other.step()
    other.finish()  # frees an instance of the same FMU mid-run of `a`
    for _ in range(STEPS - STEPS // 2):
        a.step()
    assert _bit_equal(a.finish(), solo)
