"""Tiny test FMU: static gain y = -k * u with direct feedthrough.

The output is computed when it is read, from the input last set, so with
k = -1 it is a probe that echoes its input. Outputs: y, n_steps.
"""

from _dcs_pythonfmu_0_7_0 import Fmi2Causality, Fmi2Slave, Fmi2Variability, Real


class MtGain(Fmi2Slave):
    """Proportional controller y = -k u (direct feedthrough)."""

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.k = 1.0
        self.u = 0.0
        self.n_steps = 0.0
        self.register_variable(
            Real("k", causality=Fmi2Causality.parameter, variability=Fmi2Variability.tunable)
        )
        self.register_variable(Real("u", causality=Fmi2Causality.input))
        self.register_variable(
            Real("y", causality=Fmi2Causality.output, getter=lambda: -self.k * self.u)
        )
        self.register_variable(Real("n_steps", causality=Fmi2Causality.output))

    def do_step(self, current_time, step_size):
        self.n_steps += 1.0
        return True

    def _get_fmu_state(self):
        return {"u": self.u, "n_steps": self.n_steps}

    def _set_fmu_state(self, state):
        for key, value in state.items():
            setattr(self, key, value)
