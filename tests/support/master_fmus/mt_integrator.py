"""Tiny test FMU: integrator x' = u, exact for an input held over each step.

Parameters: x0 (initial state), fail_at_time / nan_at_time (negative = never):
from the first step starting at or after that time, do_step returns False
(fmi2Discard) when ``fail_mode == 0`` or raises (fmi2Error/Fatal) otherwise, or
the output x becomes NaN. Outputs: x, n_steps (number of doStep calls) and
last_h (size of the last step).
"""

from _dcs_pythonfmu_0_7_0 import Fmi2Causality, Fmi2Slave, Fmi2Variability, Integer, Real


class MtIntegrator(Fmi2Slave):
    """Integrator xdot = u with failure injection, for master tests."""

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.x0 = 0.0
        self.fail_at_time = -1.0
        self.nan_at_time = -1.0
        self.fail_mode = 0
        self.u = 0.0
        self.x = 0.0
        self.n_steps = 0.0
        self.last_h = 0.0
        par = Fmi2Causality.parameter
        tun = Fmi2Variability.tunable
        self.register_variable(Real("x0", causality=par, variability=tun))
        self.register_variable(Real("fail_at_time", causality=par, variability=tun))
        self.register_variable(Real("nan_at_time", causality=par, variability=tun))
        self.register_variable(Integer("fail_mode", causality=par, variability=tun))
        self.register_variable(Real("u", causality=Fmi2Causality.input))
        self.register_variable(Real("x", causality=Fmi2Causality.output))
        self.register_variable(Real("n_steps", causality=Fmi2Causality.output))
        self.register_variable(Real("last_h", causality=Fmi2Causality.output))

    def exit_initialization_mode(self):
        self.x = float(self.x0)

    def do_step(self, current_time, step_size):
        if 0.0 <= self.fail_at_time <= current_time + 1e-12:
            if self.fail_mode == 0:
                return False
            raise RuntimeError("injected failure")
        self.x = self.x + self.u * step_size
        if 0.0 <= self.nan_at_time <= current_time + 1e-12:
            self.x = float("nan")
        self.n_steps += 1.0
        self.last_h = step_size
        return True

    def _get_fmu_state(self):
        return {"x": self.x, "u": self.u, "n_steps": self.n_steps, "last_h": self.last_h}

    def _set_fmu_state(self, state):
        for key, value in state.items():
            setattr(self, key, value)
