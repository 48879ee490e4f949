"""Stepping a model over communication steps: what the plant FMU (and the benchmarks) call.

:class:`PlantSimulator` holds time, state and inputs, splits each communication step into equal
internal steps (RK4 by default) no longer than the method's stable step, and checks the state
after every step.
A numerical failure is *returned* as a :class:`StepResult` naming the time and the quantity that
diverged (scipy ``_ivp`` style); nothing is raised from :meth:`do_step`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from . import guards
from .batch import run_record_rk4
from .guards import check_state
from .integrators import stable_step
from .model import FIXED_STEP_METHODS, DrillstringModel

__all__ = ["PlantSimulator", "StepResult", "simulate"]

# Beyond these the lumped model has left its range of validity: report divergence.
MAX_LATERAL = 1.0  # m, lateral position of any mass centre
MAX_TILT = 0.5  # rad, Cardan tilt angles theta, phi
MAX_SPEED = 1e4  # m/s or rad/s
MAX_STRAIN = 5e-3  # bending strain at the outer wall: 2.5x the yield strain of collar steel
# A step may take at most this many internal steps (~10 s of wall time): a huge step size must not
# hang the caller (an FMU importer).
MAX_SUBSTEPS = 2_000_000


@dataclass(frozen=True)
class StepResult:
    """Outcome of a step: ``ok`` and, on failure, a message naming time and quantity."""

    ok: bool
    message: str = ""
    time: float = math.nan
    quantity: str = ""
    value: float = math.nan


class PlantSimulator:
    """Time, state and inputs of one plant instance.

    Parameters
    ----------
    model : DrillstringModel
    max_step : float, optional
        Upper bound of the internal step [s]; default: the model's stable step for ``method``
        (``inf``, i.e. one step a communication step, for the exponential integrators).
    method : {"rk4", "verlet", "expeuler", "etd2", "dopri5"}, optional
        Internal integrator (default ``"rk4"``); see :meth:`DrillstringModel.advance`.
        ``"dopri5"`` is adaptive (``rtol``, ``atol``) and steps to each communication point.
    """

    def __init__(self, model: DrillstringModel, max_step: float | None = None,
                 method: str = "rk4", rtol: float = 1e-6, atol: float = 1e-9) -> None:
        if method not in FIXED_STEP_METHODS and method != "dopri5":
            raise ValueError(f"method = {method!r} is not allowed: one of "
                             f"{', '.join([*FIXED_STEP_METHODS, 'dopri5'])}")
        self.model = model
        self.method = method
        self.rtol = float(rtol)
        self.atol = float(atol)
        self._hstate = np.zeros(1)
        radius = FIXED_STEP_METHODS.get(method)
        if max_step is not None:
            self.max_step = float(max_step)
        elif method == "rk4":
            self.max_step = model.stable_step()
        elif radius is None:
            self.max_step = math.inf
        else:
            self.max_step = stable_step(model.max_eigenvalue, radius)
        if not self.max_step > 0.0 or (math.isinf(self.max_step) and radius is not None):
            raise ValueError(f"max_step = {max_step!r} is not allowed: must be > 0 and finite (s)")
        self.time = 0.0
        self.y = model.initial_state()
        self.u = np.zeros(2 * model.n_sites)
        self._names = self._state_names()
        self.input_names = [f"actuator{s}_force_{a}" for s in range(1, model.n_sites + 1)
                            for a in "CE"]
        self._strain_factor = 0.5 * model.params.pipe.outer_diameter / model.derived.dx

    def _state_names(self) -> list[str]:
        m = self.model
        n = m.n
        if m.kind == "full3d":
            blocks = (("X", "Y", "Z"), ("psi", "theta", "phi"), ("vX", "vY", "vZ"),
                      ("wx", "wy", "wz"))
            return [f"body{k + 1}.{c}" for b in blocks for k in range(n) for c in b]
        return [f"body{k + 1}.{c}" for c in ("Z", "psi", "vZ", "wz") for k in range(n)]

    def set_inputs(self, u: np.ndarray) -> None:
        """Actuator forces [N], shape (2 n_sites,): site 1 C, site 1 E, site 2 C, ..."""
        self.u[:] = u

    def check(self) -> StepResult:
        """Is the state finite and inside the model's range of validity? (compiled check)"""
        m = self.model
        code, i, val = check_state(m.kind == "full3d", m.n, self.y, MAX_LATERAL, MAX_TILT,
                                   MAX_SPEED, MAX_STRAIN, self._strain_factor, m.wR)
        return self._report(code, i, val)

    def _report(self, code: int, i: int, val: float) -> StepResult:
        """Turn a :func:`plant.guards.check_state` result into a :class:`StepResult`."""
        if code == guards.OK:
            return StepResult(True)
        if code == guards.NOT_FINITE:
            return self._fail(f"{self._names[i]} is not finite", self._names[i], float(val))
        if code == guards.SPEED:
            return self._fail(f"{self._names[i]} = {val:.3g} exceeds {MAX_SPEED:g}",
                              self._names[i], float(val))
        if code == guards.LATERAL:
            return self._fail(f"lateral deflection of body{i + 1} = {val:.3g} m exceeds "
                              f"{MAX_LATERAL} m", f"body{i + 1}.radial", float(val))
        if code == guards.TILT:
            return self._fail(f"tilt of body{i + 1} = {val:.3g} rad exceeds {MAX_TILT} rad",
                              f"body{i + 1}.tilt", float(val))
        return self._fail(f"bending strain at the joint below body{i + 1} = {val:.3g} exceeds "
                          f"{MAX_STRAIN:g} (beyond the elastic range)", f"joint{i + 1}.strain",
                          float(val))

    def run_record(self, h: float, n_out: int, idx: np.ndarray) -> tuple[np.ndarray, StepResult]:
        """``n_out`` RK4 output steps of ``h`` [s] in one compiled loop, recording outputs.

        Equals ``n_out`` calls of :meth:`do_step` + :meth:`outputs` bit for bit.

        Returns
        -------
        rec : numpy.ndarray, shape (completed + 1, len(idx))
            Outputs ``idx`` at the start and after each completed step.
        result : StepResult
        """
        m = self.model
        n_sub = max(1, math.ceil(h / self.max_step - 1e-9))
        rec = np.empty((n_out + 1, len(idx)))
        k1, k2, k3, k4, yt = m._scratch
        limits = np.array([MAX_LATERAL, MAX_TILT, MAX_SPEED, MAX_STRAIN])
        done, code, i, val = run_record_rk4(
            m.model_id, self.time, h, n_out, n_sub, self.y, m.p, m.ip, m.fp, self.u, m.wR, m.wF,
            m.wM, k1, k2, k3, k4, yt, m._zbit_ref, m._out, np.asarray(idx, dtype=np.int64), rec,
            limits, self._strain_factor)
        self.time = self.time + done * h
        return rec[:done + 1], self._report(code, i, val)

    def _fail(self, what: str, quantity: str, value: float) -> StepResult:
        return StepResult(False, f"diverged at t = {self.time:.6g} s: {what}", self.time,
                          quantity, value)

    def do_step(self, t: float, h: float) -> StepResult:
        """Advance from ``t`` [s] by ``h`` [s] with the inputs held.

        The step is split into ``ceil(h / max_step)`` equal RK4 steps. Refused with the state
        unchanged (a result without ``quantity``): a step size that is not finite and > 0, a
        time ``t`` that is not the simulator's own (within 1e-9 relative), a non-finite input,
        or a step that needs more than :data:`MAX_SUBSTEPS` internal steps.
        """
        if not (h > 0.0 and math.isfinite(h)):
            return StepResult(False, f"step size {h!r} s at t = {t!r} s is not allowed: must be "
                                     f"> 0 and finite; step rejected (state unchanged)")
        if not (math.isfinite(t) and abs(t - self.time) <= 1e-9 * max(1.0, abs(t))):
            return StepResult(False, f"communication point t = {t!r} s is not the plant's time "
                                     f"{self.time!r} s; step rejected (state unchanged)")
        if not np.all(np.isfinite(self.u)):
            bad = [f"{n} = {v!r}" for n, v in zip(self.input_names, self.u.tolist())
                   if not math.isfinite(v)]
            return StepResult(False, f"input {', '.join(bad)} is not finite at t = {t!r} s; "
                                     f"step rejected (state unchanged)")
        if self.method != "dopri5" and math.ceil(h / self.max_step) > MAX_SUBSTEPS:
            return StepResult(False, f"step size h = {h!r} s needs {math.ceil(h / self.max_step):.3g}"
                                     f" internal steps of {self.max_step:.3g} s, more than "
                                     f"{MAX_SUBSTEPS:g} allowed per step; step rejected (state "
                                     f"unchanged)")
        if self.method == "dopri5":
            code = self.model.advance_adaptive(t, t + h, self.y, self._hstate, self.rtol,
                                               self.atol, self.u)
            self.time = t + h
            res = self.check()
            if res.ok and code != 0:
                return StepResult(False, f"adaptive step failed at t = {t:.6g} s (code {code})",
                                  t)
            return res
        n_sub = max(1, math.ceil(h / self.max_step - 1e-9))
        done = self.model.advance(t, self.y, n_sub, h / n_sub, self.u, self.method)
        self.time = t + h if done == n_sub else t + done * h / n_sub
        return self.check()

    def outputs(self) -> np.ndarray:
        """Outputs at the current time, in the order of ``model.output_names`` (a reused view)."""
        return self.model.outputs(self.time, self.y, self.u)

    def get_state(self) -> tuple[float, np.ndarray, np.ndarray]:
        """A copy of (time, state, inputs) for FMU state save."""
        return self.time, self.y.copy(), self.u.copy()

    def set_state(self, state: tuple[float, np.ndarray, np.ndarray]) -> None:
        """Restore a state from :meth:`get_state`."""
        t, y, u = state
        self.time = float(t)
        self.y[:] = y
        self.u[:] = u


