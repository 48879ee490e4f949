"""When a sweep point supports a stability verdict, and which one.

A closed-loop point is judged from its strain-envelope growth rate (:func:`cosim.study.point.metrics`:
the slope of ``ln(envelope)`` of the high-passed strains over the last ``fit_fraction`` of the run)
compared with the open-loop reference run of the same scene, engine, step and stop time.
The rules, in this order (``docs/delay_study.md``, "Verdicts"):

1. ``error``: the point raised; ``unstable``: it diverged (a non-finite value, the plant out of its
   range, or an actuator force above the cap): a divergence is conclusive at any run length.
2. ``undecided`` when the run is shorter than :attr:`JudgingWindow.min_stop_time`: the growth fit
   must start after the start-up transient and be long enough to see growth at the margin rate
   (:func:`judging_window`, derived from the scene).
3. ``undecided`` without a completed open-loop reference, or without a measurable growth rate.
4. With ``excess = growth - growth_open`` and ``noise`` the standard error of that difference
   (the two slope fits' standard errors combined; 0 if the measurement reports none) and
   ``band = NOISE_FACTOR * noise``: ``unstable`` if ``excess > GROWTH_MARGIN + band`` (clearly
   above the margin); ``stable`` if ``excess <= band`` and ``excess < GROWTH_MARGIN - band``
   (no extra growth beyond the noise, and clearly below the margin); else ``undecided``:
   within the noise of the margin, or a significant excess below it (a slow instability or
   a different forced build-up: run longer, compare with the linear prediction).

The open-loop run itself gets ``reference`` (``unstable`` if it diverged). The verdict of a row is
a function of that row and its reference row only: :func:`judge` is what the results table
(:mod:`cosim.study.table`) applies to every row whenever a row is added.

Against the linear prediction (:func:`compare_with_prediction`): a verdict ``stable`` agrees with a
predicted growth rate <= 0, ``unstable`` with one > 0; where they differ, the reason in this order:
the predicted growth is *below the margin* (0 < rate <= :data:`GROWTH_MARGIN`: the verdict's rule
cannot call it unstable), *wall contact* (the run touched the wellbore: a nonlinearity the
prediction leaves out), else none known. ``undecided`` and ``error`` rows are not compared (*too
short to judge* when the run ends before the judging window), nor rows without a prediction
(*prediction unavailable*).

The control benefit (:func:`benefit_note`) is judged only when the open-loop reference has built up
its vibration: its RMS deflection over the second half of the RMS window at most
:data:`BENEFIT_RISE` times that over the first half (a benefit measured while the reference still
grows is a property of the window, not of the controller).
"""

from __future__ import annotations

import functools
import json
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import scipy.linalg
from threadpoolctl import threadpool_limits

from drillcosim.cosim.scenario.config import key_paths, load_config

from .stability import coupled_plant

__all__ = ["BENEFIT_RISE", "GROWTH_MARGIN", "NOISE_FACTOR", "PREDICTION_NOTES",
           "SETTLE_TIME_CONSTANTS", "VERDICTS", "JudgingWindow", "benefit_note",
           "compare_with_prediction", "judge", "judging_window", "rule_text",
           "scene_judging_window"]

#: A closed-loop run is unstable when its strain-envelope growth rate exceeds the open-loop
#: run's by more than this [1/s] (the forced whirl builds up over the first seconds in every
#: band, open or closed loop; differences below this are not a loop instability).
GROWTH_MARGIN = 0.5
#: Half-width of the undecided band around the margin, in standard errors of the excess [-].
NOISE_FACTOR = 2.0
#: The start-up transient is over when the slowest mode the growth fit sees has decayed by
#: ``exp(-SETTLE_TIME_CONSTANTS)`` (5 %) after the last start-up event [-].
SETTLE_TIME_CONSTANTS = 3.0
#: Verdict values of the results table.
VERDICTS = ("stable", "unstable", "undecided", "reference", "error")
#: The benefit of a span is judged when the open-loop reference's RMS deflection over the second
#: half of the RMS window is at most this many times that over its first half [1].
BENEFIT_RISE = 1.5
#: Why a verdict and the prediction are not compared or differ (``prediction_note`` starts so).
PREDICTION_NOTES = ("below the margin", "wall contact", "unexplained", "too short to judge",
                    "undecided", "prediction unavailable", "error")


