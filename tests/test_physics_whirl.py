"""Wellbore friction and whirl against closed-form results.

* Backward whirl: a collar rolling without slip on the wall of a borehole of radial clearance c
  orbits at -Omega r / c (r collar radius; kinematics of rolling: the contact point's velocity
  v_t + r Omega = 0 with v_t = whirl * orbit radius).
* Forward synchronous whirl from unbalance: the centre orbits with the spin; its amplitude is the
  Euler-Bernoulli modal sum of the rotating force m e Omega^2 at midspan (pinned-pinned span,
  viscous drag alpha): X = sum_k 2 F sin^2(k pi/2) / (rho A L (w_k^2 - Omega^2 + i alpha Omega)).
* Friction is dissipative and acts at the contact point: its power equals -mu N |s|^2 /
  sqrt(|s|^2 + v_eps^2) with s the slip velocity computed here from the state.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from drillcosim.plant.kernels import cardan
from drillcosim.plant.model import DrillstringModel
from drillcosim.plant.scene import SceneError, load_scene, scene_from_dict
from drillcosim.plant.simulator import simulate

NAMES = ["body6_radial_deflection", "body6_contact_force", "body6_whirl_speed",
         "body6_whirl_direction"]


def _run(scene: str, stop: float, extended: bool | None = None, **over):
    sc = load_scene(scene, overrides=over or None)
    m = DrillstringModel(sc.plant, sc.model, extended_outputs=extended)
    t, v, res = simulate(m, stop, 1e-3, NAMES)
    assert res.ok, res.message
    return m, t, v


def test_kicked_collar_rolls_backward_at_minus_omega_r_over_c():
    m, t, v = _run("backward_whirl", 5.0)
    omega = m.params.top_drive.rotary_speed
    r = 0.5 * m.params.pipe.outer_diameter
    c = m.params.contact.clearance
    last = t > 3.0
    whirl = v["body6_whirl_speed"][last]
    rho = v["body6_radial_deflection"][last]
    assert np.all(v["body6_whirl_direction"][last] == -1.0)
    assert np.all(v["body6_contact_force"][last] > 0.0)  # on the wall the whole time
    assert whirl.std() < 1e-3 * abs(whirl.mean())  # a steady orbit
    # rolling whirl: within a few percent of -Omega r / c (measured 1.3 %: the wall yields 0.1 mm)
    assert whirl.mean() == pytest.approx(-omega * r / c, rel=0.02)
    # rolling without slip on the actual orbit radius (c + penetration): measured 0.24 %
    assert whirl.mean() == pytest.approx(np.mean(-omega * r / rho), rel=0.005)


def test_without_friction_the_kick_does_not_start_a_backward_whirl():
    m, t, v = _run("backward_whirl", 5.0, contact={"friction_coefficient": 0.0})
    last = t > 3.0
    assert np.all(v["body6_contact_force"][last] == 0.0)  # it bounced off and stays off
    assert v["body6_radial_deflection"][last].max() < 0.5 * m.params.contact.clearance


@pytest.mark.parametrize("omega", [10.0, 25.0])  # below and above the first critical speed
def test_unbalance_gives_forward_synchronous_whirl_of_euler_bernoulli_amplitude(omega):
    m, t, v = _run("forward_whirl", 6.0, top_drive={"rotary_speed": omega})
    last = t > 4.0
    assert np.all(v["body6_whirl_direction"][last] == 1.0)
    assert np.all(v["body6_contact_force"] == 0.0)  # inside the clearance: the wall never acts
    assert v["body6_whirl_speed"][last].mean() == pytest.approx(omega, rel=1e-6)
    pipe = m.params.pipe
    ei = pipe.youngs_modulus * pipe.second_moment
    rho_a = pipe.density * pipe.area
    L = pipe.length
    alpha = m.derived.alpha_lateral  # drag rate [1/s] of every body
    force = m.params.unbalance.moment * omega**2
    x = sum(2.0 * force / (rho_a * L) * math.sin(k * math.pi / 2) ** 2
            / ((k * math.pi / L) ** 4 * ei / rho_a - omega**2 + 1j * alpha * omega)
            for k in range(1, 80))
    # lumped n = 11 vs continuous beam: measured -0.4 % (10 rad/s), -0.2 % (25 rad/s)
    assert v["body6_radial_deflection"][last].mean() == pytest.approx(abs(x), rel=0.01)


def test_friction_never_acting_leaves_the_trajectory_bit_for_bit():
    """forward_whirl has mu = 0.3 but no contact: identical to mu = 0 (the branch never runs)."""
    _, _, a = _run("forward_whirl", 2.0)
    _, _, b = _run("forward_whirl", 2.0, extended=True, contact={"friction_coefficient": 0.0})
    for k in NAMES:
        np.testing.assert_array_equal(a[k], b[k], err_msg=k)


def test_friction_power_is_the_dissipation_at_the_contact_point():
    """rhs(mu) - rhs(0) on random states in contact: the friction force and moment do power
    F . v_P = -mu N |s|^2 / sqrt(|s|^2 + v_eps^2) (s from the state here, independently)."""
    sc = load_scene("backward_whirl")
    mu = sc.plant.contact.friction_coefficient
    eps = sc.plant.contact.friction_velocity
    m = DrillstringModel(sc.plant, sc.model)
    m0 = DrillstringModel(load_scene("backward_whirl", overrides={
        "contact": {"friction_coefficient": 0.0}}).plant, "full3d")
    n, k = m.n, 5  # body 6
    d = m.derived
    rc = 0.5 * sc.plant.pipe.outer_diameter
    rng = np.random.default_rng(7)
    for _ in range(5):
        y = m.initial_state()
        ang = rng.uniform(-0.05, 0.05, 3)
        y[3 * n + 3 * k:3 * n + 3 * k + 3] = ang
        phi = rng.uniform(0, 2 * math.pi)
        dl = sc.plant.contact.clearance + rng.uniform(1e-5, 2e-4)
        y[3 * k], y[3 * k + 1] = dl * math.cos(phi), dl * math.sin(phi)
        v = rng.normal(size=3) * 0.3
        w = rng.normal(size=3) * [1.0, 1.0, 10.0]
        y[6 * n + 3 * k:6 * n + 3 * k + 3] = v
        y[9 * n + 3 * k:9 * n + 3 * k + 3] = w
        diff = m.rhs(0.0, y) - m0.rhs(0.0, y)
        dv = diff[6 * n + 3 * k:6 * n + 3 * k + 3]
        dw = diff[9 * n + 3 * k:9 * n + 3 * k + 3]
        power = d.mass * dv @ v + d.j_transverse * (dw[0] * w[0] + dw[1] * w[1]) \
            + d.j_polar * dw[2] * w[2]
        R = np.empty((3, 3))
        cardan(*ang, R)
        nrm = np.array([math.cos(phi), math.sin(phi), 0.0])
        vp = v + np.cross(R @ w, rc * nrm)
        s = vp - (vp @ nrm) * nrm  # slip in the wall's tangent plane
        fn = sc.plant.contact.stiffness * (dl - sc.plant.contact.clearance)
        expected = -mu * fn * (s @ s) / math.sqrt(s @ s + eps**2)
        assert expected < 0.0
        assert power == pytest.approx(expected, rel=1e-9)
        assert np.all(diff[:6 * n] == 0.0)  # forces only: positions' rates unchanged


def test_whirl_output_follows_a_prescribed_orbit():
    """Centre on a circle of radius 5 mm moving at w about +Z: whirl speed w; direction by the
    sign of w times the spin (body z spin 3 rad/s)."""
    sc = load_scene("forward_whirl")
    m = DrillstringModel(sc.plant, sc.model)
    n, k = m.n, 5
    i_w = m.output_names.index("body6_whirl_speed")
    i_d = m.output_names.index("body6_whirl_direction")
    for w, spin, sense in ((7.0, 3.0, 1.0), (-7.0, 3.0, -1.0), (7.0, -3.0, -1.0), (0.0, 3.0, 0.0)):
        y = m.initial_state()
        phi = 0.7
        y[3 * k], y[3 * k + 1] = 5e-3 * math.cos(phi), 5e-3 * math.sin(phi)
        y[6 * n + 3 * k], y[6 * n + 3 * k + 1] = -5e-3 * w * math.sin(phi), 5e-3 * w * math.cos(phi)
        y[9 * n + 3 * k + 2] = spin
        out = m.outputs(0.0, y)
        assert out[i_w] == pytest.approx(w, abs=1e-12)
        assert out[i_d] == sense
    y = m.initial_state()  # on the axis: no whirl
    assert m.outputs(0.0, y)[i_w] == 0.0 and m.outputs(0.0, y)[i_d] == 0.0


def test_paper_scenes_keep_the_paper_outputs_and_whirl_outputs_are_opt_in():
    paper = DrillstringModel(load_scene("paper_open_loop").plant, "full3d")
    assert not any("whirl" in nm for nm in paper.output_names)
    ext = DrillstringModel(load_scene("paper_open_loop").plant, "full3d", extended_outputs=True)
    assert {"body11_whirl_speed", "body26_whirl_direction"} <= set(ext.output_names)
    assert ext.output_units["body11_whirl_speed"] == "rad/s"
    sc = load_scene("paper_open_loop", overrides={"contact": {"friction_coefficient": 0.2}})
    assert "body26_whirl_speed" in DrillstringModel(sc.plant, sc.model).output_names


@pytest.mark.parametrize("table, message", [
    ({"friction_coefficient": -0.1}, "contact.friction_coefficient = -0.1 is out of range: "
                                     "allowed [0, 2]"),
    ({"friction_coefficient": 3.0}, "contact.friction_coefficient = 3.0 is out of range"),
    ({"friction_velocity": 0.0}, "contact.friction_velocity = 0.0 is out of range: allowed "
                                 "(0, 10] m/s"),
    ({"clearance": -0.01}, "contact.clearance = -0.01 is out of range: allowed [0, 10] m"),
    ({"whirl_outputs": 1}, "contact.whirl_outputs = 1 is not allowed: must be true or false"),
])
def test_bad_friction_parameters_are_refused_in_one_line(table, message):
    with pytest.raises(SceneError) as exc:
        scene_from_dict({"contact": table}, source="w.toml")
    assert message in str(exc.value) and "\n" not in str(exc.value)
