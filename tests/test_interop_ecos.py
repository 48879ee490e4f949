"""Ecos (the C++ engine shipped by the ecospy wheel) runs our exported SSP like our master.

Same system, step and algorithm: the closed loop of support.closed_loop (Jacobi with a
zero-order hold, no delays, H = 0.1 ms, 1 s), once with Ecos's default threaded stepping and
once with ``--noParallel``:

    ecos simulate --path X.ssp --stopTime 1 --stepSize 0.0001 --parameterSet <name> [--noParallel]

Ecos applies SSP parameter sets only when named (``--parameterSet``); our export gives every
component's set the system's name. Ecos counts time as t += H (a few ulps from our k H), so
the time-dependent forcing differs by ulps, as in libcosim.

The CLI's CSV prints every Real with ``%f`` (six decimals): a value is known only to
+-5e-7 from it, coarser than 1e-9 of the peak for signals below ~500 in their unit (strains,
deflections). The CLI runs are compared to 1e-9 of each signal's peak plus that printing
resolution, and the threaded and serial CSVs must be identical; the same engine through its
C library (libecosc, threaded) is compared at full precision, to 1e-9 of each peak.

Without Debian's libtbb12 the engine cannot start: the tests skip, naming it.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from support.closed_loop import ClosedLoop
from support.engines import CSV_RESOLUTION, compare, ecos_binary, run_ecos_cli, run_ecos_library
from support.required import import_module, missing

pytestmark = [pytest.mark.interop]


@pytest.fixture(scope="module")
def ecos(tmp_path_factory) -> Path:
    exe, info = ecos_binary(tmp_path_factory.mktemp("ecos_bin"))
    if exe is None:
        if "libtbb" in info:
            missing("libtbb12", info)
        import_module("ecospy")
        pytest.fail(info, pytrace=False)  # ecospy is there but its engine cannot run
    return exe


@pytest.fixture(scope="module")
def cli_runs(ecos, closed_loop_py, tmp_path_factory) -> dict[str, tuple]:
    """The CLI run of the closed loop, threaded and serial."""
    loop = closed_loop_py
    work = tmp_path_factory.mktemp("ecos_cli")
    return {mode: run_ecos_cli(ecos, loop.ssp, loop.step, loop.stop, loop.outputs,
                               loop.parameter_set, work, parallel=mode == "threaded")
            for mode in ("threaded", "serial")}


def _report(label: str, loop: ClosedLoop, result, record_property,
            resolution: float = 0.0) -> None:
    record_property("max_rel_diff", result.worst(resolution / 1e-9)[1])
    print(f"\nENGINE {label}: {result.summary(resolution)}; {loop.n_steps} steps of "
          f"{loop.step:g} s")
    assert result.n_moving() > 15  # not a comparison between constants
    forces = [o for o in loop.outputs if "_force_" in o and o.startswith("controller.")]
    assert min(result.peak[f] for f in forces) > 1.0  # the controller acted at every site


@pytest.mark.parametrize("mode", ["threaded", "serial"])
def test_ecos_cli_equals_our_master(cli_runs, closed_loop_py, mode, record_property) -> None:
    loop = closed_loop_py
    times, cols, _text = cli_runs[mode]
    assert times.shape == (loop.n_steps + 1,)
    np.testing.assert_allclose(times, loop.data["time"], rtol=0, atol=5e-6)  # printed %g
    result = compare(loop.data, cols, rtol=1e-9, resolution=CSV_RESOLUTION)
    _report(f"Ecos CLI {mode} (CSV, %f)", loop, result, record_property, CSV_RESOLUTION)
    # the signals large enough for the CSV to resolve 1e-9 of their peak were held to it
    assert sum(p * 1e-9 >= CSV_RESOLUTION for p in result.peak.values()) >= 3


def test_ecos_threaded_and_serial_agree_to_the_digit(cli_runs) -> None:
    """Threaded stepping must not change a result (order of finishing is irrelevant)."""
    assert cli_runs["threaded"][2] == cli_runs["serial"][2]


def test_ecos_library_equals_our_master_in_full_precision(ecos, closed_loop_py, tmp_path,
                                                          record_property) -> None:
    loop = closed_loop_py
    rows = run_ecos_library(loop.ssp, loop.step, loop.n_steps, loop.outputs,
                            loop.parameter_set, tmp_path)
    result = compare(loop.data, {o: rows[:, j] for j, o in enumerate(loop.outputs)}, rtol=1e-9)
    _report("Ecos library (libecosc, threaded, full precision)", loop, result, record_property)


def test_ecos_runs_the_c_controller_like_our_master(ecos, closed_loop_c, tmp_path,
                                                    record_property) -> None:
    loop = closed_loop_c
    times, cols, _ = run_ecos_cli(ecos, loop.ssp, loop.step, loop.stop, loop.outputs,
                                  loop.parameter_set, tmp_path, parallel=False)
    result = compare(loop.data, cols, rtol=1e-9, resolution=CSV_RESOLUTION)
    _report("Ecos CLI serial, C controller (CSV, %f)", loop, result, record_property,
            CSV_RESOLUTION)
    rows = run_ecos_library(loop.ssp, loop.step, loop.n_steps, loop.outputs,
                            loop.parameter_set, tmp_path)
    result = compare(loop.data, {o: rows[:, j] for j, o in enumerate(loop.outputs)}, rtol=1e-9)
    _report("Ecos library, C controller (full precision)", loop, result, record_property)