@dataclass(frozen=True)
class JudgingWindow:
    """The shortest run whose growth fit can support a verdict.

    Attributes
    ----------
    start_up : float
        Last start-up event [s]: the end of the top-drive speed ramp, or the controller's
        switch-on time if later.
    slowest_frequency : float
        Frequency [rad/s] of the least damped plant mode the growth fit sees (at or above the
        high-pass cut-off; top-drive frame, loop-coupled modes only).
    slowest_decay : float
        Its decay rate [1/s], > 0.
    transient_end : float
        ``start_up + SETTLE_TIME_CONSTANTS / slowest_decay`` [s].
    min_length : float
        Shortest fit window [s]: ``1 / GROWTH_MARGIN``, over which growth at the margin rate
        amounts to a factor e.
    fit_fraction : float
        Fraction of the run (at its end) the growth is fitted over, (0, 1].
    """

    start_up: float
    slowest_frequency: float
    slowest_decay: float
    transient_end: float
    min_length: float
    fit_fraction: float

    @property
    def min_stop_time(self) -> float:
        """Shortest stop time [s]: the fit window ``[(1 - f) T, T]`` starts after the transient
        and is at least :attr:`min_length` long."""
        f = self.fit_fraction
        start = self.transient_end / (1.0 - f) if f < 1.0 else (
            0.0 if self.transient_end <= 0.0 else math.inf)
        return max(start, self.min_length / f)

    def describe(self) -> str:
        """One clause: the numbers behind :attr:`min_stop_time`."""
        return (f"start-up until {self.start_up:g} s + {SETTLE_TIME_CONSTANTS:g} x "
                f"{1.0 / self.slowest_decay:.3g} s decay of the least damped mode the fit sees "
                f"({self.slowest_frequency:.4g} rad/s) = {self.transient_end:.3g} s; fit window "
                f">= {self.min_length:g} s over the last {100 * self.fit_fraction:g} % of the run")


def judging_window(eigenvalues, start_up: float, highpass: float, fit_fraction: float
                   ) -> JudgingWindow:
    """The judging window from the plant's modes and the start-up time.

    Parameters
    ----------
    eigenvalues : array_like of complex, shape (N,)
        Continuous eigenvalues [1/s] of the loop-coupled plant modes (open loop).
    start_up : float
        Last start-up event [s] (top-drive ramp end, controller switch-on).
    highpass : float
        Cut-off [rad/s] of the high-pass filter before the growth fit (0: none): modes below it
        are not seen by the fit.
    fit_fraction : float
        Fraction of the run at its end used by the fit, (0, 1].

    Returns
    -------
    JudgingWindow
    """
    lam = np.asarray(eigenvalues, dtype=complex)
    seen = lam[(np.abs(lam.imag) >= highpass) & (lam.real < 0)]
    if seen.size == 0:
        raise ValueError(f"no damped mode at or above the high-pass cut-off {highpass:g} rad/s")
    i = int(np.argmax(seen.real))
    decay = float(-seen[i].real)
    return JudgingWindow(float(start_up), float(abs(seen[i].imag)), decay,
                         float(start_up) + SETTLE_TIME_CONSTANTS / decay, 1.0 / GROWTH_MARGIN,
                         float(fit_fraction))


