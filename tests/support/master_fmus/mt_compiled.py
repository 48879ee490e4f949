"""Tiny test FMU of the wrapper's compiled-step protocol: integrator x' = u.

The step is a numba ``@cfunc`` (``int32(voidptr, float64, float64)``) over one float64 array
``ctx = [u, x, n_compiled, n_python, fail_at_time]``; the Real buffers are views of it (input
``u``, outputs ``x, n_compiled, n_python``), so the step reads its input and writes its outputs
where the wrapper moves them. ``use_compiled`` (Boolean parameter) switches the accelerator off:
``do_step`` in Python is the reference. From the first step starting at or after
``fail_at_time`` (>= 0) the step fails with code 7; ``_fmi2_compiled_step_failed`` (or the
Python ``do_step``) turns it into fmi2Discard with a message naming the time.
"""

import numpy as np
from _dcs_pythonfmu_0_7_0 import Boolean, Fmi2Causality, Fmi2Slave, Fmi2Variability, Real
from numba import carray, cfunc, types

U, X, N_COMPILED, N_PYTHON, FAIL_AT = range(5)


@cfunc(types.int32(types.voidptr, types.float64, types.float64), nopython=True)
def _step(context, t, h):
    c = carray(context, 5, dtype=np.float64)
    if 0.0 <= c[FAIL_AT] <= t + 1e-12:
        return 7
    c[X] = c[X] + c[U] * h
    c[N_COMPILED] += 1.0
    return 0


class MtCompiled(Fmi2Slave):
    """Integrator with a compiled step, for the wrapper's protocol tests."""

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.ctx = np.zeros(5)
        self.ctx[FAIL_AT] = -1.0
        self.use_compiled = True
        self.messages = []
        par, tun = Fmi2Causality.parameter, Fmi2Variability.tunable
        self.register_variable(Boolean("use_compiled", causality=par, variability=tun))
        self._register("fail_at_time", FAIL_AT, par, tun)
        self._register("u", U, Fmi2Causality.input)
        self._register("x", X, Fmi2Causality.output)
        self._register("n_compiled", N_COMPILED, Fmi2Causality.output)
        self._register("n_python", N_PYTHON, Fmi2Causality.output)

    def _register(self, name, i, causality, variability=None):
        ctx = self.ctx

        def getter():
            return float(ctx[i])

        def setter(value):
            ctx[i] = value

        kw = {"variability": variability} if variability is not None else {}
        self.register_variable(Real(name, causality=causality, getter=getter, setter=setter,
                                    **kw), nested=False)

    def _fmi2_real_buffers(self):
        vr = {v.name: r for r, v in self.vars.items()}
        return ([vr["u"]], self.ctx[U:U + 1], [vr["x"], vr["n_compiled"], vr["n_python"]],
                self.ctx[X:N_PYTHON + 1])

    def _fmi2_compiled_step(self):
        return (_step.address, self.ctx.ctypes.data) if self.use_compiled else None

    def _fmi2_compiled_step_failed(self, code, t, h):
        self.log(f"{self.instance_name}: step failed at t = {t!r} s (code {code})")
        return False

    def do_step(self, current_time, step_size):
        if 0.0 <= self.ctx[FAIL_AT] <= current_time + 1e-12:
            return self._fmi2_compiled_step_failed(7, current_time, step_size)
        self.ctx[X] = self.ctx[X] + self.ctx[U] * step_size
        self.ctx[N_PYTHON] += 1.0
        return True

    def _get_fmu_state(self):
        return {"ctx": self.ctx.tolist(), "use_compiled": self.use_compiled}

    def _set_fmu_state(self, state):
        self.ctx[:] = state["ctx"]
        self.use_compiled = state["use_compiled"]