def simulate(model: DrillstringModel, stop_time: float, output_interval: float,
             outputs: list[str] | None = None, max_step: float | None = None,
             method: str = "rk4",
             ) -> tuple[np.ndarray, dict[str, np.ndarray], StepResult]:
    """Run the plant alone (inputs zero) and sample outputs.

    Returns
    -------
    t : numpy.ndarray, shape (k,)
        Sample times [s].
    values : dict of str -> numpy.ndarray, shape (k,)
        Requested outputs (all by default).
    result : StepResult
        ``ok`` or the divergence report; samples stop at the failure.
    """
    sim = PlantSimulator(model, max_step, method)
    names = outputs or model.output_names
    idx = [model.output_names.index(n) for n in names]
    n_out = int(round(stop_time / output_interval))
    if method == "rk4":  # compiled loop, same numbers as the loop below
        arr, res = sim.run_record(output_interval, n_out, np.array(idx))
        ts = np.arange(arr.shape[0]) * output_interval
        return ts, {n: arr[:, i] for i, n in enumerate(names)}, res
    ts = [0.0]
    rows = [sim.outputs()[idx].copy()]
    res = StepResult(True)
    for k in range(n_out):
        res = sim.do_step(k * output_interval, output_interval)
        if not res.ok:
            break
        ts.append((k + 1) * output_interval)
        rows.append(sim.outputs()[idx].copy())
    arr = np.array(rows)
    return np.array(ts), {n: arr[:, i] for i, n in enumerate(names)}, res
