"""drillcosim.cosim.scenario: a scene becomes a typed configuration, a system, a result.

The way through, one module per step:

* :mod:`.config` - a scene file and overrides -> :class:`~.config.SceneConfig` (parsed and
  validated once; times as integer numbers of steps; one override mechanism by key path);
* :mod:`.build` - :func:`~.build.build_system` (config, engine ``"fmu"`` | ``"inprocess"``)
  -> the system and its slaves; :mod:`.scene_fmus` finds and builds the project's FMUs,
  :mod:`.interface` wires instances by name and checks them, :mod:`.inprocess` holds the
  in-process slaves;
* :mod:`.simulate` - the one call of the master for a run; :mod:`.result` - what a run gives
  (data with units, ``to_pandas``, summary, plots, files; :mod:`.summary`, :mod:`.plots`);
* :mod:`.ssp_run` - SSP files: simulate one, write a configuration's;
* :mod:`.schema` - the scene schema as markdown.

Signal and instance names come from :mod:`plant.signals`.
"""
