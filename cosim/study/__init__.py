"""drillcosim.cosim.study: sweeps over gain, delay and step, their verdicts, ensembles, and the
stability prediction; the paper's own study in :mod:`.paper`.

* :mod:`.grid` - value lists from the command line, the points of a sweep;
* :mod:`.point` - measure one point: its configuration through the one builder and master
  call (:mod:`cosim.scenario.build`, :mod:`cosim.scenario.simulate`), its metrics;
* :mod:`.verdict` - when a point supports a stability verdict (the judging window) and which;
* :mod:`.table` - the resumable results table (CSV and Parquet), derived columns from all rows;
* :mod:`.sweep` - execute a sweep on an executor (process pool, Dask, inline);
* :mod:`.ensemble`, :mod:`.scene_stats` - perturbed ensemble members and their statistics;
* :mod:`.stability` - the linear discrete-time prediction of the sampled loop;
  :mod:`.continuous` - its continuous-time limit;
* :mod:`.maps` - stability and benefit maps with the predicted boundary;
* :mod:`.paper` - the paper's calibration, experiments and conclusion, and their reports.
"""
