"""drillcosim.cosim.scenario: a scene becomes a co-simulation system and is simulated.

* :mod:`.scene_system` - scene -> system: the ``[cosim]`` and ``[controller]`` tables, finding
  and building the FMUs, the wiring of plant and controller;
* :mod:`.interface` - a plant/controller FMU pair wired by name and checked;
* :mod:`.inprocess` - the plant simulator and the controller law as in-process slaves that
  stand in for the FMUs (same numbers, no FMI boundary);
* :mod:`.run` - ``drillcosim run``: simulate a scene into a folder (results, summary, plots);
* :mod:`.ssp_run` - SSP files: simulate one, write a scene's;
* :mod:`.summary` - the run summary (``summary.json``);
* :mod:`.plots` - the figures of a run.
"""
