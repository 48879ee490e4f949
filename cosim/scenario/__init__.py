"""drillcosim.cosim.scenario: a scene becomes a co-simulation system and is run.

:mod:`.scene_system` (scene -> system, finding and building the FMUs), :mod:`.interface` (a
plant/controller FMU pair wired by name and checked), :mod:`.run` (one run: results, summary,
plots), :mod:`.ssp_run` (SSP files: run one, write a scene's), :mod:`.summary`, :mod:`.plots`.
"""