@functools.lru_cache(maxsize=16)
def _cached_window(scene: str, overrides: str, highpass: float, fit_fraction: float
                   ) -> JudgingWindow:
    config = load_config(scene, json.loads(overrides) if overrides else None)
    # a closed-loop point switches the controller on whatever the scene file says
    start_up = max(config.scene.plant.top_drive.ramp_time,
                   getattr(config.controller.params, "switch_on_time", 0.0))
    A = coupled_plant(config.scene)[0]
    with threadpool_limits(1):      # ~240 states: one BLAS thread (6x faster on a busy machine)
        lam = scipy.linalg.eigvals(A)
    return judging_window(lam, start_up, highpass, fit_fraction)


def scene_judging_window(scene: str, overrides: Mapping[str, Any] | None = None,
                         highpass: float = 100.0, fit_fraction: float = 0.5
                         ) -> JudgingWindow:
    """:func:`judging_window` of a scene (linearized plant; cached per process).

    Parameters
    ----------
    scene : str
        Scene name or path.
    overrides : mapping, optional
        Scene keys by key path (the sweep's ``--set``); ``cosim.*`` does not matter.
    highpass, fit_fraction : float
        The point options of the growth fit (:class:`cosim.study.point.PointOptions`).
    """
    over = {k: v for k, v in key_paths(overrides).items() if not k.startswith("cosim.")}
    return _cached_window(str(scene), json.dumps(over, sort_keys=True) if over else "",
                          float(highpass), float(fit_fraction))


def _number(row: Mapping[str, Any], key: str) -> float:
    v = row.get(key, math.nan)
    return float(v) if isinstance(v, (int, float)) and not isinstance(v, bool) else math.nan


def judge(row: Mapping[str, Any], reference: Mapping[str, Any] | None
          ) -> tuple[str, str, float]:
    """Verdict of one row (rules: module docstring).

    Parameters
    ----------
    row : mapping
        A table row: ``kind``, ``status``, ``reason``, ``end_time`` [s], ``min_stop_time`` [s]
        (NaN: unknown, not checked), ``growth_rate`` and ``growth_noise`` [1/s].
    reference : mapping or None
        The open-loop row of the same scene/engine/step/stop time (any status), if present.

    Returns
    -------
    verdict : str
        One of :data:`VERDICTS`.
    reason : str
        Why (empty for ``stable`` and ``reference``); for ``error`` / ``unstable`` by
        divergence the row's own reason.
    excess : float
        ``growth_rate - growth_rate(open loop)`` [1/s] (NaN when not available).
    """
    status = row.get("status")
    if status == "error":
        return "error", str(row.get("reason", "")), math.nan
    if status == "diverged":
        return "unstable", str(row.get("reason", "")), math.nan
    if row.get("kind") == "open_loop":
        return "reference", "", math.nan
    end, need = _number(row, "end_time"), _number(row, "min_stop_time")
    g, noise = _number(row, "growth_rate"), _number(row, "growth_noise")
    ok_ref = reference is not None and reference.get("status") == "ok"
    g0 = _number(reference, "growth_rate") if ok_ref else math.nan
    excess = g - g0
    if end < need:
        return "undecided", (f"too short to judge: a {end:g} s run ends before the {need:.3g} s "
                             "the growth fit needs after the start-up transient"), excess
    if not ok_ref:
        what = "missing" if reference is None else f"{reference.get('status')}"
        return "undecided", f"no completed open-loop reference run ({what})", excess
    if not math.isfinite(excess):
        return "undecided", "growth rate not measurable (too few envelope windows)", excess
    noise = math.hypot(noise, _number(reference, "growth_noise"))
    if not math.isfinite(noise):     # a measurement that does not report it: the fit at face value
        noise = 0.0
    band = NOISE_FACTOR * noise
    about = f"strain envelope grows {excess:.3g} +- {noise:.2g} 1/s faster than open loop"
    if excess > GROWTH_MARGIN + band:
        return "unstable", f"{about} (> {GROWTH_MARGIN:g} 1/s)", excess
    if excess <= band and excess < GROWTH_MARGIN - band:
        return "stable", "", excess
    if excess >= GROWTH_MARGIN - band:
        return "undecided", (f"{about}: within the noise of the {GROWTH_MARGIN:g} 1/s margin "
                             "(run longer)"), excess
    return "undecided", (f"{about}: more than the noise, less than the {GROWTH_MARGIN:g} 1/s "
                         "margin (a slow instability or another forced build-up: run longer, "
                         "compare with the prediction)"), excess


