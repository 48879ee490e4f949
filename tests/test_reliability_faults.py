"""Reliability: faults during a co-simulation.

Injected by manipulators (:class:`cosim.master.manipulators.InjectFault`,
:class:`~cosim.master.manipulators.ScheduledChange`) or by the environment:

* an FMU that starts discarding its steps mid-run, a NaN on an input, a plant
  driven to divergence by a huge actuator force;
* a full disk (a 64 KiB tmpfs when running as root, else ``ENOSPC`` raised by a
  patched file object) and an unwritable output directory.

Each time the master stops with a clear, one-line report, the rows recorded so far
are complete and readable (``numpy.loadtxt`` gives exactly ``result.data``), no
temporary file is left behind, and no earlier result file is overwritten by a
truncated one. Bugs in files owned by others are ``xfail(strict=True)``.

The master :class:`cosim.master.Master` takes no manipulators; the tests
add theirs through a subclass of :class:`cosim.master.execution.Execution` patched into
``cosim.master``, so the facade's own error handling is what is tested.
"""

from __future__ import annotations

import contextlib
import errno
import hashlib
import io
import math
import os
import subprocess
import types
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

import drillcosim.cosim.master.files as files_module
import drillcosim.cosim.master.master as master_module
import drillcosim.cosim.scenario.result as result_module
from drillcosim.cosim.master.errors import CosimError
from drillcosim.cosim.master.execution import Execution
from drillcosim.cosim.master.manipulators import InjectFault, ScheduledChange
from drillcosim.cosim.master.master import Master
from drillcosim.cosim.master.recorder import ResultWriteError
from drillcosim.cosim.master.system import FmuSpec, SystemSpec

OUTPUTS = ["i.x", "i.n_steps", "i.last_h"]


def integrator(fmus, **params) -> SystemSpec:
    """One integrator x' = u (u = 1, unconnected), 1 ms steps."""
    return SystemSpec([FmuSpec("i", fmus["mt_integrator"], {"u": 1.0, **params})],
                      base_step=1e-3)


@contextlib.contextmanager
def manipulated(monkeypatch: pytest.MonkeyPatch, *manipulators) -> Iterator[None]:
    """Make the facade's executions carry ``manipulators``."""

    class WithManipulators(Execution):
        def __init__(self, *args, **kwargs):
            super().__init__(*args, **kwargs)
            for m in manipulators:
                self.add_manipulator(m)

    with monkeypatch.context() as mp:
        mp.setattr(master_module, "Execution", WithManipulators)
        yield


