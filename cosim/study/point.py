"""One sweep point: a co-simulation of a scene at (gain, delay, step) and its metrics.

:func:`measure_point` is a plain module-level function of picklable arguments that
returns a flat dict, so it runs unchanged in a process pool or on a
dask.distributed worker. The point's configuration (:func:`point_config`: the scene with the
point's key-path overrides) is built by the one builder
(:func:`cosim.scenario.build.build_system`) with one of its engines and run by the one master
call (:func:`cosim.scenario.simulate.simulate`):

``"fmu"``
    the plant FMU and the controller FMU;
``"inprocess"``
    the same models in process (:mod:`cosim.scenario.inprocess`), without the FMI
    boundary: the same numbers, bit for bit.

A run stops early ("diverged") on a non-finite value, a plant step the plant
discards (state out of its range of validity), or an actuator force above
``force_cap``.

Metrics (:func:`metrics`), all from the recorded series (every ``output_interval``):

* ``growth_rate`` [1/s]: slope of a least-squares fit of ``ln(envelope)`` over
  the last ``fit_fraction`` of the run, the envelope being the largest ``|strain|``
  of the four gauges (high-passed above ``highpass`` rad/s) in windows of
  ``envelope_window`` s (NaN with fewer than 3 windows); ``growth_noise`` [1/s]: the
  standard error of that slope (scatter of the envelope about the fitted line);
* ``min_stop_time`` [s]: the shortest run whose growth fit supports a verdict
  (:func:`cosim.study.verdict.scene_judging_window`; NaN if the scene cannot be
  linearized). The verdict itself needs the open-loop reference run and is made by
  the results table (:mod:`cosim.study.verdict`);
* ``rms_long``, ``rms_short`` [m]: RMS radial deflection of the long/short span's
  contact body over the last ``rms_fraction`` of the run (a scene with one span
  fills the ``long`` columns); NaN when the run diverged;
* ``peak_deflection_long/short`` [m], ``peak_force`` [N] (largest ``|F|`` of the
  four actuators), ``peak_power`` [W] (largest ``|P|`` of the actuator pairs);
* ``stick_slip_severity`` [1] ((max - min) / mean bit speed) and ``stick_fraction`` [1] (time
  with the bit below :data:`cosim.scenario.summary.STICK_SPEED`) over the last
  ``rms_fraction`` of the run (:func:`cosim.scenario.summary.stick_slip_metrics`; NaN when the
  run diverged).

The swept gain is the value of a scene key, ``gain_key``: the strain controller's ``gain``
[N per unit strain] by default, or e.g. the top-drive controller's ``p_gain`` [N m s/rad]
(:func:`default_gain_key`: the latter when the scene enables a top-drive controller and no
strain controller). The point enables the controller of that table; its open-loop reference
disables it.

The recorded columns are named ``fmu.var`` (``plant.strain1_C``,
``controller.actuator1_force_C``, ...), as the master records them.
"""

from __future__ import annotations

import math
import time
import traceback
from collections.abc import Mapping
from dataclasses import dataclass, fields
from typing import Any

import numpy as np

from drillcosim.cosim.master.checkpoint import Checkpoint
from drillcosim.cosim.master.limits import OutputLimit
from drillcosim.cosim.scenario.build import ENGINES, build_system
from drillcosim.cosim.scenario.config import ConfigError, SceneConfig, key_paths, load_config
from drillcosim.cosim.scenario.result import Result
from drillcosim.cosim.scenario.simulate import simulate
from drillcosim.cosim.scenario.summary import span_info, stick_slip_metrics
from drillcosim.plant.signals import (
    CONTROLLER,
    PLANT,
    TOP_DRIVE,
    actuator_force,
    actuator_power,
    body_signal,
    ref,
    site_channels,
    strain,
)

from .grid import DEFAULT_GAIN_KEY, check_gain_key
from .highpass import butter_highpass, sosfilt
from .prediction import point_prediction
from .verdict import scene_judging_window

__all__ = ["ENGINES", "PointOptions", "default_gain_key", "error_row", "measure_point", "metrics",
           "point_config", "run_point", "simulate_point"]

SPANS = ("long", "short")


