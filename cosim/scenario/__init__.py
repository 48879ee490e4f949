"""drillcosim.cosim.scenario: a scene becomes a co-simulation system and is run.

:mod:`.scene_system` (scene -> system, finding and building the FMUs), :mod:`.run` (one run:
results, summary, plots), :mod:`.summary`, :mod:`.plots`.
"""
