"""drillcosim.cosim.study: sweeps over gain, delay and step, and the stability prediction.

:mod:`.grid` (value lists, points), :mod:`.point` (one point and its metrics), :mod:`.table`
(the resumable results table), :mod:`.sweep` (executors: process pool, Dask), :mod:`.stability`
(linear discrete-time prediction), :mod:`.maps` (stability and benefit maps).
"""
