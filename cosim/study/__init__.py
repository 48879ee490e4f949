"""drillcosim.cosim.study: sweeps over gain, delay and step, their verdicts, and the stability
prediction.

* :mod:`.grid` - value lists from the command line, the points of a sweep;
* :mod:`.point` - measure one point: simulate it through the master, compute its metrics;
* :mod:`.verdict` - when a point supports a stability verdict (the judging window) and which;
* :mod:`.table` - the resumable results table (CSV and Parquet), derived columns from all rows;
* :mod:`.sweep` - execute a sweep on an executor (process pool, Dask, inline);
* :mod:`.stability` - the linear discrete-time prediction of the sampled loop;
* :mod:`.maps` - stability and benefit maps with the predicted boundary.
"""
