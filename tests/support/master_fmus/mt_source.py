"""Tiny test FMU: signal source y(t) = amplitude * sin(omega * t).

y is evaluated at the FMU's current time (t_start after initialisation, the
end of the step after each doStep).
"""

import math

from _dcs_pythonfmu_0_7_0 import Fmi2Causality, Fmi2Slave, Fmi2Variability, Real


class MtSource(Fmi2Slave):
    """Sine source without inputs."""

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.amplitude = 1.0
        self.omega = 1.0
        self.t0 = 0.0
        self.y = 0.0
        par = Fmi2Causality.parameter
        tun = Fmi2Variability.tunable
        self.register_variable(Real("amplitude", causality=par, variability=tun))
        self.register_variable(Real("omega", causality=par, variability=tun))
        self.register_variable(Real("y", causality=Fmi2Causality.output))

    def setup_experiment(self, start_time, stop_time, tolerance):
        self.t0 = start_time

    def exit_initialization_mode(self):
        self.y = self.amplitude * math.sin(self.omega * self.t0)

    def do_step(self, current_time, step_size):
        self.y = self.amplitude * math.sin(self.omega * (current_time + step_size))
        return True

    def _get_fmu_state(self):
        return {"y": self.y}

    def _set_fmu_state(self, state):
        self.y = state["y"]
