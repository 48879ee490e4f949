"""The paper's experiments (section 4, Figs. 9-16) point by point: today's scenes and the
calibrated ones, as ensembles.

:data:`EXPERIMENTS` lists each experiment's scene pair (``paper_<x>`` and
``paper_calibrated_<x>``, the latter extending the former with the calibrated plant of
:mod:`cosim.study.paper.calibration`). :func:`run_experiments` runs ``members`` ensemble members of
each (member 0 unperturbed: the numbers of ``drillcosim run <scene>``) through the sweep
executors into a :class:`~cosim.study.scene_stats.SceneTable`; :func:`comparison_rows` reduces
them to the paper's quantities, each next to the paper's value, as ensemble mean +- standard
deviation over the members and the value of member 0.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from ..ensemble import ensemble_stat
from ..scene_stats import ScenePoint, SceneTable, aggregate, measure_scene
from ..sweep import execute_points

__all__ = ["EXPERIMENTS", "FAMILIES", "Experiment", "comparison_rows", "experiment_points",
           "markdown_table", "run_experiments"]

#: Scene families: today's scenes and the calibrated ones.
FAMILIES = ("today", "calibrated")


@dataclass(frozen=True)
class Experiment:
    """One of the paper's experiments.

    Attributes
    ----------
    name : str
        Scene suffix: ``paper_<name>`` and ``paper_calibrated_<name>``.
    figures : str
        The paper's figures.
    stop_time : float
        [s] (the scene's).
    """

    name: str
    figures: str
    stop_time: float

    def scene(self, family: str) -> str:
        """The scene of a family (:data:`FAMILIES`)."""
        if family not in FAMILIES:
            raise ValueError(f"family = {family!r}: one of {', '.join(FAMILIES)}")
        return f"paper_{self.name}" if family == "today" else f"paper_calibrated_{self.name}"


EXPERIMENTS = (
    Experiment("open_loop", "Figs. 9-10, 11 upper", 30.0),
    Experiment("closed_loop", "Figs. 11 middle, 12", 30.0),
    Experiment("restricted_actuator", "Figs. 11 lower, 13", 30.0),
    Experiment("switch_on_25s", "Fig. 14", 40.0),
    Experiment("severe", "Figs. 15-16", 40.0),
)


def experiment_points(members: int, families: Sequence[str] = FAMILIES,
                      experiments: Sequence[Experiment] = EXPERIMENTS, *, eps: float = 1e-6,
                      seed: int = 2024) -> list[ScenePoint]:
    """Members 0..members-1 of every experiment and family; group ``<name>/<family>``."""
    if members < 1:
        raise ValueError(f"members = {members!r}: >= 1")
    return [ScenePoint(e.scene(f), f"{e.name}/{f}", e.stop_time, "", k, float(eps), int(seed))
            for e in experiments for f in families for k in range(members)]


def run_experiments(out_dir: str | Path, members: int = 6, *, workers: int | None = None,
                    scheduler: Any = None, progress: bool | None = None,
                    families: Sequence[str] = FAMILIES) -> list[dict[str, Any]]:
    """Run (or resume) every experiment's ensemble into ``out_dir``; returns the table rows."""
    points = experiment_points(members, families)
    table = SceneTable(out_dir)
    meta = {"members": members, "families": list(families),
            "experiments": [{"name": e.name, "figures": e.figures, "stop_time_s": e.stop_time,
                             "scenes": [e.scene(f) for f in families]} for e in EXPERIMENTS]}
    execute_points(points, table, measure_scene, workers=workers, scheduler=scheduler,
                   progress=progress, desc="experiments", meta={"experiments.json": meta})
    keys = {p.key for p in points}
    return [r for r in table.rows if r["key"] in keys]


@dataclass(frozen=True)
class Quantity:
    """A row of the comparison.

    Attributes
    ----------
    label, unit : str
    column : str
        Column of the table.
    scale : float
        Table unit -> ``unit``.
    paper : str
        The paper's statement ("" when it states nothing).
    ratio_to : str
        If set, the quantity is ``column / ratio_to``: per member within the same run when
        ``reference`` is empty (e.g. after / before the switch-on), else the ratio of the
        ensemble means of this experiment and the ``reference`` experiment (same family).
    reference : str
        Experiment name of the denominator (see ``ratio_to``).
    """

    label: str
    column: str
    scale: float
    unit: str
    paper: str
    ratio_to: str = ""
    reference: str = ""


MM, KN = 1e3, 1e-3
_SPAN = (
    Quantity("long span peak", "long_peak_m", MM, "mm", ""),
    Quantity("long span steady mean", "long_mean_m", MM, "mm", ""),
    Quantity("long span steady std", "long_std_m", MM, "mm", ""),
    Quantity("long span steady p05-p95 half-band", "long_band_m", MM, "mm", ""),
    Quantity("long span contact time", "long_contact_time_s", 1.0, "s", ""),
    Quantity("short span peak", "short_peak_m", MM, "mm", ""),
    Quantity("short span steady mean", "short_mean_m", MM, "mm", ""),
    Quantity("short span steady std", "short_std_m", MM, "mm", ""),
    Quantity("short span contact time", "short_contact_time_s", 1.0, "s", ""),
)
_ACT = (
    Quantity("site 1 peak force", "site1_peak_force_N", KN, "kN", ""),
    Quantity("site 1 peak power", "site1_peak_abs_power_W", 1.0, "W", ""),
    Quantity("site 1 steady mean power", "site1_mean_power_W", 1.0, "W", ""),
    Quantity("site 1 steady strain rms", "site1_strain_rms", 1e6, "ustrain", ""),
    Quantity("site 2 peak force", "site2_peak_force_N", KN, "kN", ""),
    Quantity("site 2 peak power", "site2_peak_abs_power_W", 1.0, "W", ""),
)
_BEFORE = (
    Quantity("long span mean before switch-on", "long_before_mean_m", MM, "mm", ""),
    Quantity("long span std before switch-on", "long_before_std_m", MM, "mm", ""),
    Quantity("short span mean before switch-on", "short_before_mean_m", MM, "mm", ""),
    Quantity("site 1 strain rms before switch-on", "site1_before_strain_rms", 1e6, "ustrain",
             ""),
)


def _with_paper(qs: Iterable[Quantity], paper: Mapping[str, str]) -> tuple[Quantity, ...]:
    return tuple(Quantity(q.label, q.column, q.scale, q.unit,
                          paper.get(f"{q.column}/{q.ratio_to}" if q.ratio_to else q.column, ""),
                          q.ratio_to, q.reference) for q in qs)


def _vs(reference: str) -> tuple[Quantity, ...]:
    return (Quantity(f"long span steady mean / {reference}'s", "long_mean_m", 1.0, "1", "",
                     "long_mean_m", reference),
            Quantity(f"long span contact time / {reference}'s", "long_contact_time_s", 1.0,
                     "1", "", "long_contact_time_s", reference))


_AFTER_BEFORE = (
    Quantity("long span steady mean after / before", "long_mean_m", 1.0, "1", "",
             "long_before_mean_m"),
    Quantity("short span steady mean after / before", "short_mean_m", 1.0, "1", "",
             "short_before_mean_m"),
    Quantity("site 1 strain rms after / before", "site1_strain_rms", 1.0, "1", "",
             "site1_before_strain_rms"),
)


#: Per experiment: the quantities and the paper's statement about each (empty: not stated).
QUANTITIES: dict[str, tuple[Quantity, ...]] = {
    "open_loop": _with_paper(_SPAN, {
        "long_peak_m": "~15 mm (Fig. 11 upper)", "long_mean_m": "~8 mm",
        "long_band_m": "+/- 5 mm", "long_contact_time_s": "> 0 ('contact eventually occurs')",
        "short_mean_m": "smaller than the long span (Fig. 10, 14)",
        "short_contact_time_s": "0 (contact at the long span)"}),
    "closed_loop": _with_paper((*_SPAN, *_vs("open_loop"), *_ACT), {
        "long_mean_m/long_mean_m": "'significantly attenuates': well below 1",
        "long_peak_m": "below the open loop's", "site1_peak_force_N": "approaches 5 kN",
        "site1_peak_abs_power_W": "'low'; below the 400 W of Fig. 14",
        "site1_mean_power_W": "low"}),
    "restricted_actuator": _with_paper((*_SPAN, *_vs("closed_loop"), *_vs("open_loop"),
                                        *_ACT), {
        "long_mean_m/long_mean_m": "'less effective' than unrestricted: > 1 vs closed loop",
        "site1_peak_force_N": "<= 5 kN (compressive only)",
        "site1_peak_abs_power_W": "more than unrestricted",
        "site1_mean_power_W": "more than unrestricted"}),
    "switch_on_25s": _with_paper((*_BEFORE, *_SPAN, *_AFTER_BEFORE, *_ACT), {
        "long_mean_m/long_before_mean_m": "< 1 ('reduced')",
        "short_mean_m/short_before_mean_m": "slightly < 1; short span small",
        "site1_strain_rms/site1_before_strain_rms": "'dramatically reduced'",
        "site1_peak_force_N": "26 kN",
        "site1_peak_abs_power_W": "400 W"}),
    "severe": _with_paper((*_BEFORE, *_SPAN, *_AFTER_BEFORE, *_ACT), {
        "long_mean_m/long_before_mean_m": ">= 1 ('no reduction of vibration')",
        "long_contact_time_s": "repeated, prolonged wall contact",
        "short_contact_time_s": "repeated, prolonged wall contact",
        "site1_strain_rms/site1_before_strain_rms": "< 1 ('despite reduction of strain')"}),
}


def _value(q: Quantity, group: str, family: str, agg: Mapping[str, Mapping[str, Any]],
           rows: Sequence[Mapping[str, Any]]) -> dict[str, Any]:
    """mean, sd, member-0 value and member counts of a quantity in one group."""
    a = agg.get(group, {})
    ok = sorted((r for r in rows if r["group"] == group and r["status"] == "ok"),
                key=lambda r: r["member"])
    m0 = ok[0] if ok and ok[0]["member"] == 0 else {}
    counts = {"completed": a.get("completed", 0), "members": a.get("members", 0)}
    if not q.ratio_to:
        return {"mean": a.get(q.column, math.nan) * q.scale,
                "sd": a.get(f"{q.column}_sd", math.nan) * q.scale,
                "member0": m0.get(q.column, math.nan) * q.scale, **counts}
    if not q.reference:       # within each run: per-member ratios
        e = ensemble_stat([_ratio(r[q.column], r[q.ratio_to]) for r in ok])
        return {"mean": e.mean, "sd": e.sd,
                "member0": _ratio(m0[q.column], m0[q.ratio_to]) if m0 else math.nan, **counts}
    ref_group = f"{q.reference}/{family}"
    ref = agg.get(ref_group, {})
    ref0 = [r for r in rows if r["group"] == ref_group and r["member"] == 0
            and r["status"] == "ok"]
    return {"mean": _ratio(a.get(q.column, math.nan), ref.get(q.ratio_to, math.nan)),
            "sd": math.nan,
            "member0": _ratio(m0[q.column], ref0[0][q.ratio_to]) if m0 and ref0 else math.nan,
            **counts}


def _ratio(a: float, b: float) -> float:
    return a / b if math.isfinite(a) and math.isfinite(b) and b != 0 else math.nan


def comparison_rows(rows: Iterable[Mapping[str, Any]],
                    experiments: Sequence[Experiment] = EXPERIMENTS,
                    families: Sequence[str] = FAMILIES) -> list[dict[str, Any]]:
    """One dict per (experiment, quantity): the paper's statement and per family the ensemble
    mean, standard deviation, member-0 value and completed/total members (scaled units).

    A ratio across experiments is the ratio of the ensemble means (sd not given); within a
    run (after / before the switch-on) the mean and sd of the members' ratios. The result
    depends on the set of rows, not their order.
    """
    rows = list(rows)
    agg = {a["group"]: a for a in aggregate(rows)}
    out = []
    for e in experiments:
        for q in QUANTITIES[e.name]:
            d: dict[str, Any] = {"experiment": e.name, "figures": e.figures,
                                 "quantity": q.label, "unit": q.unit, "paper": q.paper,
                                 "column": q.column}
            for f in families:
                d[f] = _value(q, f"{e.name}/{f}", f, agg, rows)
            out.append(d)
    return out


def _fmt(x: float) -> str:
    if not math.isfinite(x):
        return "-"
    a = abs(x)
    if a >= 100:
        return f"{x:.0f}"
    if a >= 10:
        return f"{x:.1f}"
    return f"{x:.2f}" if a >= 0.1 or a == 0 else f"{x:.2g}"


def markdown_table(comparison: Sequence[Mapping[str, Any]],
                   families: Sequence[str] = FAMILIES) -> str:
    """The comparison as one markdown table per experiment (mean +- sd [member 0])."""
    lines: list[str] = []
    current = None
    for d in comparison:
        if d["experiment"] != current:
            current = d["experiment"]
            first = d[families[0]]
            lines += ["", f"**{current}** ({d['figures']}; ensemble of "
                          f"{first['members']} members, mean +- sd [member 0])", "",
                      "| quantity | paper | " + " | ".join(families) + " |",
                      "|---|---|" + "---|" * len(families)]
        cells = []
        for f in families:
            v = d[f]
            done = "" if v["completed"] == v["members"] else \
                f" ({v['completed']}/{v['members']} completed)"
            cells.append(f"{_fmt(v['mean'])} +- {_fmt(v['sd'])} [{_fmt(v['member0'])}]{done}")
        lines.append(f"| {d['quantity']} [{d['unit']}] | {d['paper'] or ''} | "
                     + " | ".join(cells) + " |")
    return "\n".join(lines).lstrip("\n") + "\n"
