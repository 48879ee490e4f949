"""PNG plots of a run (cosim.scenario.plots): which figures a run's recorded outputs give."""

from __future__ import annotations

import numpy as np
from matplotlib.image import imread

from drillcosim.cosim.scenario.plots import plot_axial_torsional, plot_run


def _record(names: list[str], n: int = 400) -> np.ndarray:
    t = np.linspace(0.0, 4.0, n)
    data = np.zeros(n, dtype=[("time", float)] + [(c, float) for c in names])
    data["time"] = t
    for k, c in enumerate(names):
        data[c] = np.sin((k + 1) * t)
    return data


def test_a_chain_run_gets_the_axial_torsional_figure_only(tmp_path) -> None:
    data = _record(["plant.top_rotary_speed", "plant.bit_rotary_speed", "plant.top_torque",
                    "plant.bit_torque", "plant.bit_axial_force", "plant.bit_on_bottom"])
    paths = plot_run(data, tmp_path, clearance=0.02, title="chain")
    assert [p.name for p in paths] == ["axial_torsional.png"]
    assert imread(paths[0]).shape[0] > 800     # three stacked panels (2.4 in each, 120 dpi)


def test_panels_follow_the_recorded_outputs(tmp_path) -> None:
    one = plot_axial_torsional(_record(["plant.bit_rotary_speed"]), tmp_path / "one.png")
    three = plot_axial_torsional(_record(["plant.bit_rotary_speed", "plant.bit_torque",
                                          "plant.bit_axial_force"]), tmp_path / "three.png")
    assert imread(three).shape[0] > 2 * imread(one).shape[0]
    assert plot_axial_torsional(_record(["plant.hook_load"]), tmp_path / "none.png") is None
    assert not (tmp_path / "none.png").exists()


def test_a_3d_run_keeps_the_lateral_figures(tmp_path) -> None:
    data = _record(["plant.body11_X", "plant.body11_Y", "plant.body11_radial_deflection",
                    "plant.body11_contact_force", "plant.bit_rotary_speed"])
    names = sorted(p.name for p in plot_run(data, tmp_path, clearance=0.02))
    assert names == ["deflection_contact.png", "orbit.png"]


def test_a_chain_run_summary_has_no_bending_actuators(tmp_path) -> None:
    """stick_slip keeps the default [actuators] joints, but its chain has no bending actuators:
    the summary must not list two sites with zero force."""
    import json

    from drillcosim import simulate

    res = simulate("stick_slip", stop_time=0.5)
    res.save(tmp_path, plots=False)
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert res.completed and summary["actuators"] == {}
    assert summary["torsional"]["bit_speed_max_rad_s"] > 0.0


def test_envelope_keeps_every_pixel_columns_min_and_max() -> None:
    """Against the undecimated data: in each of the columns of a 300-dpi figure, the decimated
    series has the same smallest and largest value, and the same first and last sample."""
    from drillcosim.cosim.scenario.plots import envelope

    rng = np.random.default_rng(7)
    n, columns = 30001, 1500
    t = np.linspace(0.0, 30.0, n)
    y = np.sin(7.3 * t) * np.exp(0.05 * t) + 0.3 * rng.standard_normal(n)
    y[12345] = 40.0                          # single-sample spikes must survive
    y[23456] = -55.0
    td, yd = envelope(t, y, columns)
    assert len(td) <= 4 * columns < n / 4
    assert np.all(np.diff(td) > 0)           # in time order, no sample twice
    edges = np.linspace(t[0], t[-1], columns + 1)
    col, cold = (np.clip(np.searchsorted(edges, x, side="right") - 1, 0, columns - 1)
                 for x in (t, td))
    for c in range(columns):
        full, dec = y[col == c], yd[cold == c]
        assert dec.min() == full.min() and dec.max() == full.max()
        assert dec[0] == full[0] and dec[-1] == full[-1]
    assert yd.max() == 40.0 and yd.min() == -55.0
    short_t, short_y = envelope(t[:100], y[:100], columns)   # fewer samples: all kept
    assert np.array_equal(short_t, t[:100]) and np.array_equal(short_y, y[:100])


def test_thin_path_keeps_the_path_to_one_pixel() -> None:
    """Every dropped orbit sample lies in the pixel of a kept sample of its run; the samples
    where the path changes pixel are all kept."""
    from drillcosim.cosim.scenario.plots import thin_path

    s = np.linspace(0.0, 60.0, 30001)
    x, y = 20 * np.cos(s) * np.cos(0.1 * s), 20 * np.sin(s) * np.cos(0.07 * s)
    cell = 0.03
    xd, yd = thin_path(x, y, cell)
    assert len(xd) < len(x)
    kept = {(a, b) for a, b in zip(np.floor(xd / cell), np.floor(yd / cell))}
    assert all((a, b) in kept for a, b in zip(np.floor(x / cell), np.floor(y / cell)))
    assert (xd[0], yd[0], xd[-1], yd[-1]) == (x[0], y[0], x[-1], y[-1])


