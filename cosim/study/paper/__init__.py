"""drillcosim.cosim.study.paper: the paper's study, on top of the generic study tools.

* :mod:`.calibration` - the quantities the paper leaves open, calibrated against its Figs. 9-11
  (ensembles of :mod:`cosim.study.scene_stats` points);
* :mod:`.experiments` - its experiments point by point, next to its numbers;
* :mod:`.conclusion` - its conclusion tested: sites per span x gain x delay;
* :mod:`.calibration_report`, :mod:`.conclusion_report` - the tables and figures;
* :mod:`.stages` - ``drillcosim calibrate STAGE``.
"""
