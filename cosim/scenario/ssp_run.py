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

The scene-specific summary and plots of :func:`cosim.scenario.run.simulate_system` need a
scene and are not written.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

from drillcosim.cosim.master.ssp import SspExport, export_ssp, unsupported_features
from drillcosim.cosim.master.ssp_import import read_ssp
from drillcosim.cosim.master.system import integer_multiple

from .run import (
    EXIT_DIVERGED,
    EXIT_OK,
    SceneOutcome,
    scene_system_from_options,
    seconds_text,
    simulate_into,
)

__all__ = ["SspWarning", "WrittenSsp", "simulate_ssp", "write_scene_ssp"]


class SspWarning(UserWarning):
    """Something in an SSP file applied differently than written (e.g. an ignored parameter)."""


def simulate_ssp(path: str | Path, *, stop_time: float | None = None, step: float | None = None,
            out_dir: str | Path | None = None, output_interval: float | None = None,
            progress: bool | None = None) -> SceneOutcome:
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
    SceneOutcome
        ``exit_code`` 1 if the run stopped early (divergence or an FMU failure).

    Raises
    ------
    ValueError
        Unsupported SSP content or bad options, one line (nothing is written).
    CosimError
        The run failed before its first step (earlier files are kept).

    Warns
    -----
    SspWarning
        One per note of the import (e.g. a parameter that names no variable: ignored).
    """
    from .summary import write_json

    for name, value in (("stop time", stop_time), ("step", step)):
        if value is not None and not (math.isfinite(value) and value > 0):
            raise ValueError(f"{name}: a finite number > 0 [s], got {value!r}")
    with read_ssp(path, step=step, stop_time=stop_time) as imp:
        for note in imp.notes:
            warnings.warn(SspWarning(f"{Path(path).name}: {note}"), stacklevel=2)
        system = imp.system
        stop = system.stop_time
        if stop is None:
            raise ValueError(f"{Path(path).name}: no stop time (DefaultExperiment has no "
                             "stopTime): give one (--stop-time S)")
        out = Path(out_dir) if out_dir is not None else Path("out") / imp.name
        out.mkdir(parents=True, exist_ok=True)
        ticks = 1 if output_interval is None else integer_multiple(output_interval,
                                                                    system.base_step)
        if ticks is None:
            raise ValueError(f"output interval: a positive integer multiple of the step "
                             f"{system.base_step:g} s, got {output_interval!r} s")
        result, failure, csv = simulate_into(system, imp.outputs, ticks, stop, out, progress)
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
        return SceneOutcome(EXIT_DIVERGED, f"run stopped at t = {result.end_time:.6g} s of "
                            f"{stop:g} s: {failure['message']}; partial results in {out}",
                            out, summary, files)
    return SceneOutcome(EXIT_OK, f"{imp.name}: {result.end_time:g} s simulated in "
                        f"{seconds_text(result.wall_time)} s (real-time factor "
                        f"{result.real_time_factor:.3g}); results.csv, summary.json in {out}",
                        out, summary, files)


@dataclass(frozen=True)
class WrittenSsp:
    """What :func:`write_scene_ssp` wrote: the export and the scene's name."""

    export: SspExport
    scene: str


def write_scene_ssp(scene: str, out: str | Path | None = None, *, step: float | None = None,
                    stop_time: float | None = None, sets: Sequence[str] = (),
                    fmu_dir: str | Path | None = None, plant_fmu: str | Path | None = None,
                    controller_fmu: str | Path | None = None,
                    omit_unsupported: bool = False) -> WrittenSsp:
    """Write a scene's system (FMUs included) as an SSP 1.0 archive.

    Parameters
    ----------
    scene : str
        Scene name or file.
    out : path-like, optional
        ``.ssp`` file (default ``out/<scene>.ssp``).
    step, stop_time, sets, fmu_dir, plant_fmu, controller_fmu :
        As for ``drillcosim run`` (:func:`cosim.scenario.run.scene_system_from_options`).
    omit_unsupported : bool
        Write a system with delays, linear coupling or Gauss-Seidel stepping without them
        (listed in :attr:`SspExport.omitted`); refused otherwise.

    Returns
    -------
    WrittenSsp

    Raises
    ------
    ValueError
        Bad scene input, or features SSP 1.0 cannot hold without ``omit_unsupported``.
    """
    ss = scene_system_from_options(scene, step=step, stop_time=stop_time, sets=sets,
                                   fmu_dir=fmu_dir, plant_fmu=plant_fmu,
                                   controller_fmu=controller_fmu)
    target = Path(out) if out is not None else Path("out") / f"{ss.scene.name}.ssp"
    omitted = unsupported_features(ss.system)
    if omitted and not omit_unsupported:
        more = f" (and {len(omitted) - 1} more)" if len(omitted) > 1 else ""
        raise ValueError(f"{ss.scene.source}: SSP 1.0 cannot hold {omitted[0]}{more}; set "
                         "cosim.algorithm='jacobi' and zero delays, or write it without them "
                         "(--omit-unsupported)")
    exp = export_ssp(ss.system, target, name=ss.scene.name, strict=False)
    return WrittenSsp(exp, ss.scene.name)
