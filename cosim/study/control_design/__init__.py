"""drillcosim.cosim.study.control_design: lateral controllers beyond the P law, designed on the
linearized plant.

* :mod:`.plant_model` - the stability module's linearized, sampled plant with the performance
  (lateral displacements) and disturbance (lateral body forces) channels, and the delay line;
* :mod:`.closed_loop` - the closed loop of that plant with any discrete state-space controller:
  eigenvalues, growth rate;
* :mod:`.lqg` - LQR with the delay line in the state + Kalman filter on the strains (MIMO);
* :mod:`.predictor` - the sampled Smith predictor around the strain P law;
* :mod:`.design` - the design API and the scene it writes.
"""

from .closed_loop import closed_loop_matrix, growth_rate, loop_spectral_radius
from .design import KINDS, Design, design_controller, design_on_plant, write_scene
from .lqg import LqgWeights
from .plant_model import LoopPlant, augment

__all__ = ["KINDS", "Design", "LoopPlant", "LqgWeights", "augment", "closed_loop_matrix",
           "design_controller", "design_on_plant", "growth_rate", "loop_spectral_radius",
           "write_scene"]
