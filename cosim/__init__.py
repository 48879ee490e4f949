"""drillcosim: cosim package — the FMI 2 co-simulation master on fmpy.

Public API::

    from cosim import (SystemSpec, FmuSpec, Connection, system_from_dict,
                       CoSimulation, Result, Execution, Recorder,
                       CosimError, DivergenceError)
"""

from .errors import CosimError, DivergenceError
from .execution import Execution, ExecutionState
from .master import CoSimulation, Divergence, Result
from .recorder import Recorder
from .system import Connection, FmuSpec, SystemSpec, system_from_dict

__all__ = ["Connection", "CoSimulation", "CosimError", "Divergence", "DivergenceError",
           "Execution", "ExecutionState", "FmuSpec", "Recorder", "Result", "SystemSpec",
           "system_from_dict"]
