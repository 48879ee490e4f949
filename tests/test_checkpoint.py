"""Checkpoints of whole runs: 0 -> t1, save, resume t1 -> t2 equals 0 -> t2 bit for bit (FMU and
in-process engines, delayed connections, a controller sampled slower than the plant); a
checkpoint of another scene, settings, FMU build or version, or a damaged one, is refused with
one line (API and CLI, exit 2); reading one runs no code from it."""

from __future__ import annotations

import ast
import dataclasses
from pathlib import Path

import numpy as np
import pytest

import drillcosim
from drillcosim.cosim.cli import main
from drillcosim.cosim.master.checkpoint import Checkpoint, CheckpointError

# sensor and actuator delays that are not multiples of the controller's period (interpolated
# lines), the controller stepping every 4 plant steps (multirate)
SETTINGS = {"cosim.actuator_delay": 1.1e-3, "cosim.sensor_delay": 2.5e-4,
            "cosim.controller_sample_period": 1e-3}
T1, T2 = 0.15, 0.3


def _run(engine: str, fmu_dir: Path | None, stop: float, **kw) -> drillcosim.Result:
    return drillcosim.simulate("paper_closed_loop", stop_time=stop, overrides=SETTINGS,
                               engine=engine, fmu_dir=fmu_dir, **kw)


@pytest.fixture(params=["fmu", "inprocess"])
def engine(request, project_fmus) -> tuple[str, Path | None]:
    return request.param, (project_fmus["DrillstringPlant"].parent
                           if request.param == "fmu" else None)


def test_resume_equals_straight_run_bit_for_bit(engine, tmp_path) -> None:
    name, fmu_dir = engine
    straight = _run(name, fmu_dir, T2).to_pandas()
    first = _run(name, fmu_dir, T1, save_state=tmp_path / "t1.ckpt")
    resumed = _run(name, fmu_dir, T2, from_state=tmp_path / "t1.ckpt").to_pandas()
    assert first.completed
    tail = straight[straight.index >= T1 - 1e-12]
    assert len(resumed) == len(tail) > 100
    assert np.array_equal(resumed.index.to_numpy(), tail.index.to_numpy())
    for column in tail.columns:   # bit for bit, every recorded output
        a, b = tail[column].to_numpy(), resumed[column].to_numpy()
        assert np.array_equal(a.view(np.int64), b.view(np.int64)), column
    # the controller acted before t1 (the state restored is not a trivial one)
    force = [c for c in tail.columns if c.startswith("controller.actuator")]
    assert force and np.abs(tail[force].to_numpy()).max() > 0


def _refusal(tmp_path: Path, fmu_dir, edit=None, **run) -> str:
    path = tmp_path / "t1.ckpt"
    _run("fmu", fmu_dir, T1, save_state=path)
    if edit is not None:
        path.write_bytes(edit(path.read_bytes()))
    with pytest.raises(CheckpointError) as info:
        drillcosim.simulate("paper_closed_loop", stop_time=T2, fmu_dir=fmu_dir,
                            from_state=path, **{"overrides": SETTINGS, **run})
    text = str(info.value)
    assert "\n" not in text
    return text


def _rewritten(**change):
    """A checkpoint as another build or version would have written it (checksums valid)."""
    def edit(data: bytes) -> bytes:
        cp = Checkpoint.from_bytes(data)
        if "slave_identity" in change:
            slaves = tuple(dataclasses.replace(s, identity={**s.identity,
                                                            **change["slave_identity"]})
                           if s.name == "controller" else s for s in cp.slaves)
            cp = dataclasses.replace(cp, slaves=slaves)
        if "identity" in change:
            cp = dataclasses.replace(cp, identity={**cp.identity, **change["identity"]})
        return cp.to_bytes()
    return edit


def test_checkpoint_of_another_run_is_refused(project_fmus, tmp_path) -> None:
    fmu_dir = project_fmus["DrillstringPlant"].parent
    assert "another scene" in _refusal(tmp_path, fmu_dir, _rewritten(
        identity={"scene": "paper_open_loop"}))
    assert "another settings" in _refusal(tmp_path, fmu_dir, overrides={
        **SETTINGS, "controller.gain": 2e8})
    assert "another drillcosim version" in _refusal(tmp_path, fmu_dir, _rewritten(
        identity={"drillcosim": "0.0.1"}))
    text = _refusal(tmp_path, fmu_dir, _rewritten(slave_identity={"fmu_sha256": "0" * 64}))
    assert "'controller'" in text and "fmu_sha256" in text