@dataclass(frozen=True)
class PointOptions:
    """Options of the point metrics and the early stop.

    Attributes
    ----------
    fit_fraction : float
        Fraction of the run (at its end) used for the growth fit, (0, 1].
    envelope_window : float
        Envelope window [s].
    rms_fraction : float
        Fraction of the run (at its end) for the RMS deflection, (0, 1].
    force_cap : float
        Stop as diverged when an actuator force exceeds this [N] (default 1e6 N;
        stable runs of the paper scenes stay below ~1e5 N, contact impacts included).
    highpass : float
        Cut-off [rad/s] of a 4th-order Butterworth high-pass applied to the strains
        before the envelope fit (0: none). The sampled-loop instabilities of the
        drillstring sit at hundreds of rad/s (the linear prediction's unstable
        mode), while the forced whirl builds up over seconds at 0-20 rad/s: the
        filter keeps that build-up out of the growth rate.
    """

    fit_fraction: float = 0.5
    envelope_window: float = 0.2
    rms_fraction: float = 0.5
    force_cap: float = 1e6
    highpass: float = 100.0

    @classmethod
    def from_kwargs(cls, kwargs: Mapping[str, Any]) -> PointOptions:
        """Pick this class's fields from ``kwargs`` (unknown keys: ``TypeError``)."""
        names = {f.name for f in fields(cls)}
        bad = set(kwargs) - names
        if bad:
            raise TypeError(f"unknown point option(s): {', '.join(sorted(bad))}; "
                            f"allowed: {', '.join(sorted(names))}")
        return cls(**kwargs)


