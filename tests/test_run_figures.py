"""A run's figures tell its story: the closed loop against its open-loop baseline, titled with
its settings, no empty panel, a legend wherever two traces share an axes (Result.plot)."""

from __future__ import annotations

import numpy as np
import pytest

import drillcosim
from drillcosim.cosim.scenario.baseline import baseline_config, baseline_path, load_baseline
from drillcosim.cosim.scenario.build import build_system
from drillcosim.cosim.scenario.simulate import simulate

#: A short closed-loop run with a delay, in process (the FMUs' numbers without the boundary).
RUN = {"stop_time": 2.0, "delay": 1e-4, "gain": 1e9, "engine": "inprocess"}


@pytest.fixture(scope="module")
def result():
    return drillcosim.simulate("paper_closed_loop", **RUN)


def _traces(ax) -> int:
    """Data traces drawn in ``ax`` that show something: lines of at least two points that are
    not all equal (a flat zero line is no picture), non-empty bands."""
    lines = sum(len(y := np.asarray(line.get_ydata(), float)) >= 2 and np.ptp(y) > 0
                for line in ax.lines)
    bands = sum(bool(c.get_paths()) for c in ax.collections)
    return lines + bands


def test_the_baseline_is_the_scene_with_the_controller_off(result) -> None:
    """The cached baseline holds what a direct open-loop simulation of the same settings
    records, bit for bit; a second request reads the same file."""
    path = baseline_path(result.config)
    assert baseline_path(result.config) == path
    base = baseline_config(result.config)
    assert not base.controller.enabled and base.cosim == result.config.cosim
    direct = simulate(build_system(base, "inprocess")).data
    cached = load_baseline(path)
    assert cached.dtype == direct.dtype and cached.tobytes() == direct.tobytes()
    assert "controller.actuator1_force_C" not in cached.dtype.names
    assert baseline_config(base) is None            # an open-loop run has no baseline


def test_figures_are_matplotlib_figures_with_the_settings_in_their_titles(result) -> None:
    from matplotlib.figure import Figure

    figures = result.plot()
    assert list(figures) == ["orbit", "deflection_contact", "actuators"]
    for name, fig in figures.items():
        assert isinstance(fig, Figure), name
        title = fig._suptitle.get_text()
        for part in ("paper_closed_loop", "K = 1e9 N/strain", "actuator delay 0.1 ms",
                     "step H = 0.25 ms"):
            assert part in title.replace("\n", " "), (name, title)


def test_no_empty_panel_and_a_legend_where_traces_share_an_axes(result) -> None:
    for name, fig in result.plot().items():
        for ax in fig.axes:
            said = [t for t in ax.texts if t.get_visible() and t.get_text()]
            assert _traces(ax) or said, (name, ax.get_title(), ax.get_ylabel())
            if _traces(ax) >= 2:
                assert ax.get_legend() is not None, (name, ax.get_title(), ax.get_ylabel())


def test_the_closed_loop_is_drawn_against_the_open_loop(result) -> None:
    """Deflection and contact panels carry the baseline's trace (grey) besides the run's; the
    orbit shows the last revolutions of both; forces C and E have panels of their own."""
    from drillcosim.cosim.scenario.plot_base import BASELINE_COLOR

    figures = result.plot()
    deflection = figures["deflection_contact"]
    for ax in deflection.axes:
        grey = [line for line in ax.lines if line.get_color() == BASELINE_COLOR
                and len(line.get_xdata()) >= 2]
        assert grey, ax.get_title()
    orbit = figures["orbit"].axes[0]
    assert len([line for line in orbit.lines if len(line.get_xdata()) >= 2]) == 3
    assert "last 5 revolutions" in orbit.get_title()
    t_from = float(orbit.get_title().split("t = ")[1].split(" ..")[0])
    assert t_from == pytest.approx(2.0 - 5 * 2 * np.pi / 20.0, abs=2e-3)
    ylabels = [ax.get_ylabel() for ax in figures["actuators"].axes]
    assert ylabels.count("force C [kN]") == 2 and ylabels.count("force E [kN]") == 2


def test_plot_without_baseline_and_save_writes_the_pngs(result, tmp_path) -> None:
    bare = result.plot(baseline=False)
    assert all(not any(line.get_color() == "0.55" for ax in fig.axes for line in ax.lines)
               for fig in bare.values())
    paths = bare.save(tmp_path)
    assert [p.name for p in paths] == ["orbit.png", "deflection_contact.png", "actuators.png"]
    assert all(p.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" for p in paths)
    assert "<img" in bare._repr_html_()
