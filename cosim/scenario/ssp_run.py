"""SSP files from the command line: run one (``drillcosim run X.ssp``), write a scene's
(``drillcosim ssp SCENE --out X.ssp``).

:func:`simulate_ssp` imports an SSP 1.0 system (:mod:`cosim.master.ssp_import`), runs it with our
master (Jacobi, zero-order hold, the SSP's base step and component periods) and writes into
the output folder (default ``out/<system name>``)

* ``results.csv`` - every Real output of every component at every ``output_interval``
  (default: every base step), header ``time,<instance>.<variable>,...`` (streamed, moved into
  place atomically);
* ``summary.json`` - the file, system, base step [s], stop time [s], time reached [s], wall
  time [s], real-time factor, the components (file, period [s], start values) and the
  divergence (time, quantity, value) if the run stopped early.

The scene-specific summary and plots (:class:`cosim.scenario.result.Result`) need a scene and
are not written.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass
from pathlib import Path

from drillcosim.cosim.master.ssp import SspExport, export_ssp, unsupported_features
from drillcosim.cosim.master.ssp_import import read_ssp
from drillcosim.cosim.master.timegrid import integer_multiple

from .build import build_system
from .config import ConfigError, SceneConfig
from .result import seconds_text
from .simulate import simulate_system
from .summary import write_json

__all__ = ["SspOutcome", "SspWarning", "WrittenSsp", "simulate_ssp", "write_scene_ssp"]


@dataclass(frozen=True)
class SspOutcome:
    """What :func:`simulate_ssp` produced.

    Attributes
    ----------
    completed : bool
        False if the run stopped early (divergence or an FMU failure).
    message : str
        One line: where the files are, or why the run stopped.
    out_dir : Path
    summary : dict
        The content of ``summary.json``.
    files : tuple of Path
    """

    completed: bool
    message: str
    out_dir: Path
    summary: dict
    files: tuple[Path, ...]


class SspWarning(UserWarning):
    """Something in an SSP file applied differently than written (e.g. an ignored parameter)."""


def simulate_ssp(path: str | Path, *, stop_time: float | None = None, step: float | None = None,
            out_dir: str | Path | None = None, output_interval: float | None = None,
            progress: bool | None = None) -> SspOutcome:
    """Run an SSP 1.0 file and write ``results.csv`` and ``summary.json``.

    Parameters
    ----------
    path : path-like
        ``.ssp`` archive, unpacked SSP folder or ``.ssd`` file.
    stop_time : float, optional
        [s]; default: the SSP's ``DefaultExperiment stopTime`` (one of them is required).
    step : float, optional
        Base step [s]; default: the SSP's ``osp:FixedStepAlgorithm baseStepSize`` (one of
        them is required).
    out_dir : path-like, optional
        Default ``out/<system name>``.
    output_interval : float, optional
        Recording interval [s], a multiple of the base step (default: every base step).
    progress : bool or None
        Progress bar (None: only on a TTY).

    Returns
    -------
    SspOutcome

    Raises
    ------
    UserError
        Unsupported SSP content or bad options, one line (nothing is written).
    CosimError
        The run failed before its first step (earlier files are kept).

    Warns
    -----
    SspWarning
        One per note of the import (e.g. a parameter that names no variable: ignored).
    """
    for name, value in (("stop time", stop_time), ("step", step)):
        if value is not None and not (math.isfinite(value) and value > 0):
            raise ConfigError(f"{name}: a finite number > 0 [s], got {value!r}")
    with read_ssp(path, step=step, stop_time=stop_time) as imp:
        for note in imp.notes:
            warnings.warn(SspWarning(f"{Path(path).name}: {note}"), stacklevel=2)
        system = imp.system
        stop = system.stop_time
        if stop is None:
            raise ConfigError(f"{Path(path).name}: no stop time (DefaultExperiment has no "
                             "stopTime): give one (--stop-time S)")
        out = Path(out_dir) if out_dir is not None else Path("out") / imp.name
        out.mkdir(parents=True, exist_ok=True)
        ticks = 1 if output_interval is None else integer_multiple(output_interval,
                                                                    system.base_step)
        if ticks is None:
            raise ConfigError(f"output interval: a positive integer multiple of the step "
                             f"{system.base_step:g} s, got {output_interval!r} s")
        csv = out / "results.csv"
        result, failure = simulate_system(system, None, imp.outputs, ticks, stop, progress=progress,
                                     csv_path=csv)
        summary = {
            "ssp_file": str(Path(path).resolve()), "system": imp.name,
            "step_s": system.base_step, "stop_time_s": stop, "end_time_s": result.end_time,
            "wall_time_s": result.wall_time, "real_time_factor": result.real_time_factor,
            "algorithm": "jacobi (zero-order hold, no delays)",
            "components": {f.name: {"fmu": Path(f.path).name,
                                    "period_s": f.sample_period_ticks * system.base_step,
                                    "start_values": dict(f.parameters)} for f in system.fmus},
            "connections": [f"{c.source} -> {c.target}" for c in system.connections],
            "notes": list(imp.notes), "diverged": failure,
        }
    files = (csv, write_json(summary, out / "summary.json"))
    if failure is not None:
        return SspOutcome(False, f"run stopped at t = {result.end_time:.6g} s of "
                            f"{stop:g} s: {failure['message']}; partial results in {out}",
                            out, summary, files)
    return SspOutcome(True, f"{imp.name}: {result.end_time:g} s simulated in "
                        f"{seconds_text(result.wall_time)} s (real-time factor "
                        f"{result.real_time_factor:.3g}); results.csv, summary.json in {out}",
                        out, summary, files)


@dataclass(frozen=True)
class WrittenSsp:
    """What :func:`write_scene_ssp` wrote: the export and the scene's name."""

    export: SspExport
    scene: str


def write_scene_ssp(config: SceneConfig, out: str | Path | None = None, *,
                    fmu_dir: str | Path | None = None,
                    omit_unsupported: bool = False) -> WrittenSsp:
    """Write a configuration's system (its FMUs included) as an SSP 1.0 archive.

    Parameters
    ----------
    config : SceneConfig
        From :func:`.config.load_config` (overrides, FMU files of the user applied).
    out : path-like, optional
        ``.ssp`` file (default ``out/<scene>.ssp``).
    fmu_dir : path-like, optional
        Folder of the project's FMUs (:func:`.build.build_system`).
    omit_unsupported : bool
        Write a system with delays, linear coupling or Gauss-Seidel stepping without them
        (listed in :attr:`SspExport.omitted`); refused otherwise.

    Returns
    -------
    WrittenSsp

    Raises
    ------
    UserError
        Features SSP 1.0 cannot hold without ``omit_unsupported``, or FMUs that do not fit.
    """
    built = build_system(config, "fmu", fmu_dir=fmu_dir)
    target = Path(out) if out is not None else Path("out") / f"{config.name}.ssp"
    omitted = unsupported_features(built.system)
    if omitted and not omit_unsupported:
        more = f" (and {len(omitted) - 1} more)" if len(omitted) > 1 else ""
        raise ConfigError(f"{config.source}: SSP 1.0 cannot hold {omitted[0]}{more}; set "
                          "cosim.algorithm='jacobi' and zero delays, or write it without them "
                          "(--omit-unsupported)")
    exp = export_ssp(built.system, target, name=config.name, strict=False)
    return WrittenSsp(exp, config.name)
