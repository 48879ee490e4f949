"""drillcosim: analysis package.

What is computed *about* the plant rather than by its runtime: the static equilibrium
(:mod:`.equilibrium`), the linearization in the top-drive frame (:mod:`.linearize`), the modes
(:mod:`.modal`) and the continuous-time closed loop with a pure actuator delay
(:mod:`.closed_loop`, the reference of the delay study). It imports the plant; the plant never
imports it, and the plant FMU does not carry it.

Importing the package drops numba's on-disk cache of this package when any of its sources or
the plant's changed (:func:`drillcosim.plant.drop_stale_numba_cache`): the closed loop's
cached machine code contains the plant kernels it calls.
"""

from __future__ import annotations

from pathlib import Path

from drillcosim import plant
from drillcosim.plant import drop_stale_numba_cache

drop_stale_numba_cache(Path(__file__).resolve().parent,
                       depends_on=(Path(plant.__file__).resolve().parent,))
