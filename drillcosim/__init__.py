"""drillcosim: drillstring vibration control by FMI co-simulation.

The public API (:mod:`drillcosim.api`, numpydoc with units)::

    import drillcosim
    res = drillcosim.simulate("paper_closed_loop", stop_time=1.0, delay=1e-4)
    res.to_pandas()        # index time [s], columns 'instance.variable'
    res.units, res.summary, res.plot(), res.save("out/run")
    drillcosim.sweep("paper_closed_loop", gains=[1e8, 1e9], delays=[0, 1e-4])  # DataFrame
    drillcosim.list_scenes(), drillcosim.load_scene("stick_slip"), drillcosim.modes()
    drillcosim.build_fmus()

One import namespace; the repository's top-level folders install as its subpackages
(``pyproject.toml``, setuptools ``package-dir``):

================================  ==========================================================
``drillcosim.plant``              the plant's runtime: parameters, scenes, model, kernels, stepping
``drillcosim.analysis``           about the plant: equilibrium, linearization, modes, the
                                  continuous-time closed loop with a pure delay
``drillcosim.controller``         pure controller laws (strain P-feedback, top-drive PI)
``drillcosim.fmu_src``            thin pythonfmu adapters, the C FMI wrapper, the FMU build
``drillcosim.cosim.master``       the generic FMI co-simulation master (no drillstring code)
``drillcosim.cosim.scenario``     scene -> typed config -> system (FMUs or in process) -> result
``drillcosim.cosim.study``        sweeps, ensembles, stability prediction, maps; ``.paper``:
                                  the paper's calibration, experiments and conclusion
``drillcosim.cosim.cli``          the ``drillcosim`` command line (on top of the API)
``drillcosim.scenes``             the shipped scene files (package data)
================================  ==========================================================

The API is loaded on first use (``import drillcosim`` stays cheap for the command line), and so
is ``__version__``: the installed distribution's version (:mod:`importlib.metadata`), whose one
source is ``pyproject.toml``.
"""

_API = ("ENGINES", "Result", "SceneConfig", "UserError", "build_fmus", "list_scenes",
        "load_scene", "modes", "simulate", "sweep")
__all__ = ["__version__", *_API]


def __getattr__(name: str):
    if name == "__version__":
        from ._version import __version__ as found

        globals()["__version__"] = found
        return found
    if name in _API:
        from . import api  # the API's imports (numpy, fmpy, the master) only when used

        return getattr(api, name)
    raise AttributeError(f"module 'drillcosim' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted({*globals(), "__version__", *_API})