def digest(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def read_csv(path: Path, names: list[str]) -> np.ndarray:
    """The CSV as the recorder's structured array (header checked)."""
    with path.open() as fh:
        assert fh.readline().strip() == ",".join(["time", *names])
    flat = np.loadtxt(path, delimiter=",", skiprows=1, ndmin=2)
    out = np.zeros(len(flat), dtype=[(n, np.float64) for n in ["time", *names]])
    for k, n in enumerate(["time", *names]):
        out[n] = flat[:, k]
    return out


def assert_complete(path: Path, data: np.ndarray) -> None:
    """``path`` holds exactly ``data`` (17 significant digits round-trip bit for bit)."""
    got = read_csv(path, list(data.dtype.names[1:]))
    assert got.shape == data.shape
    for n in data.dtype.names:
        assert np.array_equal(got[n], data[n]), n


def no_temporaries(folder: Path) -> None:
    left = [p.name for p in folder.iterdir() if p.name.endswith(".part")
            or p.name.startswith(".")]
    assert not left, left


@pytest.fixture
def earlier(tmp_path: Path) -> tuple[Path, str]:
    """An earlier result file of another run in the output folder (must survive)."""
    old = tmp_path / "earlier_run.csv"
    old.write_text("time,i.x\n0,0\n0.001,0.001\n")
    return old, digest(old)


# ------------------------------------------------------------- FMU faults
@pytest.mark.parametrize("flush_every", [1, 7, 1000])
def test_fmu_discarding_mid_run_stops_with_report_and_complete_partial_file(
        fmus, tmp_path, monkeypatch, earlier, flush_every):
    out = tmp_path / "run.csv"
    fault = ScheduledChange(0.5, "i.fail_at_time", 0.5)
    with manipulated(monkeypatch, fault), pytest.raises(CosimError) as info:
        Master(integrator(fmus)).simulate(2.0, outputs=OUTPUTS, csv_path=out,
                                           flush_every=flush_every)
    err = info.value
    assert str(err) == ("FMU 'i': fmi2DoStep failed at t = 0.5 s: the FMU discarded the "
                        "step (fmi2Discard)")
    assert (err.fmu_name, err.call, err.status) == ("i", "fmi2DoStep", 2)
    res = err.result
    assert res is not None and res.end_time == 0.5
    assert len(res.data) == 501 and res.data["time"][-1] == 0.5
    assert np.array_equal(res.data["i.n_steps"], np.arange(501.0))
    assert_complete(out, res.data)
    old, old_digest = earlier
    assert digest(old) == old_digest
    no_temporaries(tmp_path)


def test_nan_injected_on_an_input_stops_with_divergence_and_finite_rows(
        fmus, tmp_path, monkeypatch):
    out = tmp_path / "run.csv"
    fault = InjectFault(0.3, "i.u", math.nan)
    with manipulated(monkeypatch, fault):
        res = Master(integrator(fmus)).simulate(1.0, outputs=OUTPUTS, csv_path=out)
    assert res.diverged is not None
    assert res.diverged.quantity == "i.x" and math.isnan(res.diverged.value)
    assert res.diverged.time == pytest.approx(0.301)
    assert fault.applied == 1
    assert res.data["time"][-1] == 0.3 and np.all(np.isfinite(res.data["i.x"]))
    assert_complete(out, res.data)
    no_temporaries(tmp_path)


def test_inject_fault_holds_then_restores(fmus, monkeypatch):
    fault = InjectFault(0.2, "i.u", 5.0, stop=0.4, restore=1.0)
    with manipulated(monkeypatch, fault):
        res = Master(integrator(fmus)).simulate(1.0, outputs=["i.x"], output_interval=0.1)
    assert fault.applied == 200
    assert res.data["i.x"][-1] == pytest.approx(0.2 + 0.2 * 5.0 + 0.6, rel=1e-12)
    with pytest.raises(ValueError, match="stop"):
        InjectFault(0.2, "i.u", 1.0, stop=0.1)


@pytest.fixture(scope="module")
def plant_fmu(project_fmus: dict[str, Path]) -> Path:
    return project_fmus["DrillstringPlant"]


PLANT_OUT = ["plant.body11_X", "plant.body11_Y", "plant.strain1_C"]


def test_plant_driven_to_divergence_by_a_huge_actuator_force(
        plant_fmu, tmp_path, monkeypatch, earlier, capfd):
    system = SystemSpec([FmuSpec("plant", plant_fmu, {"max_internal_step": 2.5e-4})],
                        base_step=1e-3)
    out = tmp_path / "plant.csv"
    fault = InjectFault(0.02, "plant.actuator1_force_C", 1e12)
    with manipulated(monkeypatch, fault), pytest.raises(CosimError) as info:
        Master(system).simulate(1.0, outputs=PLANT_OUT, csv_path=out, flush_every=5)
    err = info.value
    assert (err.fmu_name, err.call, err.status) == ("plant", "fmi2DoStep", 2)
    assert 0.02 <= err.time < 1.0
    # the plant's own report, through the FMI logger callback; nothing on stdout
    assert "discarded: diverged at t = " in err.fmu_message and str(err).endswith(
        err.fmu_message)
    assert capfd.readouterr().out == ""
    res = err.result
    assert res.data["time"][-1] == pytest.approx(err.time) and len(res.data) >= 21
    assert np.all(np.isfinite(res.data.view(np.float64)))
    assert_complete(out, res.data)
    old, old_digest = earlier
    assert digest(old) == old_digest
    no_temporaries(tmp_path)


# ----------------------------------------------------------- full disk
@contextlib.contextmanager
def tiny_tmpfs(path: Path, size: str = "64k") -> Iterator[Path]:
    """A tmpfs of ``size`` at ``path`` (root only); skips the test if mounting fails."""
    path.mkdir()
    if os.geteuid() != 0:
        pytest.skip("mounting a tmpfs needs root (the ENOSPC-patch test covers this)")
    proc = subprocess.run(["mount", "-t", "tmpfs", "-o", f"size={size}", "tmpfs", str(path)],
                          capture_output=True, text=True)
    if proc.returncode:
        pytest.skip(f"cannot mount a tmpfs: {proc.stderr.strip()}")
    try:
        yield path
    finally:
        subprocess.run(["umount", str(path)], check=False)


def _check_disk_full(err: CosimError, out: Path, old_text: str, folder: Path,
                     flush_every: int) -> None:
    assert isinstance(err, ResultWriteError)
    msg = str(err)
    assert msg.startswith(f"cannot write results to '{out}'") and "\n" not in msg
    assert "No space left on device" in msg and "not replaced" in msg
    assert err.os_errno == errno.ENOSPC
    assert out.read_text() == old_text  # the earlier result is untouched
    no_temporaries(folder)
    res = err.result
    assert res is not None and len(res.data) > 0  # rows recorded so far, in memory
    assert np.array_equal(res.data["i.n_steps"], np.arange(len(res.data), dtype=float))
    assert res.data["time"][-1] == pytest.approx(err.time)


def test_full_disk_tmpfs_stops_cleanly_and_keeps_earlier_file(fmus, tmp_path):
    with tiny_tmpfs(tmp_path / "disk") as disk:
        out = disk / "run.csv"
        old_text = "time,i.x\n0,0\n"
        out.write_text(old_text)
        with pytest.raises(CosimError) as info:
            Master(integrator(fmus)).simulate(30.0, outputs=OUTPUTS, csv_path=out,
                                               flush_every=100)
        _check_disk_full(info.value, out, old_text, disk, 100)
        # the space is free again: a small run to the same file now succeeds
        res = Master(integrator(fmus)).simulate(0.1, outputs=OUTPUTS, csv_path=out)
        assert_complete(out, res.data)


class _DiskFullFile(io.TextIOWrapper):
    """A text file whose writes fail with ENOSPC after ``budget`` characters."""

    budget = 0

    def write(self, s: str) -> int:
        type(self).budget -= len(s)
        if type(self).budget < 0:
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        return super().write(s)


@pytest.mark.parametrize("budget, flush_every", [(5_000, 10), (60_000, 1000), (0, 1)])
def test_full_disk_patched_enospc_stops_cleanly_and_keeps_earlier_file(
        fmus, tmp_path, monkeypatch, budget, flush_every):
    out = tmp_path / "run.csv"
    old_text = "time,i.x\n0,0\n"
    out.write_text(old_text)

    def fdopen(fd, mode="r", *args, **kwargs):
        raw = io.FileIO(fd, mode.replace("t", ""), closefd=True)
        return _DiskFullFile(io.BufferedWriter(raw), newline=kwargs.get("newline"))

    _DiskFullFile.budget = budget + len("time," + ",".join(OUTPUTS) + "\n")
    patched_os = types.SimpleNamespace(**{k: getattr(os, k) for k in dir(os)
                                          if not k.startswith("__")})
    patched_os.fdopen = fdopen
    monkeypatch.setattr(files_module, "os", patched_os)   # the recorder's atomic file
    with pytest.raises(CosimError) as info:
        Master(integrator(fmus)).simulate(5.0, outputs=OUTPUTS, csv_path=out,
                                           flush_every=flush_every)
    _check_disk_full(info.value, out, old_text, tmp_path, flush_every)


# --------------------------------------------------- unwritable output folder
@contextlib.contextmanager
def read_only_dir(path: Path) -> Iterator[Path]:
    """A folder this process cannot write (read-only tmpfs as root, chmod 500 otherwise)."""
    path.mkdir()
    (path / "earlier.csv").write_text("time,i.x\n0,0\n")
    if os.geteuid() != 0:
        path.chmod(0o500)
        try:
            yield path
        finally:
            path.chmod(0o700)
        return
    subprocess.run(["mount", "-t", "tmpfs", "-o", "size=64k", "tmpfs", str(path)], check=True)
    (path / "earlier.csv").write_text("time,i.x\n0,0\n")
    subprocess.run(["mount", "-o", "remount,ro", str(path)], check=True)
    try:
        yield path
    finally:
        subprocess.run(["umount", str(path)], check=False)


def test_unwritable_output_folder_fails_before_running(fmus, tmp_path):
    with read_only_dir(tmp_path / "ro") as ro:
        with pytest.raises(OSError) as info:
            Master(integrator(fmus)).simulate(0.1, outputs=OUTPUTS, csv_path=ro / "run.csv")
        msg = str(info.value)
        assert f"cannot write results to '{ro / 'run.csv'}'" in msg and "\n" not in msg
        assert sorted(p.name for p in ro.iterdir()) == ["earlier.csv"]
        assert (ro / "earlier.csv").read_text() == "time,i.x\n0,0\n"


# ------------------------------------------------------- drillcosim run (CLI)
def test_cli_run_into_read_only_folder_exits_2_with_one_line(tmp_path: Path) -> None:
    with read_only_dir(tmp_path / "ro") as ro:
        proc = subprocess.run(
            [os.path.join(os.path.dirname(os.sys.executable), "drillcosim"), "run", "--out",
             str(ro), "--stop-time", "0.01", "--no-plots", "--no-progress"],
            capture_output=True, text=True, timeout=600, cwd=tmp_path)
        assert proc.returncode == 2 and "Traceback" not in proc.stderr, proc.stderr
        assert len(proc.stderr.strip().splitlines()) == 1


def test_cli_run_disk_full_while_writing_summary_gives_one_line(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys) -> None:
    from drillcosim.cosim.cli import main

    def full(*args, **kwargs):
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC), str(tmp_path / "summary.json"))

    monkeypatch.setattr(result_module, "write_json", full)
    code = None
    with contextlib.suppress(OSError):
        code = main(["run", "--out", str(tmp_path / "out"), "--stop-time", "0.01",
                     "--no-plots", "--no-progress"])
    err = capsys.readouterr().err
    assert code in (1, 2) and len(err.strip().splitlines()) == 1, err
    assert "No space left on device" in err
