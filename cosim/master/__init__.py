"""drillcosim.cosim.master: a generic FMI 2.0 co-simulation master on fmpy.

It imports nothing from the drillstring packages (plant, controller, fmu_src): any FMI 2.0
co-simulation FMUs can be coupled. The pieces, each with one job (as in libcosim):

* :mod:`.system` - the typed description of a system (FMU instances, connections, steps);
* :mod:`.slave` - the slave protocol the algorithms drive (a numbered contract), and
  :class:`~.slave.FmuSlave`, an FMU instance behind fmpy's low-level API;
* :mod:`.algorithms` - Jacobi / Gauss-Seidel stepping with multirate sampling, and the
  exchange timing (:func:`~.algorithms.newest_sample_tick`) stated once;
* :mod:`.delays` - transport delays and coupling (hold, extrapolation) on connections;
* :mod:`.execution` - owns time (integer ticks) and calls algorithm, observers, manipulators;
* :mod:`.native` - the same stepping in chunks of steps in C (the FMUs' entry points called
  from C, Python between chunks), chosen by the execution wherever it applies;
* :mod:`.recorder`, :mod:`.progress`, :mod:`.limits` - observers (read only);
* :mod:`.manipulators` - scenario events and fault injection (write only);
* :mod:`.errors` - the one place FMI statuses become exceptions;
* :mod:`.fmi_log` - FMU log messages through the FMI logger callback;
* :mod:`.files` - atomic files (every file the project publishes);
* :mod:`.unpack` - where FMUs are unpacked (once per content, in the user cache);
* :mod:`.ssp` - SSP 1.0 export; :mod:`.ssp_import` - SSP 1.0 import;
* :mod:`.interface` - the check that connected FMU variables fit (before the first step);
* :mod:`.master` - :class:`~.master.Master`: simulate a system to a stop time and return its
  recorded result.
"""

from .errors import CosimError, DivergenceError
from .execution import Execution, ExecutionState
from .master import Divergence, Master, Result
from .recorder import Recorder
from .system import Connection, FmuSpec, SystemSpec, system_from_dict

__all__ = ["Connection", "CosimError", "Divergence", "DivergenceError", "Execution",
           "ExecutionState", "FmuSpec", "Master", "Recorder", "Result", "SystemSpec",
           "system_from_dict"]