def test_checkpoint_of_another_fmu_is_refused(project_fmus, c_controller_fmu, tmp_path) -> None:
    """Saved with the Python controller FMU, resumed with the C one: refused by its identity."""
    text = _refusal(tmp_path, project_fmus["DrillstringPlant"].parent,
                    controller_fmu=c_controller_fmu)
    assert "another build" in text


def _flip(offset: int):
    def edit(data: bytes) -> bytes:
        b = bytearray(data)
        b[offset % len(b)] ^= 0x01
        return bytes(b)
    return edit


def _inside_state(data: bytes) -> bytes:
    """One byte of the plant's FMU state changed, the file's checksums made valid again: the
    FMU's own SHA-256 refuses it."""
    cp = Checkpoint.from_bytes(data)
    s = cp.slaves[0]
    blob = bytearray(s.state)
    blob[len(blob) // 2] ^= 0x10
    slaves = (dataclasses.replace(s, state=bytes(blob)), *cp.slaves[1:])
    return dataclasses.replace(cp, slaves=slaves).to_bytes()


@pytest.mark.parametrize(("edit", "expected"), [
    (lambda d: d[:len(d) // 2], "damaged: its SHA-256"),
    (_flip(100), "damaged: its SHA-256"),
    (_flip(-1), "damaged: its SHA-256"),
    (lambda d: b"PK\x03\x04" + d[4:], "not a drillcosim checkpoint"),
    (lambda d: b"", "not a drillcosim checkpoint"),
    (_inside_state, "refused it"),
], ids=["truncated", "flipped-manifest", "flipped-digest", "other-file", "empty", "fmu-state"])
def test_damaged_checkpoint_is_refused(project_fmus, tmp_path, edit, expected) -> None:
    assert expected in _refusal(tmp_path, project_fmus["DrillstringPlant"].parent, edit)


def test_cli_bad_checkpoint_exits_2_one_line(project_fmus, tmp_path, capsys) -> None:
    fmu_dir = str(project_fmus["DrillstringPlant"].parent)
    common = ["--no-plots", "--no-progress", "--fmu-dir", fmu_dir]
    path = tmp_path / "a.ckpt"
    assert main(["run", "paper_closed_loop", "--stop-time", str(T1), "--out",
                 str(tmp_path / "a"), "--save-state", str(path), *common]) == 0
    assert "checkpoint at 0.15 s" in capsys.readouterr().out
    path.write_bytes(path.read_bytes()[:-1])
    out = tmp_path / "b"
    code = main(["run", "paper_closed_loop", "--stop-time", str(T2), "--out", str(out),
                 "--from-state", str(path), *common])
    err = capsys.readouterr().err
    assert code == 2, err
    assert err.startswith("drillcosim run: error: checkpoint") and err.count("\n") == 1, err
    assert not (out / "results.csv").exists()


def test_loading_runs_no_code() -> None:
    """The reading modules import no deserializer that runs code (pickle, marshal, shelve,
    dill) and call no eval/exec: a checkpoint is JSON and bytes."""
    import importlib

    for rel in ("cosim.master.checkpoint", "cosim.master.state_codec", "cosim.master.resume",
                "cosim.scenario.checkpoints"):
        module = importlib.import_module(f"drillcosim.{rel}")
        tree = ast.parse(Path(module.__file__).read_text())
        names = {a.name.split(".")[0] for n in ast.walk(tree)
                 if isinstance(n, (ast.Import, ast.ImportFrom)) for a in n.names}
        names |= {n.module.split(".")[0] for n in ast.walk(tree)
                  if isinstance(n, ast.ImportFrom) and n.module}
        assert not names & {"pickle", "marshal", "shelve", "dill", "cloudpickle"}, rel
        calls = {n.func.id for n in ast.walk(tree) if isinstance(n, ast.Call)
                 and isinstance(n.func, ast.Name)}
        assert not calls & {"eval", "exec", "compile", "__import__"}, rel
