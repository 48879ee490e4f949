"""Tiny test FMU: one mass of a two-mass oscillator.

m x'' = -k x - kc (x - x_other) - c x', x_other held constant over a step,
integrated with classical RK4 on substeps of at most h_max (error far below
the coupling error).  Input: x_other [m].  Outputs: x [m], v [m/s].
"""

import math

from _dcs_pythonfmu_0_7_0 import Fmi2Causality, Fmi2Slave, Fmi2Variability, Real


class MtMass(Fmi2Slave):
    """Single mass on a spring to ground and a coupling spring."""

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.m = 1.0
        self.k = 1.0
        self.kc = 1.0
        self.c = 0.0
        self.x0 = 0.0
        self.v0 = 0.0
        self.h_max = 1e-3
        self.x_other = 0.0
        self.x = 0.0
        self.v = 0.0
        par = Fmi2Causality.parameter
        tun = Fmi2Variability.tunable
        for name in ("m", "k", "kc", "c", "x0", "v0", "h_max"):
            self.register_variable(Real(name, causality=par, variability=tun))
        self.register_variable(Real("x_other", causality=Fmi2Causality.input))
        self.register_variable(Real("x", causality=Fmi2Causality.output))
        self.register_variable(Real("v", causality=Fmi2Causality.output))

    def exit_initialization_mode(self):
        self.x = float(self.x0)
        self.v = float(self.v0)

    def do_step(self, current_time, step_size):
        n = max(1, math.ceil(step_size / self.h_max - 1e-9))
        h = step_size / n
        m, k, kc, c, xo = self.m, self.k, self.kc, self.c, self.x_other
        x, v = self.x, self.v

        def acc(x, v):
            return (-k * x - kc * (x - xo) - c * v) / m

        for _ in range(n):
            k1x, k1v = v, acc(x, v)
            k2x, k2v = v + 0.5 * h * k1v, acc(x + 0.5 * h * k1x, v + 0.5 * h * k1v)
            k3x, k3v = v + 0.5 * h * k2v, acc(x + 0.5 * h * k2x, v + 0.5 * h * k2v)
            k4x, k4v = v + h * k3v, acc(x + h * k3x, v + h * k3v)
            x += h / 6.0 * (k1x + 2 * k2x + 2 * k3x + k4x)
            v += h / 6.0 * (k1v + 2 * k2v + 2 * k3v + k4v)
        self.x, self.v = x, v
        return True

    def _get_fmu_state(self):
        return {"x": self.x, "v": self.v, "x_other": self.x_other}

    def _set_fmu_state(self, state):
        for key, value in state.items():
            setattr(self, key, value)
