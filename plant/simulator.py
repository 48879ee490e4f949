"""Stepping a model over communication steps: what the plant FMU (and the benchmarks) call.

:class:`PlantSimulator` holds time, state and inputs, splits each communication step into equal
internal steps no longer than the method's stable step (the method chosen per step size,
:meth:`DrillstringModel.method_for_step`), and checks the state after every step.
A numerical failure is *returned* as a :class:`StepResult` naming the time and the quantity that
diverged (scipy ``_ivp`` style); nothing is raised from :meth:`do_step`. :meth:`do_step` is the
Python reference of the compiled step (:meth:`PlantSimulator.compiled_step`,
``plant/compiled_step.py``) that the FMU and the in-process slave run: the same bits.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np

from . import guards
from .batch import RECORD_EXPEULER, RECORD_RK4, run_record
from .guards import check_state
from .integrators import METHODS, Method, next_breakpoint, stable_step
from .model import DrillstringModel
from .step_result import StepResult

if TYPE_CHECKING:
    from .compiled_step import CompiledStep

__all__ = ["PlantSimulator", "StepResult", "simulate"]

# Beyond these the lumped model has left its range of validity: report divergence.
MAX_LATERAL = 1.0  # m, lateral position of any mass centre
MAX_TILT = 0.5  # rad, Cardan tilt angles theta, phi
MAX_SPEED = 1e4  # m/s or rad/s
MAX_STRAIN = 5e-3  # bending strain at the outer wall: 2.5x the yield strain of collar steel
# A step may take at most this many internal steps (~10 s of wall time): a huge step size must not
# hang the caller (an FMU importer).
MAX_SUBSTEPS = 2_000_000


_NO_OPERATOR = (np.zeros((0, 0), dtype=np.int64), np.zeros(0, dtype=np.int64), np.zeros((0, 0, 0)),
                np.zeros((0, 0)))


class PlantSimulator:
    """Time, state and inputs of one plant instance.

    Parameters
    ----------
    model : DrillstringModel
    max_step : float, optional
        Upper bound of the internal step [s]; default: the model's stable step for ``method``
        (``inf``, i.e. one step a communication step, for the exponential integrators).
    method : str, optional
        Internal integrator: ``"auto"`` (default), ``"dopri5"`` or a fixed-step method of
        :data:`plant.integrators.METHODS` (``"rk4"``, ``"kutta3"``, ``"verlet"``,
        ``"expeuler"``, ...; see :meth:`DrillstringModel.advance`). ``"auto"`` without
        ``max_step`` is :meth:`DrillstringModel.method_for_step` of each step's size (the
        fewest right-hand sides per communication step among the methods that met the
        accuracy bar, ``BENCHMARKS.md``; exponential Euler for a linear axial-torsional
        scene); with ``max_step`` it is :attr:`DrillstringModel.default_method`.
        ``"dopri5"`` is adaptive (``rtol``, ``atol``) and steps to each communication point.

    Attributes
    ----------
    clock : numpy.ndarray, shape (1,)
        The time [s] (:attr:`time`), in an array that the compiled step updates in place.
    automatic : bool
        The method is chosen per step size (``method="auto"`` without ``max_step``).
    automatic_step : float or None
        The step size [s] the automatic method was chosen for (None: not yet).
    operator_dt : float or None
        Internal step [s] of the exponential integrators' operator used by the last
        unsplit step (what the compiled step can reuse).
    """

    #: The result of a successful step (shared: results are immutable).
    ok = StepResult(True)

    def __init__(self, model: DrillstringModel, max_step: float | None = None,
                 method: str = "auto", rtol: float = 1e-6, atol: float = 1e-9) -> None:
        if method not in METHODS and method not in ("dopri5", "auto"):
            raise ValueError(f"method = {method!r} is not allowed: one of "
                             f"{', '.join(['auto', *METHODS, 'dopri5'])}")
        self.model = model
        self.automatic = method == "auto" and max_step is None
        self.automatic_step: float | None = None
        self.operator_dt: float | None = None
        self.rtol = float(rtol)
        self.atol = float(atol)
        self._hstate = np.zeros(1)
        self._max_step_given = max_step
        self._use_method(model.default_method if method == "auto" else method)
        self.clock = np.zeros(1)
        self.y = model.initial_state()
        self.u = np.zeros(model.n_inputs)
        self._names = self._state_names()
        #: names of the entries of the input vector (see ``DrillstringModel.input_names``)
        self.input_names = list(model.input_names)
        #: the most internal steps one step may take (:data:`MAX_SUBSTEPS`)
        self.max_substeps = MAX_SUBSTEPS

    @property
    def time(self) -> float:
        """The simulator's time [s]."""
        return float(self.clock[0])

    @time.setter
    def time(self, value: float) -> None:
        self.clock[0] = value

    def _use_method(self, method: str) -> None:
        """Take ``method`` and its internal step bound (given, or automatic)."""
        spec = METHODS.get(method)
        radius = spec.radius if spec is not None else None
        if self._max_step_given is not None:
            max_step = float(self._max_step_given)
        elif radius is None:
            max_step = math.inf
        elif radius == 0.0:
            raise ValueError(f"method = {method!r} has no automatic step (its stability region "
                             f"holds no part of the imaginary axis): give max_step (s)")
        else:
            max_step = stable_step(self.model.max_eigenvalue, radius)
        if not max_step > 0.0 or (math.isinf(max_step) and radius is not None):
            raise ValueError(f"max_step = {self._max_step_given!r} is not allowed: must be > 0 "
                             f"and finite (s)")
        self.method = method
        #: the method's entry of :data:`plant.integrators.METHODS` (None for dopri5)
        self.method_spec: Method | None = spec
        self.max_step = max_step
        if spec is None or spec.radius is not None:
            self.operator_dt = None

    def choose_method(self, h: float) -> None:
        """Take the automatic method for communication steps of ``h`` [s] (:attr:`automatic`;
        a step of a new size does it first)."""
        method = self.model.method_for_step(h)
        if method != self.method:
            self._use_method(method)
        self.automatic_step = h

    def _state_names(self) -> list[str]:
        m = self.model
        n = m.n
        if m.kind == "full3d":
            blocks = (("X", "Y", "Z"), ("psi", "theta", "phi"), ("vX", "vY", "vZ"),
                      ("wx", "wy", "wz"))
            body = [f"body{k + 1}.{c}" for b in blocks for k in range(n) for c in b]
        else:
            body = [f"body{k + 1}.{c}" for c in ("Z", "psi", "vZ", "wz") for k in range(n)]
        return body + list(m.aux_names)

    def set_inputs(self, u: np.ndarray) -> None:
        """Inputs held over the next steps, shape (n_inputs,), in the order of
        :attr:`input_names`: actuator forces [N] (site 1 C, site 1 E, site 2 C, ...), then the
        top-drive speed command [rad/s] or motor torque [N m] if the scene's top drive takes one.

        Raises
        ------
        ValueError
            If ``u`` does not have one value per input (the message lists the inputs).
        """
        u = np.asarray(u, dtype=float)
        if u.shape != self.u.shape:
            raise ValueError(f"inputs: {u.size} values given, the plant takes {self.u.size} "
                             f"({', '.join(self.input_names) or 'none'})")
        self.u[:] = u

    def check(self) -> StepResult:
        """Is the state finite and inside the model's range of validity? (compiled check)"""
        m = self.model
        code, i, val = check_state(m.kind == "full3d", m.n, self.y, *self.limits(),
                                   m.wR, m.p, m.ip)
        return self.report(code, i, val)

    @staticmethod
    def limits() -> tuple[float, float, float, float]:
        """Range of validity: lateral [m], tilt [rad], speed [m/s, rad/s], strain [1]."""
        return MAX_LATERAL, MAX_TILT, MAX_SPEED, MAX_STRAIN

    def report(self, code: int, i: int, val: float) -> StepResult:
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
        """``n_out`` output steps of ``h`` [s] in one compiled loop, recording outputs.

        Equals ``n_out`` calls of :meth:`do_step` + :meth:`outputs` bit for bit. For RK4, and
        for exponential Euler with one step an output step and no load switch inside one;
        other cases run that Python loop.

        Returns
        -------
        rec : numpy.ndarray, shape (completed + 1, len(idx))
            Outputs ``idx`` at the start and after each completed step.
        result : StepResult
        """
        m = self.model
        idx = np.asarray(idx, dtype=np.int64)
        if self.automatic and h > 0.0 and math.isfinite(h) and h != self.automatic_step:
            self.choose_method(h)
        if self.method == "rk4":
            code_m, op = RECORD_RK4, _NO_OPERATOR
        elif self.method == "expeuler" and self._expeuler_compiled(h, n_out):
            code_m, op = RECORD_EXPEULER, m.expeuler_operator(float(h))
        else:
            return self._record_in_python(h, n_out, idx)
        rec = np.empty((n_out + 1, len(idx)))
        k1, k2, k3, k4, yt = m._scratch
        done, code, i, val = run_record(
            m.model_id, code_m, self.time, h, n_out, self.max_step, m.breakpoints, self.y, m.p,
            m.ip, m.fp, self.u, m.wR, m.wF, m.wM, k1, k2, k3, k4, yt, *op, m._zbit_ref, m._out,
            idx, rec, np.array(self.limits()))
        self.time = self.time + done * h
        return rec[:done + 1], self.report(code, i, val)

    def _expeuler_compiled(self, h: float, n_out: int) -> bool:
        """One exponential Euler step an output step, no breakpoint inside one (see run_record)."""
        if math.ceil(h / self.max_step - 1e-9) > 1:
            return False
        t0, t1 = self.time, self.time + n_out * h
        tol = 1e-9 * max(1.0, abs(t1))
        for b in self.model.breakpoints:
            if t0 + tol < b < t1 - tol:
                k = (b - t0) / h
                if abs(k - round(k)) * h > tol:
                    return False
        return True

    def _record_in_python(self, h: float, n_out: int, idx: np.ndarray
                          ) -> tuple[np.ndarray, StepResult]:
        """The loop of :meth:`run_record` in Python, each step compiled where it can be."""
        rows = [self.outputs()[idx].copy()]
        res = StepResult(True)
        t0 = self.time
        recorded = np.zeros(len(idx))
        step = self.compiled_step(self.u, np.arange(self.u.size), recorded, idx)
        for k in range(n_out):
            if step is not None:
                res = step.step(t0 + k * h, h)
            else:
                res = self.do_step(t0 + k * h, h)
            if not res.ok and not res.quantity:
                break
            rows.append(recorded.copy() if res.ok and step is not None
                        else self.outputs()[idx].copy())
            if not res.ok:
                break
        return np.array(rows), res

    def _fail(self, what: str, quantity: str, value: float) -> StepResult:
        return StepResult(False, f"diverged at t = {self.time:.6g} s: {what}", self.time,
                          quantity, value)

    def refusal(self, t: float, h: float) -> StepResult | None:
        """Why a step from ``t`` [s] by ``h`` [s] is refused (state unchanged), or None.

        Refused: a step size that is not finite and > 0, a time ``t`` that is not the
        simulator's own (within 1e-9 relative), a non-finite input, or a step that needs more
        than :data:`MAX_SUBSTEPS` internal steps. For a valid ``h`` the automatic method is
        chosen for it first (:attr:`automatic`).
        """
        if not (h > 0.0 and math.isfinite(h)):
            return StepResult(False, f"step size {h!r} s at t = {t!r} s is not allowed: must be "
                                     f"> 0 and finite; step rejected (state unchanged)")
        if self.automatic and h != self.automatic_step:
            self.choose_method(h)
        if not (math.isfinite(t) and abs(t - self.time) <= 1e-9 * max(1.0, abs(t))):
            return StepResult(False, f"communication point t = {t!r} s is not the plant's time "
                                     f"{self.time!r} s; step rejected (state unchanged)")
        u = self.u.tolist()  # a few values: cheaper in Python than np.all(np.isfinite(...))
        bad = [f"{n} = {v!r}" for n, v in zip(self.input_names, u)
               if not math.isfinite(v)] if not math.isfinite(sum(u)) else None
        if bad:
            return StepResult(False, f"input {', '.join(bad)} is not finite at t = {t!r} s; "
                                     f"step rejected (state unchanged)")
        if self.method != "dopri5" and math.ceil(h / self.max_step) > MAX_SUBSTEPS:
            return StepResult(False, f"step size h = {h!r} s needs {math.ceil(h / self.max_step):.3g}"
                                     f" internal steps of {self.max_step:.3g} s, more than "
                                     f"{MAX_SUBSTEPS:g} allowed per step; step rejected (state "
                                     f"unchanged)")
        return None

    def do_step(self, t: float, h: float) -> StepResult:
        """Advance from ``t`` [s] by ``h`` [s] with the inputs held (in Python: the reference of
        the compiled step, :meth:`compiled_step`).

        The step is split at the model's load switch times (:attr:`DrillstringModel.breakpoints`)
        and each part into ``ceil(length / max_step)`` equal internal steps. A refused step
        (:meth:`refusal`) leaves the state unchanged and has no ``quantity``.
        """
        refused = self.refusal(t, h)
        if refused is not None:
            return refused
        if self.method == "rk4":
            self.time = self.model.advance_span(t, t + h, self.max_step, self.y, self.u)
            return self.check()
        bps = self.model.breakpoints
        t_start, t1 = t, t + h
        while t < t1:  # segments between the load switch times (see next_breakpoint)
            te = next_breakpoint(t, t1, bps)
            whole = t == t_start and te == t1
            length = h if whole else te - t  # (t + h) - t != h
            if self.method == "dopri5":
                code = self.model.advance_adaptive(t, te, self.y, self._hstate, self.rtol,
                                                   self.atol, self.u)
                self.time = te
                if code != 0:
                    res = self.check()
                    return res if not res.ok else StepResult(
                        False, f"adaptive step failed at t = {t:.6g} s (code {code})", t)
            else:
                n_sub = max(1, math.ceil(length / self.max_step - 1e-9))
                dt = length / n_sub
                if whole and self.method_spec.radius is None:
                    self.operator_dt = dt  # the exponential operator a compiled step can reuse
                done = self.model.advance(t, self.y, n_sub, dt, self.u, self.method)
                self.time = te if done == n_sub else t + done * dt
                if done < n_sub:
                    break
            t = te
        return self.check()

    def compiled_key(self) -> tuple:
        """What a compiled step's context depends on besides the arrays (method, internal step,
        automatic step size, operator step)."""
        return self.method, self.max_step, self.automatic_step, self.operator_dt

    def compiled_step(self, inputs: np.ndarray, in_index: np.ndarray, outputs: np.ndarray,
                      out_index: np.ndarray) -> CompiledStep | None:
        """This simulator's compiled step (:class:`plant.compiled_step.CompiledStep`), or None
        when there is none: compiled steps switched off (``DRILLCOSIM_COMPILED_STEP=0``), the
        adaptive ``dopri5``, or Verlet on a state with first-order auxiliary states.

        ``inputs`` / ``outputs`` are the buffers it reads and writes at every step
        (``u[in_index[j]] = inputs[j]``, ``outputs[j] = output out_index[j]``).
        """
        from . import compiled_step as cs

        if not cs.enabled() or self.method_spec is None or (
                self.method == "verlet" and self.model.n_state != self.model.n_body_state):
            return None
        return cs.CompiledStep(self, inputs, in_index, outputs, out_index)

    def outputs(self) -> np.ndarray:
        """Outputs at the current time, in the order of ``model.output_names`` (a reused view)."""
        return self.model.outputs(self.time, self.y, self.u)

    def get_state(self) -> tuple[float, np.ndarray, np.ndarray]:
        """A copy of (time, state, inputs) for FMU state save."""
        return self.time, self.y.copy(), self.u.copy()

    def set_state(self, state: tuple[float, np.ndarray, np.ndarray]) -> None:
        """Restore a state from :meth:`get_state`: all of it, or (ValueError: a state vector or
        inputs of another length) nothing."""
        t, y, u = state
        y, u = np.asarray(y, dtype=float), np.asarray(u, dtype=float)
        if y.shape != self.y.shape or u.shape != self.u.shape:
            raise ValueError(f"a state of {y.size} values and {u.size} inputs; this model has "
                             f"{self.y.size} and {self.u.size}")
        self.time = float(t)
        self.y[:] = y
        self.u[:] = u


def simulate(model: DrillstringModel, stop_time: float, output_interval: float,
             outputs: list[str] | None = None, max_step: float | None = None,
             method: str = "auto", rtol: float = 1e-6, atol: float = 1e-9,
             ) -> tuple[np.ndarray, dict[str, np.ndarray], StepResult]:
    """Run the plant alone (inputs zero) and sample outputs.

    ``max_step``, ``method``, ``rtol`` and ``atol`` as for :class:`PlantSimulator`.

    Returns
    -------
    t : numpy.ndarray, shape (k,)
        Sample times [s].
    values : dict of str -> numpy.ndarray, shape (k,)
        Requested outputs (all by default).
    result : StepResult
        ``ok`` or the divergence report; samples stop at the failure.
    """
    sim = PlantSimulator(model, max_step, method, rtol, atol)
    names = outputs or model.output_names
    idx = np.array([model.output_names.index(n) for n in names], dtype=np.int64)
    n_out = int(round(stop_time / output_interval))
    arr, res = sim.run_record(output_interval, n_out, idx)
    ts = np.arange(arr.shape[0]) * output_interval
    return ts, {n: arr[:, i] for i, n in enumerate(names)}, res