def _envelope_growth(t: np.ndarray, s: np.ndarray, window: float, fraction: float
                     ) -> tuple[float, float]:
    """Slope of ln(windowed max |s|) over the last ``fraction`` of ``t`` and its standard
    error [1/s] (NaN, NaN with fewer than 3 windows)."""
    if len(t) < 4:
        return math.nan, math.nan
    t0 = t[-1] - fraction * (t[-1] - t[0])
    sel = t >= t0
    tt, ss = t[sel], np.abs(s[sel])
    n_win = int((tt[-1] - tt[0]) // window)
    if n_win < 3:
        return math.nan, math.nan
    edges = tt[0] + window * np.arange(n_win + 1)
    idx = np.searchsorted(tt, edges)
    centers, env = [], []
    for a, b in zip(idx[:-1], idx[1:]):
        if b > a:
            m = float(ss[a:b].max())
            if m > 0:
                centers.append(float(tt[a:b].mean()))
                env.append(math.log(m))
    if len(env) < 3:
        return math.nan, math.nan
    x, y = np.array(centers), np.array(env)
    slope, intercept = np.polyfit(x, y, 1)
    r = y - (slope * x + intercept)
    dx = x - x.mean()
    return float(slope), float(math.sqrt(float(r @ r) / (len(x) - 2) / float(dx @ dx)))


def metrics(data: np.ndarray, spans: Mapping[int, str], n_sites: int, opts: PointOptions,
            diverged: bool) -> dict[str, float]:
    """Stability and benefit metrics of one recorded run (see the module docstring).

    Parameters
    ----------
    data : numpy.ndarray
        The recorder's structured array: ``time`` [s] and ``fmu.var`` columns
        (``plant.body11_radial_deflection``, ``plant.strain1_C``,
        ``controller.actuator1_force_C``, ``plant.actuator1_power``, ...).
    spans : mapping
        Contact body -> ``"long" | "short" | "only"``.
    n_sites : int
        Actuator sites.
    opts : PointOptions
    diverged : bool
    """
    names = set(data.dtype.names or ())
    t = np.asarray(data["time"], dtype=float)
    out: dict[str, float] = {}
    sites = range(1, n_sites + 1)
    strains = [np.asarray(data[n], dtype=float) for s, a in site_channels(sites)
               if (n := ref(PLANT, strain(s, a))) in names]
    if strains and len(t) > 8 and opts.highpass > 0:
        dt = float(np.median(np.diff(t)))
        nyq = math.pi / dt
        if opts.highpass < 0.9 * nyq:
            sos = butter_highpass(4, opts.highpass / nyq)
            strains = [sosfilt(sos, s) for s in strains]
    out["growth_rate"] = out["growth_noise"] = math.nan  # no strains: no strain-loop growth
    if strains and len(t):
        smax = np.max(np.abs(np.vstack(strains)), axis=0)
        out["growth_rate"], out["growth_noise"] = _envelope_growth(
            t, smax, opts.envelope_window, opts.fit_fraction)
    forces = [data[n] for s, a in site_channels(sites)
              if (n := ref(CONTROLLER, actuator_force(s, a))) in names]
    powers = [data[n] for s in sites if (n := ref(PLANT, actuator_power(s))) in names]
    out["peak_force"] = float(np.max(np.abs(np.vstack(forces)))) if forces and len(t) else 0.0
    out["peak_power"] = float(np.max(np.abs(np.vstack(powers)))) if powers and len(t) else 0.0
    t_rms = t[-1] - opts.rms_fraction * (t[-1] - t[0]) if len(t) else 0.0
    out["stick_slip_severity"] = out["stick_fraction"] = math.nan
    bit_speed = ref(PLANT, "bit_rotary_speed")
    if bit_speed in names and len(t) and not diverged:
        torsional = stick_slip_metrics(t, np.asarray(data[bit_speed], float), t_rms)
        out["stick_slip_severity"] = torsional["stick_slip_severity"]
        out["stick_fraction"] = torsional["stick_fraction"]
    for span in SPANS:
        out[f"rms_{span}"] = out[f"rms_rise_{span}"] = math.nan
        out[f"peak_deflection_{span}"] = math.nan
    out["contact_time"] = 0.0
    dt = float(np.median(np.diff(t))) if len(t) > 1 else 0.0
    in_contact = np.zeros(len(t), bool)
    for body, kind in spans.items():
        col = "long" if kind == "only" else kind
        contact = ref(PLANT, body_signal(body, "contact_force"))
        if contact in names:
            in_contact |= np.asarray(data[contact], dtype=float) > 0.0
        name = ref(PLANT, body_signal(body, "radial_deflection"))
        if name not in names or not len(t):
            continue
        r = np.asarray(data[name], dtype=float)
        out[f"peak_deflection_{col}"] = float(np.max(r))
        if not diverged:
            out[f"rms_{col}"] = float(np.sqrt(np.mean(r[t >= t_rms] ** 2)))
            out[f"rms_rise_{col}"] = _rms_rise(t, r, t_rms)
    out["contact_time"] = float(np.count_nonzero(in_contact)) * dt
    return out


def _rms_rise(t: np.ndarray, r: np.ndarray, t_rms: float) -> float:
    """RMS of ``r`` over the second half of ``[t_rms, t_end]`` over its RMS over the first half
    [1] (NaN if either half is empty or the first is 0)."""
    mid = 0.5 * (t_rms + t[-1])
    first, second = r[(t >= t_rms) & (t < mid)], r[t >= mid]
    if not first.size or not second.size:
        return math.nan
    a = float(np.sqrt(np.mean(first**2)))
    return float(np.sqrt(np.mean(second**2))) / a if a > 0 else math.nan


def default_gain_key(scene: str, overrides: Mapping[str, Any] | None = None) -> str:
    """The key a sweep of ``scene`` varies by default: ``top_drive_controller.p_gain`` when the
    scene enables a top-drive controller and no strain controller, else ``controller.gain``."""
    instances = load_config(scene, overrides).instances
    if TOP_DRIVE in instances and CONTROLLER not in instances:
        return f"{TOP_DRIVE}.p_gain"
    return DEFAULT_GAIN_KEY


def point_config(scene: str, gain: float, delay: float, step: float, stop_time: float,
                 open_loop: bool, overrides: Mapping[str, Any] | None,
                 gain_key: str = DEFAULT_GAIN_KEY) -> SceneConfig:
    """The configuration of a point: the scene with ``overrides`` (key paths), the step, stop
    time and actuator delay, ``gain_key`` set to ``gain`` and its controller enabled (disabled
    for the open-loop reference)."""
    table = check_gain_key(gain_key).partition(".")[0]
    over = {**key_paths(overrides), "cosim.step": step, "cosim.stop_time": stop_time,
            "cosim.actuator_delay": delay}
    if open_loop:
        over[f"{table}.enabled"] = False
    else:
        over[f"{table}.enabled"] = True
        if not math.isnan(gain):  # NaN: the scene's gain
            over[gain_key] = gain
    return load_config(scene, over)


def simulate_point(config: SceneConfig, opts: PointOptions, engine: str = "fmu",
                   fmu_dir: str | None = None, initial_offset: np.ndarray | None = None
                   ) -> tuple[np.ndarray, str]:
    """Build and run a configuration, stopping early at the force cap.

    Parameters
    ----------
    config : SceneConfig
        The point's configuration (:func:`point_config`).
    opts : PointOptions
    engine : {"fmu", "inprocess"}
        FMU slaves, or the in-process ones.
    fmu_dir : str, optional
        FMU folder (``fmu`` engine; default ``build/fmus``).
    initial_offset : numpy.ndarray, shape (n_state,), optional
        Added to the plant's initial state (``inprocess`` engine only: an FMU's state is not
        an input), e.g. the perturbation of an ensemble member
        (:func:`cosim.study.ensemble.lateral_perturbation`).

    Returns
    -------
    data : numpy.ndarray
        The recorder's structured array (``time`` and ``instance.var`` columns).
    reason : str
        Why the run stopped early ("" if it reached its stop time).

    Raises
    ------
    CosimError
        A failure before the run's first step (bad parameters, a missing FMU); a failure while
        stepping ends the run as diverged (its reason names the slave's own message).
    """
    res, reason = run_point(config, opts, engine, fmu_dir, initial_offset)
    return res.data, reason


def run_point(config: SceneConfig, opts: PointOptions, engine: str = "fmu",
              fmu_dir: str | None = None, initial_offset: np.ndarray | None = None,
              from_checkpoint: Checkpoint | None = None) -> tuple[Result, str]:
    """:func:`simulate_point`, returning the run's :class:`~cosim.scenario.result.Result`
    (its timings too) instead of its data; from ``from_checkpoint`` if given (its rows begin
    at the checkpoint's time)."""
    if initial_offset is not None and engine != "inprocess":
        raise ConfigError("initial_offset: a perturbed initial state needs engine 'inprocess' "
                          "(the in-process plant)")
    built = build_system(config, engine, fmu_dir=fmu_dir)
    if initial_offset is not None:
        sim = built.slaves[PLANT].sim
        offset = np.asarray(initial_offset, dtype=float)
        if offset.shape != sim.y.shape:
            raise ConfigError(f"initial_offset: shape {offset.shape}, the plant's state has "
                              f"{sim.y.shape}")
        sim.y = sim.y + offset
    channels = site_channels(range(1, config.n_sites + 1))
    forces = [o for o in (ref(CONTROLLER, actuator_force(s, a)) for s, a in channels)
              if o in built.outputs]
    # a force beyond the cap stops the point as a divergence (checked in C by the native loop)
    res = simulate(built, observers=[OutputLimit(forces, opts.force_cap)] if forces else (),
                   from_state=from_checkpoint)
    f = res.failure
    if f is None:
        return res, ""
    if f["value"] is None:
        return res, f"diverged at t = {f['time_s']:.6g} s: {f['message']}"
    return res, (f"diverged at t = {f['time_s']:.6g} s: {f['quantity']} = {f['value']:.3g}"
                 + (f" exceeds the force cap {opts.force_cap:g} N"
                    if math.isfinite(f["value"]) else ""))


def error_row(exc: BaseException, wall_time: float = math.nan) -> dict[str, Any]:
    """Row fields of a point that raised: status ``error`` and a one-line reason."""
    last = traceback.extract_tb(exc.__traceback__)[-1:] if exc.__traceback__ else []
    where = f" ({last[0].filename.rsplit('/', 1)[-1]}:{last[0].lineno})" if last else ""
    msg = " ".join(str(exc).split()) or type(exc).__name__
    return {"status": "error", "reason": f"{type(exc).__name__}: "
            f"{msg}{where}"[:500], "wall_time": wall_time}


def measure_point(scene: str, gain: float, delay: float, step: float, stop_time: float,
                  engine: str = "fmu", *, open_loop: bool = False,
                  overrides: Mapping[str, Any] | None = None, fmu_dir: str | None = None,
                  gain_key: str = DEFAULT_GAIN_KEY, config: SceneConfig | None = None,
                  prefix: Any = None,
                  **options: float) -> dict[str, Any]:
    """Run one sweep point and measure it.

    Parameters
    ----------
    scene : str
        Scene name (``scenes/<name>.toml``) or path.
    gain : float
        Value of ``gain_key``: by default the strain controller's gain [N per unit strain]
        (ignored for open loop).
    delay : float
        Actuator delay [s] (``cosim.actuator_delay``).
    step : float
        Communication step [s] (``cosim.step``; the controller samples at it).
    stop_time : float
        [s].
    engine : {"fmu", "inprocess"}
    open_loop : bool
        Controller disabled (the reference run of the control benefit).
    overrides : mapping, optional
        Extra scene keys by key path (e.g. ``{"cosim.algorithm": "jacobi"}``).
    fmu_dir : str, optional
        FMU folder for the ``fmu`` engine (default ``build/fmus``).
    gain_key : str
        The scene key ``gain`` sets (default ``controller.gain``).
    config : SceneConfig, optional
        The point's typed configuration (a sweep derives it once from its base,
        :attr:`cosim.study.grid.SweepSpec.planned`); default: :func:`point_config` of the
        arguments above.
    prefix : cosim.study.branch.Prefix, optional
        Continue from this shared prefix (its checkpoint and rows) instead of running from
        0 s: the same record, bit for bit (:mod:`cosim.study.branch`).
    **options
        :class:`PointOptions` fields.

    Returns
    -------
    dict
        ``status`` (``"ok"`` | ``"diverged"``), ``divergence_time`` [s] (NaN if none),
        ``end_time`` [s], ``reason`` (why it diverged; empty if ok), the metrics of
        :func:`metrics`, ``min_stop_time`` [s] (closed loop; NaN for open loop) and
        ``wall_time`` [s]. The verdict is the table's (:func:`cosim.study.verdict.judge`).

    Raises
    ------
    Exception
        Bad input or an FMU failure before the first step (the sweep records it
        as an ``error`` row, see :func:`cosim.study.sweep.execute_sweep`).
    """
    wall0 = time.perf_counter()
    opts = PointOptions.from_kwargs(options)
    if config is None:
        config = point_config(scene, gain, delay, step, stop_time, open_loop, overrides,
                              gain_key)
    start = None if prefix is None else Checkpoint.from_bytes(prefix.checkpoint)
    res, reason = run_point(config, opts, engine, fmu_dir, from_checkpoint=start)
    run_time = time.perf_counter() - wall0
    data = res.data
    if prefix is not None:   # the shared rows before the branch time, then the point's own
        data = np.concatenate([prefix.rows.astype(data.dtype, copy=False), data])
    t = data["time"]
    end = float(t[-1]) if len(t) else 0.0
    diverged = bool(reason)
    spans = {b: str(v["span"]) for b, v in span_info(config.scene).items()}
    row: dict[str, Any] = {"status": "diverged" if diverged else "ok",
                           "divergence_time": end if diverged else math.nan,
                           "end_time": end, "reason": reason}
    row.update(metrics(data, spans, config.n_sites, opts, diverged))
    strain_loop = gain_key.startswith(f"{CONTROLLER}.")
    row["min_stop_time"] = (math.nan if open_loop or not strain_loop
                            else _min_stop_time(scene, overrides, opts))
    row["predicted_growth_rate"], row["prediction_note"] = math.nan, ""
    if strain_loop and not open_loop:
        row["predicted_growth_rate"], row["prediction_note"] = point_prediction(config)
    row["branch_time"] = math.nan if prefix is None else prefix.time
    row["stepping_time"] = res.wall_time
    row["startup_time"] = run_time - res.wall_time
    row["wall_time"] = time.perf_counter() - wall0
    return row


def _min_stop_time(scene: str, overrides: Mapping[str, Any] | None, opts: PointOptions
                   ) -> float:
    """:attr:`JudgingWindow.min_stop_time` [s] of the scene; NaN if it cannot be derived."""
    try:
        return scene_judging_window(scene, overrides, opts.highpass,
                                    opts.fit_fraction).min_stop_time
    except (ValueError, np.linalg.LinAlgError):  # e.g. no damped mode above the cut-off
        return math.nan
