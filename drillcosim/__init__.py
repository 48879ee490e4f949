"""drillcosim: drillstring vibration control by FMI co-simulation.

One import namespace; the repository's top-level folders install as its subpackages
(``pyproject.toml``, setuptools ``package-dir``):

================================  ==========================================================
``drillcosim.plant``              pure physics: parameters, scenes, model, kernels, integrators
``drillcosim.controller``         pure controller laws (strain P-feedback, saturation, lag)
``drillcosim.fmu_src``            thin pythonfmu adapters, the C FMI wrapper, the FMU build
``drillcosim.cosim.master``       the generic FMI co-simulation master (no drillstring code)
``drillcosim.cosim.scenario``     scene -> system, finding/building FMUs, run, summary, plots
``drillcosim.cosim.study``        sweeps, stability prediction, maps
``drillcosim.cosim.cli``          the ``drillcosim`` command line
``drillcosim.scenes``             the shipped scene files (package data)
================================  ==========================================================
"""

__version__ = "0.2.0"
