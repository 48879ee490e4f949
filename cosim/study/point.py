"""One sweep point: a co-simulation of a scene at (gain, delay, step) and its metrics.

:func:`run_point` is a plain module-level function of picklable arguments that
returns a flat dict, so it runs unchanged in a process pool or on a
dask.distributed worker. Two engines:

``"fmu"``
    The scene's system (:func:`cosim.scenario.scene_system.scene_system`: plant FMU +
    controller FMU) run by the master (:class:`cosim.master.execution.Execution`).
``"python"``
    The same loop in-process, without FMI: :class:`plant.simulator.PlantSimulator`
    and :class:`controller.StrainController`, the master's delay lines
    (:class:`cosim.master.delays.DelayLine`) and stepping order (Gauss-Seidel or Jacobi,
    from the scene's ``[cosim]``), zero-order hold or linear coupling. Same
    numbers as the FMU engine up to the FMU's float exchange, ~3x faster.

Both stop early ("diverged") on a non-finite value, a plant step the plant
rejects (state out of its range of validity), or an actuator force above
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
  four actuators), ``peak_power`` [W] (largest ``|P|`` of the actuator pairs).
"""

from __future__ import annotations

import math
import time
import traceback
from collections.abc import Mapping
from dataclasses import dataclass, fields
from typing import Any

import numpy as np

__all__ = ["PointOptions", "error_row", "metrics", "run_point"]

AXES = ("C", "E")
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


class _Series:
    """Recorded series of one run (plain arrays keyed like the master's outputs)."""

    def __init__(self, names: list[str]):
        self.names = names
        self.rows: list[tuple[float, ...]] = []

    def add(self, t: float, values) -> None:
        self.rows.append((t, *values))

    def arrays(self) -> dict[str, np.ndarray]:
        arr = np.array(self.rows, dtype=float).reshape(-1, len(self.names) + 1)
        out = {"time": arr[:, 0]}
        out.update({n: arr[:, i + 1] for i, n in enumerate(self.names)})
        return out


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


def metrics(series: Mapping[str, np.ndarray], spans: Mapping[int, str], n_sites: int,
            opts: PointOptions, diverged: bool) -> dict[str, float]:
    """Stability and benefit metrics of one recorded run (see the module docstring).

    Parameters
    ----------
    series : mapping
        ``time`` [s] and plant/controller variables without the FMU prefix
        (``body11_radial_deflection``, ``strain1_C``, ``actuator1_force_C``,
        ``actuator1_power``, ...).
    spans : mapping
        Contact body -> ``"long" | "short" | "only"``.
    n_sites : int
        Actuator sites.
    opts : PointOptions
    diverged : bool
    """
    t = series["time"]
    out: dict[str, float] = {}
    strains = [series[f"strain{s}_{a}"] for s in range(1, n_sites + 1) for a in AXES
               if f"strain{s}_{a}" in series]
    if strains and len(t) > 8 and opts.highpass > 0:
        from scipy.signal import butter, sosfilt

        dt = float(np.median(np.diff(t)))
        nyq = math.pi / dt
        if opts.highpass < 0.9 * nyq:
            sos = butter(4, opts.highpass / nyq, "highpass", output="sos")
            strains = [sosfilt(sos, s) for s in strains]
    smax = np.max(np.abs(np.vstack(strains)), axis=0) if strains and len(t) else np.zeros(0)
    out["growth_rate"], out["growth_noise"] = _envelope_growth(
        t, smax, opts.envelope_window, opts.fit_fraction) if len(t) else (math.nan, math.nan)
    forces = [series[k] for k in series if k.startswith("actuator") and "_force_" in k]
    powers = [series[f"actuator{s}_power"] for s in range(1, n_sites + 1)
              if f"actuator{s}_power" in series]
    out["peak_force"] = float(np.max(np.abs(np.vstack(forces)))) if forces and len(t) else 0.0
    out["peak_power"] = float(np.max(np.abs(np.vstack(powers)))) if powers and len(t) else 0.0
    t_rms = t[-1] - opts.rms_fraction * (t[-1] - t[0]) if len(t) else 0.0
    for span in SPANS:
        out[f"rms_{span}"] = math.nan
        out[f"peak_deflection_{span}"] = math.nan
    for body, kind in spans.items():
        col = "long" if kind == "only" else kind
        r = series.get(f"body{body}_radial_deflection")
        if r is None or not len(r):
            continue
        out[f"peak_deflection_{col}"] = float(np.max(r))
        if not diverged:
            out[f"rms_{col}"] = float(np.sqrt(np.mean(r[t >= t_rms] ** 2)))
    return out


def _scene(scene: str, gain: float, delay: float, step: float, stop_time: float,
           open_loop: bool, overrides: Mapping[str, Any] | None):
    from drillcosim.plant.scene import load_scene

    over: dict[str, Any] = {k: dict(v) if isinstance(v, Mapping) else v
                            for k, v in (overrides or {}).items()}
    over.setdefault("cosim", {}).update({"step": step, "stop_time": stop_time,
                                         "actuator_delay": delay})
    ctrl = over.setdefault("controller", {})
    if open_loop:
        ctrl["enabled"] = False
    else:
        ctrl.update({"enabled": True, "gain": gain})
    return load_scene(scene, overrides=over), over


