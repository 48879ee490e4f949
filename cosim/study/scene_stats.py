"""Scene statistics of ensemble members: the paper's quantities per run, in a results table.

One point (:class:`ScenePoint`) is one run of a scene with overrides, started from the
initial state plus the perturbation of an ensemble member
(:func:`cosim.study.ensemble.lateral_perturbation`; member 0 is unperturbed, i.e. the run
``drillcosim run`` makes). :func:`measure_scene` runs it through the one builder and master
call (:func:`cosim.study.point.simulate_point`, in-process slaves by default: the FMUs'
numbers bit for bit) and reduces it with :func:`cosim.scenario.summary.summarize` to flat columns
(:data:`STAT_COLUMNS`); the points run through the sweep executors
(:func:`cosim.study.sweep.execute_points`: local process pool, Dask, or inline) into a
:class:`SceneTable` (resumable; its content does not depend on the order the points
finished in). :func:`aggregate` reduces the members of each group to mean, standard
deviation and standard error, sorted by group.

Windows (those of ``summary.json``): *steady* is the last third of the recorded run; *before*
is the last third of the time before the controller's switch-on (switch-on scenes only).
Columns per span (``long``: the longest span's contact body, ``short``: the other):

``<span>_peak_m``, ``<span>_mean_m``, ``<span>_std_m``, ``<span>_p05_m``, ``<span>_p95_m``,
``<span>_band_m``
    peak radial deflection over the run; mean, standard deviation, 5th and 95th percentile
    over the steady window, and the half-width of that band, (p95 - p05) / 2 [m];
``<span>_contact_time_s``, ``<span>_contact_events``, ``<span>_peak_contact_force_N``,
``<span>_first_contact_s``
    time in contact, entries into contact, peak contact force, first contact (NaN: none);
``<span>_before_peak_m``, ``<span>_before_mean_m``, ``<span>_before_std_m``
    the same before the switch-on (NaN without one).

Per actuator site ``site<k>`` (k = 1 long span, 2 short span): ``_peak_force_N`` (C and E),
``_peak_power_W`` (largest delivered power), ``_peak_abs_power_W``, ``_mean_power_W`` (steady
mean), ``_strain_rms`` (steady, gauges C and E), ``_before_strain_rms``, ``_peak_strain``.
"""

from __future__ import annotations

import json
import math
import time
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from drillcosim.cosim.scenario.config import SceneConfig, key_paths, load_config
from drillcosim.cosim.scenario.summary import span_info, summarize
from drillcosim.plant.model import DrillstringModel
from drillcosim.plant.signals import PLANT, body_signal, ref

from .ensemble import ensemble_stat, lateral_perturbation
from .point import PointOptions, simulate_point
from .table import ResultTable, full_row

__all__ = ["ID_COLUMNS", "STAT_COLUMNS", "SPAN_STATS", "SITE_STATS", "ScenePoint", "SceneTable",
           "aggregate", "measure_scene", "simulate_member", "run_statistics"]

SPANS = ("long", "short")
SITES = (1, 2)
SPAN_STATS = ("peak_m", "mean_m", "std_m", "p05_m", "p95_m", "band_m", "contact_time_s",
              "contact_events", "peak_contact_force_N", "first_contact_s", "before_peak_m",
              "before_mean_m", "before_std_m")
SITE_STATS = ("peak_force_N", "peak_power_W", "peak_abs_power_W", "mean_power_W",
              "strain_rms", "before_strain_rms", "peak_strain")
#: Identity columns of a row (:meth:`ScenePoint.identity`).
ID_COLUMNS = ("key", "group", "scene", "engine", "overrides", "member", "eps", "seed",
              "stop_time")
#: Measured columns (:func:`measure_scene`).
STAT_COLUMNS = ("status", "reason", "end_time", "wall_time",
                *(f"{s}_{q}" for s in SPANS for q in SPAN_STATS),
                *(f"site{k}_{q}" for k in SITES for q in SITE_STATS))
TEXT_COLUMNS = frozenset({"key", "group", "scene", "engine", "overrides", "status", "reason"})


