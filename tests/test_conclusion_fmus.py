"""The conclusion study (docs/paper_comparison.md section 3) through FMUs built for its layouts.

The study runs its 1, 2 and 3 sites per span with the in-process engine of the one builder
(:func:`cosim.scenario.build.build_system`). Here the same points run through the plant
and controller FMUs built for each layout (:mod:`cosim.scenario.scene_fmus`, both layouts in one
FMU folder) and must give the same trajectories bit for bit: the FMI boundary, the variants'
input/output routing and the master's timing change nothing.
"""

from __future__ import annotations

import numpy as np
import pytest

from drillcosim.cosim.scenario.config import load_config
from drillcosim.cosim.study.paper.conclusion import site_joints
from drillcosim.cosim.study.point import PointOptions, simulate_point

pytestmark = [pytest.mark.needs_cc]

SCENE = "paper_calibrated_closed_loop"


@pytest.fixture(scope="module")
def fmu_dir(tmp_path_factory):
    return tmp_path_factory.mktemp("conclusion_fmus")


def _scene_file(folder, per_span: int):
    """The study's point as a scene file (an FMU built for a scene reads its layout from the
    scene file it names; overrides made in memory do not reach it)."""
    joints = list(site_joints(load_config(SCENE).scene.plant, per_span))
    path = folder / f"conclusion_{per_span}_per_span.toml"
    # the answer's configuration: gain 1e8, 0.5 ms actuator delay, H = 0.25 ms
    path.write_text(f'extends = "{SCENE}"\n\n[actuators]\njoints = {joints}\n\n'
                    f'[controller]\nenabled = true\ngain = 1e8\n\n'
                    f'[cosim]\nstep = 2.5e-4\nstop_time = 0.06\nactuator_delay = 5e-4\n')
    return path


@pytest.mark.parametrize("per_span", [2, 3])
def test_conclusion_point_through_scene_fmus_equals_in_process(per_span, fmu_dir) -> None:
    config = load_config(_scene_file(fmu_dir, per_span))
    n_sites = 2 * per_span
    assert config.n_sites == n_sites
    opts = PointOptions()
    data_in, reason_in = simulate_point(config, opts, "inprocess")
    data_fmu, reason_fmu = simulate_point(config, opts, "fmu", fmu_dir)
    assert reason_in == reason_fmu == ""
    common = [c for c in data_in.dtype.names if c in data_fmu.dtype.names]
    forces = [c for c in common if "actuator" in c and "force" in c]
    assert len(forces) == 2 * n_sites, common      # every site's C and E force is compared
    assert any(np.abs(data_in[c]).max() > 0.0 for c in forces)
    for c in common:
        assert np.array_equal(data_in[c], data_fmu[c]), c
