"""`drillcosim modes`: exit codes, JSON shape, and the numbers against the formulas."""

from __future__ import annotations

import json
import math
import subprocess
import sys

import pytest

from drillcosim.plant.params import PipeParams


def run(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "cosim.cli", *args], capture_output=True,
                          text=True, timeout=300)


def test_modes_json_matches_rod_and_beam_formulas():
    r = run("modes", "table1_lateral_step", "--json")
    assert r.returncode == 0, r.stderr
    out = json.loads(r.stdout)
    assert set(out) == {"axial", "torsional", "lateral"}
    pipe = PipeParams()
    # torsion: rigid top drive, free bit -> fixed-free rod within 1 %
    wt = math.pi * pipe.torsional_wave_speed / (2 * pipe.length)
    assert out["torsional"]["frequency_rad_s"] == pytest.approx(wt, rel=0.01)
    # lateral: two spans 2:1 pinned -> 1.2815 x pinned-pinned over 53.33 m
    ei = pipe.youngs_modulus * pipe.second_moment
    wpp = (math.pi / 53.33) ** 2 * math.sqrt(ei / (pipe.density * pipe.area))
    assert out["lateral"]["frequency_rad_s"] == pytest.approx(1.2815 * wpp, rel=0.02)
    assert out["axial"]["damping_ratio"] == pytest.approx(0.015, rel=0.05)
    assert out["torsional"]["damping_ratio"] == pytest.approx(0.034, rel=0.02)


def test_modes_unknown_scene_exits_2_without_traceback():
    r = run("modes", "no_such_scene")
    assert r.returncode == 2
    assert "Traceback" not in r.stderr
    assert len(r.stderr.strip().splitlines()) == 1
    assert "no_such_scene" in r.stderr