@dataclass(frozen=True)
class ScenePoint:
    """One ensemble member of a scene with overrides.

    Attributes
    ----------
    scene : str
        Scene name or path.
    group : str
        What the member belongs to (a parameter set, an experiment); :func:`aggregate`
        groups by it.
    stop_time : float
        [s].
    overrides : str
        JSON of the scene keys by key path ("" for none), e.g.
        ``{"bit.weight_on_bit": 36000.0}``.
    member : int
        Ensemble member (0: unperturbed).
    eps : float
        Standard deviation of the lateral position perturbation [m].
    seed : int
        Perturbation seed.
    engine : {"inprocess", "fmu"}
        ``fmu`` runs member 0 only.
    tags : tuple of (str, float)
        Extra identity columns (e.g. the calibration's parameters).
    """

    scene: str
    group: str
    stop_time: float
    overrides: str = ""
    member: int = 0
    eps: float = 1e-6
    seed: int = 2024
    engine: str = "inprocess"
    tags: tuple[tuple[str, float], ...] = ()

    @property
    def key(self) -> str:
        """Identity in the table (group and tags are labels, not part of it)."""
        return (f"{self.scene}|{self.engine}|{self.stop_time:.12g}|{self.overrides}|"
                f"{self.member}|{self.eps:.6g}|{self.seed}")

    def kwargs(self) -> dict[str, Any]:
        """Keyword arguments of :func:`measure_scene`."""
        return {"scene": self.scene, "stop_time": self.stop_time, "engine": self.engine,
                "overrides": json.loads(self.overrides) if self.overrides else None,
                "member": self.member, "eps": self.eps, "seed": self.seed}

    def identity(self) -> dict[str, Any]:
        """Identity columns of the row (:data:`ID_COLUMNS` and the tags)."""
        return {"key": self.key, "group": self.group, "scene": self.scene,
                "engine": self.engine, "overrides": self.overrides,
                "member": float(self.member), "eps": self.eps, "seed": float(self.seed),
                "stop_time": self.stop_time, **dict(self.tags)}


class SceneTable(ResultTable):
    """Results table of :class:`ScenePoint` rows (no derived columns)."""

    columns = (*ID_COLUMNS, *STAT_COLUMNS)
    text_columns = TEXT_COLUMNS

    def derive(self, rows: Sequence[Mapping[str, Any]]) -> list[dict[str, Any]]:
        """Full rows (every column present)."""
        return [full_row(r, self.columns, self.text_columns) for r in rows]


def _window_percentiles(t: np.ndarray, r: np.ndarray, t0: float, t1: float
                        ) -> tuple[float, float]:
    sel = (t >= t0) & (t <= t1) & np.isfinite(r)
    if not np.any(sel):
        return math.nan, math.nan
    p05, p95 = np.percentile(r[sel], [5.0, 95.0])
    return float(p05), float(p95)


def run_statistics(data: np.ndarray, config: SceneConfig) -> dict[str, float]:
    """The columns of :data:`STAT_COLUMNS` (except status, reason, times) of one run.

    Parameters
    ----------
    data : numpy.ndarray
        The recorder's structured array (``time``, ``plant.*``, ``controller.*``).
    config : SceneConfig
        The run's configuration (spans, sites, switch-on time).

    Returns
    -------
    dict
        NaN where a quantity does not apply (no second span, no switch-on, no contact).
    """
    spans = span_info(config.scene)
    t = np.asarray(data["time"], dtype=float)
    on = config.switch_on_time
    switch = on if on is not None and len(t) and t[0] < on < t[-1] else None
    summ = summarize(data, spans=spans, n_sites=config.n_sites,
                     switch_on_time=switch)
    out: dict[str, float] = {f"{s}_{q}": math.nan for s in SPANS for q in SPAN_STATS}
    out.update({f"site{k}_{q}": math.nan for k in SITES for q in SITE_STATS})
    w0, w1 = summ["steady_window_s"]
    for body, info in spans.items():
        span = "long" if info["span"] == "only" else str(info["span"])
        e = summ["spans"].get(f"body{body}")
        if e is None or span not in SPANS:
            continue
        r = np.asarray(data[ref(PLANT, body_signal(body, "radial_deflection"))], dtype=float)
        p05, p95 = _window_percentiles(t, r, w0, w1)
        force = ref(PLANT, body_signal(body, "contact_force"))
        f = np.asarray(data[force], dtype=float) if force in (data.dtype.names or ()) else None
        first = float(t[np.argmax(f > 0)]) if f is not None and np.any(f > 0) else math.nan
        before = e.get("before_switch_on", {})
        out.update({f"{span}_peak_m": e["peak_radial_deflection_m"],
                    f"{span}_mean_m": e["steady_radial_deflection_mean_m"],
                    f"{span}_std_m": e["steady_radial_deflection_std_m"],
                    f"{span}_p05_m": p05, f"{span}_p95_m": p95,
                    f"{span}_band_m": 0.5 * (p95 - p05),
                    f"{span}_contact_time_s": e["contact_time_s"],
                    f"{span}_contact_events": float(e["contact_events"]),
                    f"{span}_peak_contact_force_N": e["peak_contact_force_N"],
                    f"{span}_first_contact_s": first,
                    f"{span}_before_peak_m": before.get("peak_radial_deflection_m", math.nan),
                    f"{span}_before_mean_m": before.get("steady_radial_deflection_mean_m",
                                                        math.nan),
                    f"{span}_before_std_m": before.get("steady_radial_deflection_std_m",
                                                       math.nan)})
    for k in SITES:
        a = summ["actuators"].get(f"site{k}")
        if a is None:
            continue
        out.update({f"site{k}_peak_force_N": a["peak_force_N"],
                    f"site{k}_peak_power_W": a["peak_power_W"],
                    f"site{k}_peak_abs_power_W": a["peak_abs_power_W"],
                    f"site{k}_mean_power_W": a["steady_mean_power_W"],
                    f"site{k}_strain_rms": a.get("steady_strain_rms", math.nan),
                    f"site{k}_before_strain_rms": a.get("before_switch_on_strain_rms", math.nan),
                    f"site{k}_peak_strain": a.get("peak_abs_strain", math.nan)})
    return {k: float(v) for k, v in out.items()}