def rule_text(stop_time: float) -> dict[str, str]:
    """The verdicts' rules in words for runs of ``stop_time`` [s] (the maps' legend)."""
    m = f"{GROWTH_MARGIN:g} 1/s"
    return {"stable": f"stable: no envelope growth above {m} (over open loop) within "
                      f"{stop_time:g} s",
            "unstable": f"unstable: envelope grows > {m} faster than open loop",
            "diverged": "unstable: diverged (non-finite, out of range or force cap)",
            "undecided": "undecided: within the noise of the margin, or run too short",
            "error": "error (the point failed)"}


def compare_with_prediction(row: Mapping[str, Any], verdict: str, excess: float
                            ) -> tuple[float, str]:
    """Does the verdict agree with the linear prediction (rules: module docstring)?

    Parameters
    ----------
    row : mapping
        A closed-loop row: ``predicted_growth_rate`` [1/s] (NaN: none), ``prediction_note``
        (why none), ``contact_time`` [s], ``end_time``, ``min_stop_time`` [s].
    verdict : str
        The row's verdict (:func:`judge`).
    excess : float
        The measured growth excess [1/s] (NaN: none).

    Returns
    -------
    agrees : float
        1 (agrees), 0 (differs), NaN (not compared).
    note : str
        "" when they agree; else one of :data:`PREDICTION_NOTES` and the numbers.
    """
    predicted = _number(row, "predicted_growth_rate")
    if verdict == "error":
        return math.nan, "error"
    if not math.isfinite(predicted):
        note = str(row.get("prediction_note", "") or "")
        return math.nan, note if note.startswith("prediction unavailable") else \
            "prediction unavailable"
    p = f"predicted {predicted:+.3g} 1/s"
    if verdict == "undecided":
        if _number(row, "end_time") < _number(row, "min_stop_time"):
            return math.nan, f"too short to judge ({p})"
        return math.nan, f"undecided ({p})"
    if (verdict == "unstable") == (predicted > 0):
        return 1.0, ""
    measured = "diverged" if row.get("status") == "diverged" else (
        f"measured excess {excess:.3g} 1/s" if math.isfinite(excess) else "no measured growth")
    if verdict == "stable" and 0 < predicted <= GROWTH_MARGIN:
        return 0.0, (f"below the margin: {p} is at most the {GROWTH_MARGIN:g} 1/s the verdict "
                     f"needs ({measured})")
    contact = _number(row, "contact_time")
    if contact > 0:
        return 0.0, (f"wall contact: {contact:.3g} s in contact with the wellbore, which the "
                     f"linear prediction leaves out ({p}, {measured})")
    return 0.0, f"unexplained: {p}, {measured}"


def benefit_note(reference: Mapping[str, Any] | None, spans: Sequence[str] = ("long", "short")
                 ) -> str:
    """Why the benefit of ``spans`` cannot be judged against ``reference`` (the open-loop row),
    "" if it can (rule: module docstring); the spans whose reference is still building up."""
    if reference is None or reference.get("status") != "ok":
        return "no completed open-loop reference"
    rising = [f"{rise:.3g}x ({span} span)" for span in spans
              if (rise := _number(reference, f"rms_rise_{span}")) > BENEFIT_RISE]
    if not rising:
        return ""
    return (f"too short to judge the benefit: the open-loop RMS deflection still rises "
            f"{', '.join(rising)} within the RMS window (> {BENEFIT_RISE:g}x); run longer")