def test_a_long_run_is_drawn_from_its_envelope(tmp_path) -> None:
    """A run of 30001 samples is denser than the pixels: each trace is a band between its smallest
    and largest value per bin of two saved pixels, the data's extremes kept; a short run is a
    line of its samples."""
    from drillcosim.cosim.scenario import plots

    data = _record(["plant.body11_X", "plant.body11_Y", "plant.body11_radial_deflection",
                    "plant.body11_contact_force"], n=30001)
    fig = plots.DeflectionContactFigure.build(data, 0.02)
    fig.update(data)
    fig.save(tmp_path / "d.png")
    assert len(fig.series) == 2 and imread(tmp_path / "d.png").shape[:2] == (756, 600)
    for tr in fig.series:
        y = data[f"{tr.fmu}.{tr.output}"] * tr.scale
        (verts,) = [p.vertices for p in tr.band.get_paths()]
        px = fig._pixels(tr.line.axes)
        assert len(tr.line.get_xdata()) == 0 and len(verts) <= 2 * (px // 2) + 5  # closed
        assert verts[:, 1].min() == y.min() and verts[:, 1].max() == y.max()
        assert verts[:, 0].min() == 0.0 and verts[:, 0].max() == data["time"][-1]
    short = _record(["plant.body11_X", "plant.body11_Y", "plant.body11_radial_deflection",
                     "plant.body11_contact_force"], n=300)
    fig = plots.DeflectionContactFigure.build(short, 0.02)
    fig.update(short)
    assert all(len(tr.line.get_xdata()) == 300 and not tr.band.get_paths()
               for tr in fig.series)


def test_plot_workers_write_the_same_figures_as_this_process(tmp_path) -> None:
    """Two worker processes draw the figures (each its group): the same PNG bytes as
    plot_run in this process, the paths in its order; a dead worker's share is drawn here."""
    from drillcosim.cosim.scenario.plot_workers import PlotWorkers

    data = _record(["plant.body11_X", "plant.body11_Y", "plant.body11_radial_deflection",
                    "plant.body11_contact_force", "plant.actuator1_power",
                    "controller.actuator1_force_C"], n=3000)
    for name in ("here", "there", "again"):
        (tmp_path / name).mkdir()
    here = plot_run(data, tmp_path / "here", clearance=0.02, n_sites=1, title="t")
    with PlotWorkers(2) as workers:
        assert len(workers.procs) == 2
        there = workers.plot_run(data, tmp_path / "there", clearance=0.02, n_sites=1,
                                 title="t")
    assert [p.name for p in there] == [p.name for p in here] == [
        "orbit.png", "deflection_contact.png", "actuators.png"]
    for a, b in zip(here, there):
        assert a.read_bytes() == b.read_bytes()
    with PlotWorkers(2) as workers:
        workers.procs[0].kill()                       # its group falls back to this process
        workers.procs[0].wait()
        again = workers.plot_run(data, tmp_path / "again", clearance=0.02, n_sites=1,
                                 title="t")
    assert [p.name for p in again] == [p.name for p in here]
    assert all(a.read_bytes() == b.read_bytes() for a, b in zip(here, again))
    with PlotWorkers(0) as none:                      # one core: no workers
        assert none.procs == []


def _feed_run(workers, data: np.ndarray, settings: dict, stop_time: float, pause: float = 0.0):
    """Stream ``data`` to ``workers`` as a run would (PlotFeed over a Recorder), the rows in
    blocks of 1/20 of ``stop_time``, then stop."""
    import time
    from types import SimpleNamespace

    from drillcosim.cosim.master.recorder import Recorder

    recorder = Recorder([n for n in data.dtype.names if n != "time"], 1)
    feed = workers.feed(settings, stop_time)
    h = float(data["time"][1] - data["time"][0])
    execution = SimpleNamespace(observers=[feed, recorder], time=float(data["time"][0]),
                                base_step=h, tick=0)
    feed.on_start(execution)
    flat = data.view(np.float64).reshape(len(data), -1)
    for start in range(0, len(data), feed.stride_ticks):
        recorder.add_rows(flat[start:start + feed.stride_ticks])
        execution.tick = start + feed.stride_ticks
        feed.on_step(execution)
        time.sleep(pause)                      # the workers draw the rows so far
    feed.on_stop(execution)
    return recorder.data


def test_figures_drawn_while_a_run_steps_equal_those_drawn_at_its_end(tmp_path) -> None:
    """The workers draw their figures from the rows so far (time axis to the stop time), then
    the final ones: the same PNG bytes as plot_run drawing the whole data at once in this
    process; a run that stops early (half its rows) gets the figures of what it recorded; a
    worker killed after the feed leaves its share to this process."""
    from drillcosim.cosim.scenario.plot_workers import PlotWorkers

    n = 3000
    data = _record(["plant.body11_X", "plant.body11_Y", "plant.body11_radial_deflection",
                    "plant.body11_contact_force", "plant.actuator1_power",
                    "controller.actuator1_force_C"], n=n)
    data["plant.body11_radial_deflection"] *= np.linspace(0.0, 1.0, n)   # limits change late
    base = tmp_path / "baseline.npz"              # an open-loop run to draw behind
    base_rows = _record(["plant.body11_X", "plant.body11_Y", "plant.body11_radial_deflection",
                         "plant.body11_contact_force"], n=n)
    np.savez(base, data=base_rows)
    settings = {"clearance": 0.02, "spans": {11: {"span": "long"}}, "n_sites": 1,
                "title": "t", "switch_on_time": 1.0, "baseline": str(base), "revolution": 0.3}
    stop = float(data["time"][-1])
    for name, rows, kill in (("whole", data, False), ("early", data[: n // 2], False),
                             ("killed", data, True)):
        here, there = tmp_path / f"{name}_here", tmp_path / f"{name}_there"
        here.mkdir()
        there.mkdir()
        expected = plot_run(rows, here, **settings)
        with PlotWorkers(2) as workers:
            fed = _feed_run(workers, rows, settings, stop, pause=0.1 if name == "whole" else 0)
            assert np.array_equal(fed, rows)
            if kill:
                workers.procs[1].kill()
                workers.procs[1].wait()
            got = workers.plot_run(fed, there, **settings)
        assert [p.name for p in got] == [p.name for p in expected] == [
            "orbit.png", "deflection_contact.png", "actuators.png"]
        for a, b in zip(expected, got):
            assert a.read_bytes() == b.read_bytes(), (name, a.name)