def simulate_member(scene: str, stop_time: float, engine: str = "inprocess", *,
               overrides: Mapping[str, Any] | None = None, member: int = 0, eps: float = 1e-6,
               seed: int = 2024, fmu_dir: str | None = None
               ) -> tuple[np.ndarray, SceneConfig, str]:
    """Run one ensemble member of a scene (arguments: :func:`measure_scene`).

    Returns
    -------
    data : numpy.ndarray
        The recorder's structured array.
    config : SceneConfig
        The member's configuration (overrides applied).
    reason : str
        Why the run stopped early ("" if it completed).
    """
    config = load_config(scene, {**key_paths(overrides), "cosim.stop_time": float(stop_time)})
    offset = None
    if member:
        model = DrillstringModel(config.scene.plant, config.scene.model)
        offset = lateral_perturbation(model, eps, seed, member)
    data, reason = simulate_point(config, PointOptions(), engine, fmu_dir, offset)
    return data, config, reason


def measure_scene(scene: str, stop_time: float, engine: str = "inprocess", *,
                  overrides: Mapping[str, Any] | None = None, member: int = 0,
                  eps: float = 1e-6, seed: int = 2024, fmu_dir: str | None = None
                  ) -> dict[str, Any]:
    """Run one ensemble member of a scene and measure it (:data:`STAT_COLUMNS`).

    Parameters
    ----------
    scene : str
        Scene name or path.
    stop_time : float
        [s] (``[cosim] stop_time``).
    engine : {"inprocess", "fmu"}
        In-process slaves (any member) or the FMUs (member 0 only).
    overrides : mapping, optional
        Scene keys by key path.
    member, eps, seed
        See :func:`cosim.study.ensemble.lateral_perturbation`.
    fmu_dir : str, optional
        FMU folder (``fmu`` engine).

    Returns
    -------
    dict
        ``status`` ("ok" | "diverged"), ``reason``, ``end_time`` [s], ``wall_time`` [s] and
        the statistics of :func:`run_statistics`.
    """
    wall0 = time.perf_counter()
    data, config, reason = simulate_member(scene, stop_time, engine, overrides=overrides, member=member,
                                  eps=eps, seed=seed, fmu_dir=fmu_dir)
    t = data["time"]
    row: dict[str, Any] = {"status": "diverged" if reason else "ok", "reason": reason,
                           "end_time": float(t[-1]) if len(t) else 0.0}
    row.update(run_statistics(data, config))
    row["wall_time"] = time.perf_counter() - wall0
    return row


def aggregate(rows: Iterable[Mapping[str, Any]], stats: Sequence[str] | None = None
              ) -> list[dict[str, Any]]:
    """Per group: members, completed members, and mean / sd / se of each statistic.

    Parameters
    ----------
    rows : iterable of dict
        Table rows (:class:`SceneTable` or a subclass).
    stats : sequence of str, optional
        Numeric columns to reduce (default: every numeric column that is not an identity
        column).

    Returns
    -------
    list of dict
        Sorted by group (then scene): ``group``, ``scene``, ``members``, ``completed``, and
        ``<stat>``, ``<stat>_sd``, ``<stat>_se`` per statistic (over the completed members;
        error rows are left out). The order of ``rows`` does not matter.
    """
    groups: dict[tuple[str, str], list[Mapping[str, Any]]] = {}
    for r in rows:
        if r.get("status") in ("ok", "diverged"):
            groups.setdefault((str(r["group"]), str(r["scene"])), []).append(r)
    out = []
    for (group, scene), members in sorted(groups.items()):
        members = sorted(members, key=lambda r: r["member"])
        if stats is None:
            stats = [c for c, v in members[0].items() if c not in ID_COLUMNS
                     and c not in TEXT_COLUMNS and isinstance(v, float)]
        ok = [r for r in members if r["status"] == "ok"]
        agg: dict[str, Any] = {"group": group, "scene": scene, "members": len(members),
                               "completed": len(ok)}
        for c in stats:
            e = ensemble_stat([r.get(c, math.nan) for r in ok])
            agg[c], agg[f"{c}_sd"], agg[f"{c}_se"] = e.mean, e.sd, e.se
        out.append(agg)
    return out