class _ForceCap:
    """Observer: stop the master (as a divergence) when a force exceeds the cap."""

    def __init__(self, refs: list[str], cap: float):
        self.refs = refs
        self.cap = cap

    def on_step(self, execution) -> None:
        from drillcosim.cosim.master.errors import DivergenceError

        for ref in self.refs:
            v = execution.get_real(ref)
            if abs(v) > self.cap:
                raise DivergenceError(ref, execution.time, v)


def _run_fmu(sc, over: Mapping[str, Any], opts: PointOptions, fmu_dir) -> tuple[dict, str]:
    import contextlib
    import io

    from drillcosim.cosim.master.errors import CosimError, DivergenceError
    from drillcosim.cosim.master.execution import Execution
    from drillcosim.cosim.master.recorder import Recorder
    from drillcosim.cosim.scenario.scene_system import scene_system

    plant_over = {k: v for k, v in over.items() if k not in ("cosim", "controller")}
    ss = scene_system(sc, fmu_dir, plant_overrides=plant_over)
    H = ss.system.base_step
    recorder = Recorder(ss.outputs, max(1, round(ss.output_interval / H)))
    forces = [o for o in ss.outputs if o.startswith("controller.actuator")]
    reason = ""
    execution = None
    with contextlib.redirect_stdout(io.StringIO()):
        try:
            execution = Execution(ss.system, read_outputs=ss.outputs)
            execution.add_observer(recorder)
            if forces:
                execution.add_observer(_ForceCap(forces, opts.force_cap))
            execution.initialize()
            execution.simulate_until(ss.stop_time)
        except DivergenceError as exc:
            reason = (f"diverged at t = {exc.time:.6g} s: {exc.quantity} = {exc.value:.3g}"
                      + (f" exceeds the force cap {opts.force_cap:g} N"
                         if math.isfinite(exc.value) else ""))
        except CosimError as exc:
            reason = f"diverged: {exc}"
            if execution is None or not execution.initialized:
                raise
        finally:
            if execution is not None:
                execution.close()
    data = recorder.data
    series = {"time": np.asarray(data["time"], dtype=float)}
    for name in data.dtype.names[1:]:
        series[name.split(".", 1)[1]] = np.asarray(data[name], dtype=float)
    return series, reason


def _run_python(sc, opts: PointOptions) -> tuple[dict, str]:
    from drillcosim.controller import ControllerParams, StrainController
    from drillcosim.cosim.master.delays import DelayLine
    from drillcosim.cosim.scenario.scene_system import controller_parameters, cosim_settings
    from drillcosim.plant.model import DrillstringModel
    from drillcosim.plant.simulator import PlantSimulator

    st = cosim_settings(sc)
    if st.controller_sample_ticks != 1:
        raise ValueError("engine 'python': controller_sample_period must equal step")
    ctrl_p = controller_parameters(sc)
    enabled = bool(ctrl_p["enabled"])
    model = DrillstringModel(sc.plant, sc.model)
    sim = PlantSimulator(model)
    n_sites = model.n_sites
    names = model.output_names
    s_idx = [names.index(f"strain{s}_{a}") for s in range(1, n_sites + 1) for a in AXES]
    rec_names = [n for n in names if n.endswith("_radial_deflection") or n.startswith("strain")
                 or n.endswith("_power")]
    rec_idx = [names.index(n) for n in rec_names]
    force_names = [f"actuator{s}_force_{a}" for s in range(1, n_sites + 1) for a in AXES]
    series = _Series(rec_names + (force_names if enabled else []))
    H = st.step
    n_steps = round(st.stop_time / H)
    every = max(1, round(st.output_interval / H))
    y0 = sim.outputs()
    if not enabled:
        series.add(0.0, y0[rec_idx])
        for k in range(n_steps):
            res = sim.do_step(k * H, H)
            if not res.ok:
                return series.arrays(), res.message
            if (k + 1) % every == 0:
                series.add((k + 1) * H, sim.outputs()[rec_idx])
        return series.arrays(), ""
    sym = float(ctrl_p["symmetric_force_limit"])
    ctrl = StrainController(ControllerParams(
        gain=float(ctrl_p["gain"]), mode=("unrestricted", "compressive_only")[int(ctrl_p["mode"])],
        force_limit=float(ctrl_p["force_limit"]),
        symmetric_force_limit=math.inf if sym >= 1e30 else sym,
        switch_on_time=float(ctrl_p["switch_on_time"]),
        lag_time_constant=float(ctrl_p["lag_time_constant"]), enabled=True))
    linear = st.coupling == "linear"
    act = [DelayLine(st.actuator_delay, H, linear) for _ in s_idx]
    sen = [DelayLine(st.sensor_delay, H, linear) for _ in s_idx]
    jacobi = st.algorithm == "jacobi"
    plant_first = jacobi or st.order[0] == "plant"
    # horizons (source steps from the newest sample to the target's step midpoint)
    h_act, h_sen = (0.5, 0.5) if jacobi else ((0.5, -0.5) if plant_first else (-0.5, 0.5))
    for line, v in zip(sen, y0[s_idx]):
        line.reset(float(v))
    F = ctrl.forces
    for line in act:
        line.reset(0.0)
    series.add(0.0, [*y0[rec_idx], *F])
    cap = opts.force_cap
    for k in range(n_steps):
        t = k * H
        c = np.array([ln.value(h_sen) for ln in sen])
        if not plant_first:                      # Gauss-Seidel, controller first
            F = ctrl.step(t, H, c)
            for ln, v in zip(act, F):
                ln.push(float(v))
        sim.set_inputs(np.array([ln.value(h_act) for ln in act]))
        res = sim.do_step(t, H)
        if not res.ok:
            return series.arrays(), res.message
        y = sim.outputs()
        if plant_first:
            if not jacobi:                       # Gauss-Seidel, plant first: newest strains
                for ln, v in zip(sen, y[s_idx]):
                    ln.push(float(v))
                c = np.array([ln.value(h_sen) for ln in sen])
            F = ctrl.step(t, H, c)
            for ln, v in zip(act, F):
                ln.push(float(v))
        if jacobi or not plant_first:
            for ln, v in zip(sen, y[s_idx]):
                ln.push(float(v))
        if (k + 1) % every == 0:
            series.add((k + 1) * H, [*y[rec_idx], *F])
        fmax = float(np.max(np.abs(F)))
        if not fmax <= cap:
            series.add((k + 1) * H, [*y[rec_idx], *F])
            return series.arrays(), (f"diverged at t = {(k + 1) * H:.6g} s: actuator force "
                                     f"{fmax:.3g} N exceeds the force cap {cap:g} N")
    return series.arrays(), ""


