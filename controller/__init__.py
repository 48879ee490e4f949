"""drillcosim controller package: pure controller laws (no FMI code): the strain feedback of
the bending actuators, a generic discrete state-space law and the top-drive speed controller,
each a plug-in (``law.py``: the contract; ``registry.py``: the registered laws; ``ports.py``:
the port tables' rows and the names with numbers).

All imports inside this package are relative and it depends on numpy only (the compiled
steps, ``compiled.py``, use numba where it is installed; nothing imports them otherwise): the
FMU build vendors a copy of it under a versioned name (``_dcs_controller_<ver>``)
into the controller FMU, so that copy can never shadow, or be shadowed by, a
``controller`` package imported by the host process.
"""

from .law import Law, Settings, setting
from .params import MODES, ControllerParams, Mode, check_gain_matrix
from .registry import LAWS, TABLES, default_kind, kinds, law_named
from .state_space import Signal, StateSpaceController, StateSpaceParams
from .strain_feedback import (
    AXES,
    CHANNELS,
    N_CHANNELS,
    SWITCH_TIME_RTOL,
    StrainController,
    channels,
)
from .top_drive import TopDriveController, TopDriveControllerParams

__all__ = [
    "AXES",
    "CHANNELS",
    "MODES",
    "N_CHANNELS",
    "SWITCH_TIME_RTOL",
    "ControllerParams",
    "LAWS",
    "Law",
    "Mode",
    "Settings",
    "TABLES",
    "Signal",
    "StateSpaceController",
    "StateSpaceParams",
    "StrainController",
    "TopDriveController",
    "TopDriveControllerParams",
    "channels",
    "check_gain_matrix",
    "default_kind",
    "kinds",
    "law_named",
    "setting",
]
