"""Run summary: peak and steady-state deflection, actuator effort, contact events.

:func:`summarize` reduces a recorded run (the structured array of
:class:`cosim.master.Result`, or :func:`load_results` of a ``results.csv``) to a
JSON-ready dict; :func:`write_json` writes it atomically. Every quantity carries
its unit in its key (``_m``, ``_N``, ``_W``, ``_s``).

Keys of the summary
-------------------
``scene``, ``scene_file``
    Scene name and file.
``stop_time_s``, ``end_time_s``, ``completed``
    Requested stop time, simulated time reached [s], and whether it was reached.
``wall_time_s``, ``real_time_factor``
    Wall-clock time of the stepping loop [s]; simulated / wall time [-].
``step_s``, ``output_interval_s``, ``steady_window_s``
    Base step, recording interval, and the window ``[t0, t1]`` [s] of the
    steady-state statistics: the last third of the recorded time.
``spans``
    Per contact body ``"body<b>"``: ``span`` ("long" / "short"),
    ``span_length_m``, ``peak_radial_deflection_m``,
    ``steady_radial_deflection_mean_m``, ``steady_radial_deflection_std_m``,
    ``peak_contact_force_N``, ``contact_events`` (number of entries into
    contact, i.e. samples where the contact force turns > 0 after a sample at
    0), ``contact_time_s`` (samples in contact x output interval), and, when
    the controller switches on during the run, ``before_switch_on`` with the
    same deflection statistics over the last third before the switch-on.
``actuators``
    Per site ``"site<s>"``: ``peak_force_N`` (max abs over the C and E
    actuators), ``peak_force_C_N``, ``peak_force_E_N``, ``peak_power_W`` (max
    of the delivered power), ``peak_abs_power_W``, ``steady_mean_power_W``,
    ``peak_abs_strain`` and ``steady_strain_rms`` (gauges C and E together, unit
    1), and ``before_switch_on_strain_rms`` (last third before the switch-on)
    when the controller switches on during the run. Forces are 0 when the
    controller is disabled.
``torsional``
    When the bit speed was recorded: :func:`stick_slip_metrics` of the steady window
    (``bit_speed_min/max/mean_rad_s``, ``stick_slip_severity``, ``stick_fraction``), and, with a
    top-drive controller, ``peak_motor_torque_N_m``.
``diverged``
    ``null``, or ``{"time_s", "quantity", "value", "message"}`` of the failure
    that stopped the run.
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from drillcosim.cosim.master.files import atomic_write
from drillcosim.plant.signals import (
    AXES,
    CONTROLLER,
    PLANT,
    TOP_DRIVE,
    TOP_DRIVE_TORQUE,
    actuator_force,
    actuator_power,
    bodies_in,
    body_signal,
    strain,
)

if TYPE_CHECKING:  # the plots' worker processes import this module: no plant model
    from drillcosim.plant.scene import Scene

__all__ = ["STICK_SPEED", "SUMMARY_KEYS", "column", "contact_bodies", "load_results",
           "span_info", "stick_slip_metrics", "summarize", "write_json"]

#: The bit counts as stuck below this speed [rad/s] (the cutting bit's friction is regularized
#: over ``bit.slip_speed``, 0.05 rad/s in stick_slip: a stuck bit creeps at < 0.04 rad/s).
STICK_SPEED = 0.1

#: Top-level keys every summary has.
SUMMARY_KEYS = ("scene", "scene_file", "stop_time_s", "end_time_s", "completed", "wall_time_s",
                "real_time_factor", "step_s", "output_interval_s", "steady_window_s", "spans",
                "actuators", "diverged")


def load_results(csv_path: str | Path) -> np.ndarray:
    """Read a ``results.csv`` into a structured array (``time`` first, names kept as is)."""
    path = Path(csv_path)
    with open(path) as fh:
        header = fh.readline().strip().split(",")
    values = np.loadtxt(path, delimiter=",", skiprows=1, ndmin=2)
    dtype = np.dtype([(n, np.float64) for n in header])
    out = np.zeros(len(values), dtype=dtype)
    for i, n in enumerate(header):
        out[n] = values[:, i]
    return out


def column(data: np.ndarray, fmu: str, name: str) -> np.ndarray | None:
    """Column ``'fmu.name'`` of a recorded result as floats, or None if not recorded."""
    ref = f"{fmu}.{name}"
    return np.asarray(data[ref], dtype=float) if ref in (data.dtype.names or ()) else None


def contact_bodies(data: np.ndarray) -> list[int]:
    """Bodies whose ``plant.body<b>_radial_deflection`` was recorded."""
    return bodies_in(data.dtype.names or (), instance=PLANT)


def span_info(scene: Scene) -> dict[int, dict[str, float | str]]:
    """Per contact body: its span's length [m] and 'long'/'short'.

    Returns
    -------
    dict
        ``{body: {"span_length": L_span [m], "span": "long" | "short" | "only"}}``.
    """
    plant = scene.plant
    dx = plant.pipe.segment_length
    spans = plant.spans()
    out: dict[int, dict[str, float | str]] = {}
    lengths = [b - a for a, b in spans]
    for body in plant.contact_bodies:
        z = (body - 0.5) * dx
        length = next((b - a for a, b in spans if a <= z <= b), float("nan"))
        if len(set(round(x, 9) for x in lengths)) < 2 or math.isnan(length):
            kind = "only"
        else:
            kind = "long" if length >= max(lengths) - 1e-9 else "short"
        out[body] = {"span_length": length, "span": kind}
    return out


def _stats(t: np.ndarray, r: np.ndarray, t0: float, t1: float) -> dict[str, float]:
    sel = (t >= t0) & (t <= t1)
    if not np.any(sel):
        return {"steady_radial_deflection_mean_m": math.nan,
                "steady_radial_deflection_std_m": math.nan}
    return {"steady_radial_deflection_mean_m": float(np.mean(r[sel])),
            "steady_radial_deflection_std_m": float(np.std(r[sel]))}


def _peak(x: np.ndarray | None) -> float:
    if x is None or x.size == 0:
        return 0.0
    finite = x[np.isfinite(x)]
    return float(np.max(np.abs(finite))) if finite.size else math.nan


def stick_slip_metrics(t: np.ndarray, bit_speed: np.ndarray, t0: float) -> dict[str, float]:
    """Stick-slip measures of the bit speed [rad/s] over ``t >= t0`` [s].

    Returns
    -------
    dict
        ``bit_speed_min_rad_s``, ``bit_speed_max_rad_s``, ``bit_speed_mean_rad_s``;
        ``stick_slip_severity`` = (max - min) / mean [1] (0 for steady rotation; about 2 and
        more for full stick-slip, where the bit stops and slips at up to ~3 times its mean
        speed; NaN if the mean is not > 0) and ``stick_fraction`` [1], the fraction of the
        samples with the bit speed below :data:`STICK_SPEED`. NaN for an empty window.
    """
    sel = (t >= t0) & np.isfinite(bit_speed)
    if not np.any(sel):
        return dict.fromkeys(("bit_speed_min_rad_s", "bit_speed_max_rad_s",
                              "bit_speed_mean_rad_s", "stick_slip_severity", "stick_fraction"),
                             math.nan)
    w = bit_speed[sel]
    lo, hi, mean = float(np.min(w)), float(np.max(w)), float(np.mean(w))
    return {"bit_speed_min_rad_s": lo, "bit_speed_max_rad_s": hi, "bit_speed_mean_rad_s": mean,
            "stick_slip_severity": (hi - lo) / mean if mean > 0 else math.nan,
            "stick_fraction": float(np.mean(w < STICK_SPEED))}


def _contact(t: np.ndarray, f: np.ndarray | None, dt: float) -> tuple[int, float, float]:
    if f is None or f.size == 0:
        return 0, 0.0, 0.0
    on = f > 0.0
    entries = int(np.count_nonzero(on[1:] & ~on[:-1])) + int(bool(on[0]))
    return entries, float(np.count_nonzero(on) * dt), float(np.max(f))


def summarize(data: np.ndarray, *, scene: str = "", scene_file: str = "",
              spans: Mapping[int, Mapping[str, Any]] | None = None, n_sites: int = 2,
              stop_time: float = math.nan, step: float = math.nan,
              output_interval: float | None = None, wall_time: float = math.nan,
              real_time_factor: float = math.nan, end_time: float | None = None,
              switch_on_time: float | None = None,
              diverged: Mapping[str, Any] | None = None) -> dict[str, Any]:
    """Summary of a recorded run (keys: module docstring).

    Parameters
    ----------
    data : numpy.ndarray
        Structured array, ``time`` [s] first, columns named ``plant.<output>``
        and ``controller.<output>``.
    scene, scene_file : str
        Scene name and file.
    spans : mapping, optional
        ``{body: {"span": ..., "span_length": [m]}}`` (see
        :func:`span_info`); default: bodies found in ``data``.
    n_sites : int
        Number of actuator sites; a site none of whose columns was recorded is left out.
    stop_time, step : float
        Requested stop time and base step [s].
    output_interval : float, optional
        Recording interval [s]; default: spacing of the first two rows.
    wall_time, real_time_factor : float
        From :class:`cosim.master.Result` [s], [-].
    end_time : float, optional
        Simulated time reached [s]; default: the last row's time.
    switch_on_time : float, optional
        Controller switch-on time [s]; adds ``before_switch_on`` statistics when
        inside the recorded time.
    diverged : mapping, optional
        Failure report ``{"time_s", "quantity", "value", "message"}``.

    Returns
    -------
    dict
        JSON-ready (non-finite floats become ``None`` in :func:`write_json`).
    """
    t = np.asarray(data["time"], dtype=float) if len(data) else np.zeros(0)
    if output_interval is None:
        output_interval = float(t[1] - t[0]) if t.size > 1 else step
    if end_time is not None:
        end = float(end_time)
    else:
        end = float(t[-1]) if t.size else math.nan
    t_first = float(t[0]) if t.size else 0.0
    t_last = float(t[-1]) if t.size else 0.0
    w0 = t_first + 2.0 / 3.0 * (t_last - t_first)
    if spans is None:
        spans = {b: {"span": "", "span_length": math.nan} for b in contact_bodies(data)}
    out_spans: dict[str, Any] = {}
    for body, info in spans.items():
        r = column(data, PLANT, body_signal(body, "radial_deflection"))
        if r is None:
            continue
        entries, t_contact, f_peak = _contact(
            t, column(data, PLANT, body_signal(body, "contact_force")), output_interval)
        entry: dict[str, Any] = {"span": info.get("span", ""),
                                 "span_length_m": info.get("span_length", math.nan),
                                 "peak_radial_deflection_m": _peak(r), **_stats(t, r, w0, t_last),
                                 "peak_contact_force_N": f_peak, "contact_events": entries,
                                 "contact_time_s": t_contact}
        if switch_on_time is not None and t_first < switch_on_time < t_last:
            b0 = t_first + 2.0 / 3.0 * (switch_on_time - t_first)
            sel = t < switch_on_time
            entry["before_switch_on"] = {"window_s": [b0, switch_on_time],
                                         "peak_radial_deflection_m": _peak(r[sel]),
                                         **_stats(t, r, b0, switch_on_time)}
        out_spans[f"body{body}"] = entry
    actuators: dict[str, Any] = {}
    for s in range(1, n_sites + 1):
        forces = [column(data, CONTROLLER, actuator_force(s, a)) for a in AXES]
        p = column(data, PLANT, actuator_power(s))
        strains = [x for x in (column(data, PLANT, strain(s, a)) for a in AXES) if x is not None]
        if p is None and not strains and all(f is None for f in forces):
            continue  # nothing of this site was recorded (e.g. the axial-torsional chain)
        fc, fe = (_peak(f) for f in forces)
        sel = t >= w0
        extra: dict[str, float] = {}
        if strains:
            eps = np.stack(strains)
            extra["peak_abs_strain"] = _peak(eps.ravel())
            extra["steady_strain_rms"] = float(np.sqrt(np.mean(eps[:, sel] ** 2))) \
                if np.any(sel) else math.nan
            if switch_on_time is not None and t_first < switch_on_time < t_last:
                b0 = t_first + 2.0 / 3.0 * (switch_on_time - t_first)
                pre = (t >= b0) & (t < switch_on_time)
                extra["before_switch_on_strain_rms"] = float(np.sqrt(np.mean(eps[:, pre] ** 2)))
        actuators[f"site{s}"] = {
            "peak_force_N": max(fc, fe), "peak_force_C_N": fc, "peak_force_E_N": fe,
            "peak_power_W": float(np.max(p)) if p is not None and p.size else 0.0,
            "peak_abs_power_W": _peak(p),
            "steady_mean_power_W": float(np.mean(p[sel])) if p is not None and np.any(sel)
            else 0.0,
            **extra,
        }
    torsional: dict[str, float] = {}
    bit_speed = column(data, PLANT, "bit_rotary_speed")
    if bit_speed is not None:
        torsional = stick_slip_metrics(t, bit_speed, w0)
        motor = column(data, TOP_DRIVE, TOP_DRIVE_TORQUE)
        if motor is not None:
            torsional["peak_motor_torque_N_m"] = _peak(motor)
    return {
        "scene": scene, "scene_file": scene_file, "stop_time_s": stop_time, "end_time_s": end,
        "completed": bool(diverged is None and math.isfinite(end)
                          and end >= stop_time - 1e-9 * max(1.0, abs(stop_time))),
        "wall_time_s": wall_time, "real_time_factor": real_time_factor, "step_s": step,
        "output_interval_s": output_interval, "steady_window_s": [w0, t_last],
        "spans": out_spans, "actuators": actuators, "torsional": torsional,
        "diverged": dict(diverged) if diverged is not None else None,
    }


def _clean(obj: Any) -> Any:
    if isinstance(obj, float):
        return obj if math.isfinite(obj) else None
    if isinstance(obj, Mapping):
        return {str(k): _clean(v) for k, v in obj.items()}
    if isinstance(obj, Sequence) and not isinstance(obj, str):
        return [_clean(v) for v in obj]
    if isinstance(obj, np.generic):
        return _clean(obj.item())
    return obj


def write_json(obj: Any, path: str | Path) -> Path:
    """Write ``obj`` as indented JSON atomically (:func:`cosim.master.files.atomic_write`);
    non-finite floats become ``null``."""
    return atomic_write(path, json.dumps(_clean(obj), indent=2, allow_nan=False) + "\n")
