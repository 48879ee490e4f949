"""The recorded result is what fmpy's plotting takes: fmpy builds its figure from it."""

from __future__ import annotations

import numpy as np
from test_master_mechanics import plant_loop

from drillcosim.cosim.master.master import Master
from support.required import import_module


def test_fmpy_plot_result_accepts_the_recorded_array(fmus):
    """fmpy.util.plot_result = create_plotly_figure + show/write: the figure gets one trace per
    recorded variable with our time axis and values."""
    import_module("plotly")
    from fmpy.util import create_plotly_figure

    res = Master(plant_loop(fmus, {})).simulate(0.2, outputs=["plant.x", "ctrl.y"],
                                                  output_interval=0.05)
    fig = create_plotly_figure(res.data)
    traces = {tr.name: tr for tr in fig.data}
    assert set(traces) == {"plant.x", "ctrl.y"}
    for name, tr in traces.items():
        np.testing.assert_array_equal(np.asarray(tr.y, dtype=float), res.data[name])
        assert len(tr.x) == len(res.data["time"])