def error_row(exc: BaseException, wall_time: float = math.nan) -> dict[str, Any]:
    """Row fields of a point that raised: status ``error`` and a one-line reason."""
    last = traceback.extract_tb(exc.__traceback__)[-1:] if exc.__traceback__ else []
    where = f" ({last[0].filename.rsplit('/', 1)[-1]}:{last[0].lineno})" if last else ""
    msg = " ".join(str(exc).split()) or type(exc).__name__
    return {"status": "error", "reason": f"{type(exc).__name__}: "
            f"{msg}{where}"[:500], "wall_time": wall_time}


def run_point(scene: str, gain: float, delay: float, step: float, stop_time: float,
              engine: str = "fmu", *, open_loop: bool = False,
              overrides: Mapping[str, Any] | None = None, fmu_dir: str | None = None,
              **options: float) -> dict[str, Any]:
    """Run one sweep point and measure it.

    Parameters
    ----------
    scene : str
        Scene name (``scenes/<name>.toml``) or path.
    gain : float
        Controller gain [N per unit strain] (ignored for open loop).
    delay : float
        Actuator delay [s] (``[cosim] actuator_delay``).
    step : float
        Communication step [s] (``[cosim] step``; the controller samples at it).
    stop_time : float
        [s].
    engine : {"fmu", "python"}
    open_loop : bool
        Controller disabled (the reference run of the control benefit).
    overrides : mapping, optional
        Extra nested scene overrides (e.g. ``{"cosim": {"algorithm": "jacobi"}}``).
    fmu_dir : str, optional
        FMU folder for the ``fmu`` engine (default ``build/fmus``).
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
        as an ``error`` row, see :func:`cosim.study.sweep.run_sweep`).
    """
    from drillcosim.cosim.scenario.scene_system import span_info

    wall0 = time.perf_counter()
    opts = PointOptions.from_kwargs(options)
    if engine not in ("fmu", "python"):
        raise ValueError(f"engine = {engine!r}: 'fmu' or 'python'")
    sc, over = _scene(scene, gain, delay, step, stop_time, open_loop, overrides)
    if engine == "fmu":
        series, reason = _run_fmu(sc, over, opts, fmu_dir)
    else:
        series, reason = _run_python(sc, opts)
    t = series["time"]
    end = float(t[-1]) if len(t) else 0.0
    diverged = bool(reason)
    spans = {b: str(v["span"]) for b, v in span_info(sc).items()}
    row: dict[str, Any] = {"status": "diverged" if diverged else "ok",
                           "divergence_time": end if diverged else math.nan,
                           "end_time": end, "reason": reason}
    row.update(metrics(series, spans, len(sc.plant.actuator_joints), opts, diverged))
    row["min_stop_time"] = math.nan if open_loop else _min_stop_time(scene, overrides, opts)
    row["wall_time"] = time.perf_counter() - wall0
    return row


def _min_stop_time(scene: str, overrides: Mapping[str, Any] | None, opts: PointOptions
                   ) -> float:
    """:attr:`JudgingWindow.min_stop_time` [s] of the scene; NaN if it cannot be derived."""
    import numpy as np

    from .verdict import scene_judging_window

    try:
        return scene_judging_window(scene, overrides, opts.highpass,
                                    opts.fit_fraction).min_stop_time
    except (ValueError, np.linalg.LinAlgError):  # e.g. no damped mode above the cut-off
        return math.nan


