"""The paper study's stages, as ``drillcosim calibrate STAGE`` runs them: the calibration
(:mod:`.calibration`: coarse, refine, confirm), the paper's experiments (:mod:`.experiments`),
its conclusion (:mod:`.conclusion`) and the reports (:mod:`.calibration_report`,
:mod:`.conclusion_report`)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from drillcosim.cosim.master.errors import UserError

from .calibration import STAGES, run_stage
from .calibration_report import ranking_markdown, report
from .conclusion import run_conclusion
from .conclusion_report import report as conclusion_report
from .experiments import comparison_rows, markdown_table, run_experiments

__all__ = ["calibrate"]


def calibrate(stage: str, out_dir: str | Path = "out/calibration", *,
              members: int | None = None, workers: int | None = None, scheduler: Any = None,
              progress: bool | None = None, figures: str | Path | None = None) -> str:
    """Run a stage (or the report) of the study in ``out_dir``; returns the text to print.

    Parameters
    ----------
    stage : {"coarse", "refine", "confirm", "all", "experiments", "conclusion", "report"}
    out_dir : path-like
        Study folder: ``coarse/``, ``refine/``, ``confirm/``, ``experiments/``,
        ``conclusion/`` tables (``conclusion``: :mod:`.conclusion`, the sites per
        span x gain x delay study on the calibrated closed loop, and its maps).
    members : int, optional
        Ensemble members per set (default: the stage's).
    workers, scheduler, progress
        As for :func:`cosim.study.sweep.execute_sweep`.
    figures : path-like, optional
        ``report``: output folder (default ``out_dir/report``).
    """
    out = Path(out_dir)
    if stage in (*STAGES, "all"):
        text = []
        for st in (STAGES if stage == "all" else (stage,)):
            ranked = run_stage(st, out, members=members, workers=workers, scheduler=scheduler,
                               progress=progress)
            text += [f"{st}: {len(ranked)} sets in {out / st}; best first:",
                     ranking_markdown(ranked, 5)]
        return "\n".join(text)
    if stage == "experiments":
        rows = run_experiments(out / "experiments", 6 if members is None else members,
                               workers=workers, scheduler=scheduler, progress=progress)
        return markdown_table(comparison_rows(rows))
    if stage == "conclusion":
        run_conclusion(out / "conclusion", workers=workers, scheduler=scheduler,
                       progress=progress)
        return conclusion_report(out / "conclusion", figures)
    if stage == "report":
        return report(out, figures)
    raise UserError(f"stage = {stage!r}: one of {', '.join((*STAGES, 'all', 'experiments'))}"
                     ", conclusion, report")
