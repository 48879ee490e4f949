"""The instance names of a scene's system (a light module: the figures and the summary need
them without the scene machinery)."""

__all__ = ["CONTROLLER", "PLANT", "TOP_DRIVE"]

PLANT = "plant"            #: instance name of the plant FMU
CONTROLLER = "controller"  #: instance name of the strain controller FMU
TOP_DRIVE = "top_drive_controller"  #: instance name of the top-drive controller FMU
