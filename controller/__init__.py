"""drillcosim controller package: pure strain-feedback laws (no FMI code).

All imports inside this package are relative and it depends on numpy only: the
FMU build vendors a copy of it under a versioned name (``_dcs_controller_<ver>``)
into the controller FMU, so that copy can never shadow, or be shadowed by, a
``controller`` package imported by the host process.
"""

from .params import MODES, ControllerParams, Mode
from .strain_feedback import CHANNELS, N_CHANNELS, SWITCH_TIME_RTOL, StrainController

__version__ = "0.1.0"

__all__ = [
    "CHANNELS",
    "MODES",
    "N_CHANNELS",
    "SWITCH_TIME_RTOL",
    "ControllerParams",
    "Mode",
    "StrainController",
    "__version__",
]
