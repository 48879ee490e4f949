"""The closed loop the third-party engines are compared on, run by our master as the reference.

``paper_closed_loop`` (plant FMU + a controller FMU, gain 1e9, unrestricted, on from t = 0)
with Jacobi stepping, no delays and a zero-order hold, the stepping the fixed-step
algorithms of libcosim and Ecos implement, at H = 0.1 ms (Jacobi adds one step of loop delay;
the paper's gain needs H <= ~0.1 ms then, design.md) for 1 s, written as an SSP file by our
export. Our master records every output at every base step, from t = 0.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from drillcosim.cosim.master.master import Master
from drillcosim.cosim.master.ssp import export_ssp
from drillcosim.cosim.master.system import SystemSpec
from drillcosim.cosim.scenario.build import build_system
from drillcosim.cosim.scenario.config import load_config

__all__ = ["STEP", "STOP", "ClosedLoop", "closed_loop"]

STEP = 1e-4  #: base step [s]
STOP = 1.0   #: stop time [s]


@dataclass(frozen=True)
class ClosedLoop:
    """A closed loop, its SSP file and our master's result.

    Attributes
    ----------
    system : SystemSpec
    outputs : tuple of str
        ``'inst.var'`` recorded (plant outputs, then the controller's forces).
    ssp : Path
        Our export of ``system``; its parameter sets are named :attr:`parameter_set`.
    parameter_set : str
    data : numpy.ndarray
        Our master's structured result, rows at t = 0, H, 2H, ..., stop.
    step, stop : float
        [s].
    """

    system: SystemSpec
    outputs: tuple[str, ...]
    ssp: Path
    parameter_set: str
    data: np.ndarray
    step: float
    stop: float

    @property
    def n_steps(self) -> int:
        """Number of base steps from 0 to :attr:`stop`."""
        return round(self.stop / self.step)


def closed_loop(plant_fmu: Path, controller_fmu: Path, folder: Path, step: float = STEP,
                stop: float = STOP, name: str = "closed_loop") -> ClosedLoop:
    """Build, export and run the comparison loop with the given FMUs."""
    config = load_config("paper_closed_loop", {
        "cosim.step": step, "cosim.stop_time": stop, "cosim.algorithm": "jacobi",
        "cosim.order": ["plant", "controller"]}, plant_fmu=plant_fmu,
        controller_fmu=controller_fmu)
    ss = build_system(config, "fmu")
    system = ss.system
    assert system.algorithm == "jacobi"
    assert all(c.delay == 0 and c.coupling == "zoh" for c in system.connections)
    assert len(system.connections) == 8
    folder.mkdir(parents=True, exist_ok=True)
    exp = export_ssp(system, folder / f"{name}.ssp", name=name)
    assert exp.omitted == ()
    data = Master(system).simulate(stop, ss.outputs).data
    return ClosedLoop(system, ss.outputs, exp.path, name, data, step, stop)
