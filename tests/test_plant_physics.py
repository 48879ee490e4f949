"""Plant physics against closed-form formulas, conservation laws and a second implementation."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from drillcosim.analysis.modal import first_modes, static_equilibrium
from drillcosim.plant.kernels import cardan
from drillcosim.plant.model import DrillstringModel
from drillcosim.plant.params import (
    BitParams,
    ContactParams,
    DampingParams,
    LoadParams,
    PipeParams,
    PlantParams,
    StabilizerParams,
    TopDriveParams,
    UnbalanceParams,
)
from drillcosim.plant.scene import load_scene

PIPE = PipeParams()
EI = PIPE.youngs_modulus * PIPE.second_moment
RHO_A = PIPE.density * PIPE.area


def quiet(**kw) -> PlantParams:
    """Table-1 style parameters: no rotation, free bit, no unbalance, no contact, no gravity."""
    base = dict(
        top_drive=TopDriveParams(rotary_speed=0.0),
        bit=BitParams(axial_stiffness=0.0, displacement_amplitude=0.0),
        unbalance=UnbalanceParams(enabled=False),
        contact=ContactParams(enabled=False),
    )
    base.update(kw)
    return PlantParams(**base)


def pinned_pinned(length: float) -> float:
    """Euler-Bernoulli first frequency [rad/s] of a pinned-pinned span."""
    return (math.pi / length) ** 2 * math.sqrt(EI / RHO_A)


# ----------------------------------------------------------------------------- kinematics
def test_rotation_matrix_orthonormal_and_composed():
    rng = np.random.default_rng(1)
    R = np.empty((3, 3))
    for psi, th, ph in rng.uniform(-1.4, 1.4, size=(20, 3)):
        cardan(psi, th, ph, R)
        assert np.allclose(R @ R.T, np.eye(3), atol=1e-14)
        assert np.linalg.det(R) == pytest.approx(1.0, abs=1e-14)
        c, s = math.cos, math.sin
        Rz = np.array([[c(psi), -s(psi), 0], [s(psi), c(psi), 0], [0, 0, 1]])
        Ry = np.array([[c(th), 0, s(th)], [0, 1, 0], [-s(th), 0, c(th)]])
        Rx = np.array([[1, 0, 0], [0, c(ph), -s(ph)], [0, s(ph), c(ph)]])
        assert np.allclose(R, Rz @ Ry @ Rx, atol=1e-14)


def test_cardan_rates_reproduce_body_angular_velocity():
    """Eq. 9-11: integrating the angle rates turns R as dR/dt = R [w]x (w in the body frame)."""
    m = DrillstringModel(quiet(pipe=PipeParams(n_segments=2)))
    rng = np.random.default_rng(2)
    n = m.n
    for _ in range(5):
        y = m.initial_state()
        ang = rng.uniform(-0.6, 0.6, 3)
        w = rng.normal(size=3)
        y[3 * n:3 * n + 3] = ang
        y[9 * n:9 * n + 3] = w
        rates = m.rhs(0.0, y)[3 * n:3 * n + 3]
        eps = 1e-6
        Rp, Rm, R = np.empty((3, 3)), np.empty((3, 3)), np.empty((3, 3))
        cardan(*(ang + eps * rates), Rp)
        cardan(*(ang - eps * rates), Rm)
        cardan(*ang, R)
        W = R.T @ (Rp - Rm) / (2 * eps)
        assert np.allclose(W, -W.T, atol=1e-8)
        assert np.allclose([W[2, 1], W[0, 2], W[1, 0]], w, rtol=1e-7, atol=1e-8)


# ----------------------------------------------------------------------------- frequencies
def rod_model(n: int, kind: str = "axial_torsional") -> DrillstringModel:
    """Fixed-free rod: rigid top (axial and torsion), free bit."""
    return DrillstringModel(
        quiet(pipe=PipeParams(n_segments=n),
              top_drive=TopDriveParams(rotary_speed=0.0, axial_stiffness=math.inf)),
        kind,
    )


@pytest.fixture(scope="module")
def rod_errors():
    out = {}
    for n in (30, 60, 120):
        m = rod_model(n)
        fm = first_modes(m)
        out[n] = {
            "axial": fm["axial"].frequency_rad_s / m.derived.w_axial_ref - 1.0,
            "torsional": fm["torsional"].frequency_rad_s / m.derived.w_tors_ref - 1.0,
            "modes": fm,
        }
    return out


def test_first_axial_and_torsional_frequency_within_1_percent(rod_errors):
    c = PIPE.axial_wave_speed
    ct = PIPE.torsional_wave_speed
    assert rod_errors[30]["modes"]["axial"].frequency_rad_s == pytest.approx(
        math.pi * c / (2 * PIPE.length), rel=0.01)
    assert rod_errors[30]["modes"]["torsional"].frequency_rad_s == pytest.approx(
        math.pi * ct / (2 * PIPE.length), rel=0.01)


@pytest.mark.parametrize("kind", ["axial", "torsional"])
def test_rod_frequency_error_falls_as_n_squared(rod_errors, kind):
    """Half segments lumped at both ends: the error falls as O(1/n^2)."""
    e = [abs(rod_errors[n][kind]) for n in (30, 60, 120)]
    assert e[0] > e[1] > e[2]
    order = math.log(e[0] / e[2]) / math.log(4.0)
    assert 1.7 < order < 3.0, e


def test_damping_ratios_meet_table1_targets(rod_errors):
    fm = rod_errors[30]["modes"]
    assert fm["axial"].damping_ratio == pytest.approx(0.015, rel=0.02)
    assert fm["torsional"].damping_ratio == pytest.approx(0.034, rel=0.02)


def test_full3d_has_the_axial_torsional_frequencies(rod_errors):
    fm3 = first_modes(rod_model(30, "full3d"))
    fm1 = rod_errors[30]["modes"]
    for k in ("axial", "torsional"):
        assert fm3[k].frequency_rad_s == pytest.approx(fm1[k].frequency_rad_s, rel=1e-6)


def single_span(tension: float = 0.0, n: int = 20) -> PlantParams:
    """A 53.33 m string pinned at the top and at the bit (one span), optional axial tension.

    The axial load acts at the bit end through the bit spring (weight on bit = -tension).
    """
    return quiet(
        pipe=PipeParams(length=53.33, n_segments=n),
        stabilizers=StabilizerParams(heights=(0.0,)),
        top_drive=TopDriveParams(rotary_speed=0.0, axial_stiffness=math.inf),
        bit=BitParams(axial_stiffness=1e9, displacement_amplitude=0.0, weight_on_bit=-tension),
    )


def test_beam_fe_reference_matches_closed_forms_and_converges():
    """The lateral reference (Hermite beam elements) is itself checked against the formulas."""
    from drillcosim.plant.beam_fe import pinned_beam_frequencies

    w1 = pinned_beam_frequencies(53.33, [0.0, 53.33], EI, RHO_A, n_elements=48, count=2)
    assert w1[0] == pytest.approx(pinned_pinned(53.33), rel=1e-6)
    assert w1[1] == pytest.approx(4 * pinned_pinned(53.33), rel=1e-5)
    w = [pinned_beam_frequencies(80.0, [0.0, 53.33, 80.0], EI, RHO_A, n_elements=ne,
                                 count=1)[0] for ne in (12, 24, 48, 96)]
    assert w[-1] == pytest.approx(1.2815 * pinned_pinned(53.33), rel=1e-4)
    err = [abs(x - w[-1]) for x in w[:-1]]
    assert err[0] > err[1] > err[2]


def test_lateral_pinned_pinned_span_within_2_percent():
    fm = first_modes(DrillstringModel(single_span()))
    assert fm["lateral"].frequency_rad_s == pytest.approx(pinned_pinned(53.33), rel=0.02)


def test_lateral_two_spans_2_to_1_within_2_percent():
    """Default layout (stabilizers at the bit and 26.67 m above it): 1.2815 x the long span."""
    fm = first_modes(DrillstringModel(quiet()))
    assert fm["lateral"].frequency_rad_s == pytest.approx(1.2815 * pinned_pinned(53.33), rel=0.02)
    assert fm["lateral"].damping_ratio == pytest.approx(0.40, rel=0.02)


@pytest.mark.parametrize("ratio", [1.0, -0.5])
def test_lateral_frequency_under_axial_load(ratio):
    """w = w0 sqrt(1 + P / P_cr), P_cr = pi^2 EI / L^2 (tension > 0, compression < 0)."""
    p_cr = math.pi**2 * EI / 53.33**2
    w0 = first_modes(DrillstringModel(single_span()))["lateral"].frequency_rad_s
    w = first_modes(DrillstringModel(single_span(ratio * p_cr)))["lateral"].frequency_rad_s
    assert w / w0 == pytest.approx(math.sqrt(1.0 + ratio), rel=0.02)


# ----------------------------------------------------------------------------- statics
def test_static_sag_of_horizontal_pinned_beam_under_self_weight():
    """A 10 m beam pinned at both ends, weight applied across its axis: 5 w L^4 / (384 EI)."""
    n = 30
    span = 10.0
    pipe = PipeParams(length=span, n_segments=n)
    w = RHO_A * 9.81
    m_seg = w * span / n
    loads = tuple(LoadParams("force", k, "x", m_seg, 0.0, math.inf) for k in range(1, n + 1))
    prm = quiet(pipe=pipe, stabilizers=StabilizerParams(heights=(0.0,)),
                top_drive=TopDriveParams(rotary_speed=0.0, axial_stiffness=math.inf), loads=loads)
    model = DrillstringModel(prm)
    y = static_equilibrium(model)
    X = y[0:3 * n:3]
    mid = 0.5 * (X[n // 2 - 1] + X[n // 2])
    assert mid == pytest.approx(5 * w * span**4 / (384 * EI), rel=0.02)


def test_hanging_string_stretch():
    """Hanging from a rigid top under gravity: the bit end drops rho g L^2 / (2 E)."""
    prm = quiet(gravity=9.81, top_drive=TopDriveParams(rotary_speed=0.0,
                                                       axial_stiffness=math.inf))
    model = DrillstringModel(prm)
    y = model.initial_state()
    n = model.n
    stretch = y[3 * (n - 1) + 2] + 0.5 * model.derived.dx - PIPE.length
    expected = PIPE.density * 9.81 * PIPE.length**2 / (2 * PIPE.youngs_modulus)
    assert stretch == pytest.approx(expected, rel=0.02)
    # and it is an equilibrium of the full 3D right-hand side (accelerations vs g)
    assert np.max(np.abs(model.rhs(0.0, y))) < 1e-6 * 9.81


# ----------------------------------------------------------------------------- conservation
def conservative(**kw) -> PlantParams:
    return quiet(damping=DampingParams(0.0, 0.0, 0.0), stabilizers=StabilizerParams(damping=0.0),
                 **kw)


def energy_drift(dt: float) -> tuple[float, float]:
    loads = (
        LoadParams("force", 11, "x", 500.0, 0.0, 0.01),
        LoadParams("torque", 5, "z", 1000.0, 0.0, 0.01),
        LoadParams("force", 30, "z", 1e4, 0.0, 0.01),
        LoadParams("torque", 20, "x", 300.0, 0.0, 0.01),
    )
    m = DrillstringModel(conservative(gravity=9.81, loads=loads))
    y = m.initial_state()
    e_static = m.energy(0.0, y)
    steps = int(round(0.01 / dt))
    m.advance(0.0, y, steps, dt)
    t = steps * dt
    e0 = m.energy(t, y)
    dev = 0.0
    chunk = int(round(0.025 / dt))
    for _ in range(40):
        m.advance(t, y, chunk, dt)
        t += chunk * dt
        dev = max(dev, abs(m.energy(t, y) - e0))
    return dev, e0 - e_static


def test_undamped_free_vibration_conserves_energy():
    """Bound reached: |dE| < 1e-4 of the injected energy over 1 s at dt = 50 us (RK4 error)."""
    dev_fine, injected = energy_drift(5e-5)
    dev_coarse, _ = energy_drift(1e-4)
    assert injected > 1.0
    assert dev_fine < 1e-4 * injected
    assert dev_coarse / dev_fine > 10.0  # the drift is the integrator's (order >= 4), not the model's


def momenta(m: DrillstringModel, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    n = m.n
    d = m.derived
    r = y[:3 * n].reshape(n, 3)
    v = y[6 * n:9 * n].reshape(n, 3)
    w = y[9 * n:].reshape(n, 3)
    Jb = np.array([d.j_transverse, d.j_transverse, d.j_polar])
    p = d.mass * v.sum(axis=0)
    L = np.zeros(3)
    R = np.empty((3, 3))
    for k in range(n):
        cardan(*y[3 * n + 3 * k:3 * n + 3 * k + 3], R)
        L += np.cross(r[k], d.mass * v[k]) + R @ (Jb * w[k])
    return p, L


def test_free_string_conserves_momentum_and_angular_momentum():
    """Free-free string (no supports), spinning and wobbling, with material damping on."""
    prm = quiet(
        top_drive=TopDriveParams(rotary_speed=0.0, axial_stiffness=0.0, lateral_stiffness=0.0,
                                 torsional_stiffness=0.0),
        stabilizers=StabilizerParams(heights=()),
        damping=DampingParams(lateral_ratio=0.0),
        pipe=PipeParams(n_segments=10),
    )
    m = DrillstringModel(prm)
    rng = np.random.default_rng(3)
    n = m.n
    y = m.initial_state()
    y[6 * n:9 * n] = rng.normal(scale=0.05, size=3 * n)
    y[9 * n:] = rng.normal(scale=0.05, size=3 * n)
    y[9 * n + 2::3] += 5.0  # spin
    p0, L0 = momenta(m, y)
    m.advance(0.0, y, 5000, 1e-4)
    p1, L1 = momenta(m, y)
    assert np.allclose(p1, p0, rtol=0, atol=1e-9 * np.linalg.norm(p0))
    assert np.allclose(L1, L0, rtol=0, atol=1e-8 * np.linalg.norm(L0))


def test_spinning_string_stays_straight():
    """Top drive at 20 rad/s, no excitation: no lateral motion appears; a small lateral kick
    decays instead of growing (gyroscopic terms add no energy), at the rate the lateral drag
    sets: drag is mass-proportional (force -alpha m v, alpha = 2 zeta_l w_l), so every lateral
    mode's envelope decays at alpha / 2 = zeta_l w_l, whatever its frequency; w_l is the two
    spans' (2:1, pinned at the top and the stabilizers) first frequency, 1.2815 x the long
    span's pinned-pinned one (0.680 rad/s): 0.272 1/s at zeta_l = 0.4. Measured from the peak
    lateral deflection over the first and second 10 s after the kick: 0.267 1/s (-2 %: the
    gyroscopic coupling at 20 rad/s and the joints' stiffness-proportional dampers); within
    5 %."""
    prm = replace(quiet(gravity=9.81), top_drive=TopDriveParams(rotary_speed=20.0))
    m = DrillstringModel(prm)
    n = m.n
    y = m.initial_state()
    dt = m.stable_step()
    steps = int(3.0 / dt)
    m.advance(0.0, y, steps, dt)
    assert np.max(np.abs(y[0:3 * n:3])) == 0.0 and np.max(np.abs(y[1:3 * n:3])) == 0.0
    assert y[9 * n + 2::3] == pytest.approx(20.0, abs=0.05)
    y[6 * n + 3 * 10] = 1e-3  # kick body 11 laterally, 1 mm/s
    t = steps * dt
    chunk = int(round(0.1 / dt))
    peaks = []
    for _ in range(200):  # 20 s in 0.1 s chunks: the largest lateral deflection of each
        m.advance(t, y, chunk, dt)
        t += chunk * dt
        peaks.append(np.max(np.hypot(y[0:3 * n:3], y[1:3 * n:3])))
    first, second = max(peaks[:100]), max(peaks[100:])
    assert 0 < second < first < 1e-3
    zeta_l = prm.damping.lateral_ratio
    w_l = 1.2815 * pinned_pinned(PIPE.length - 26.67)
    decay = math.log(first / second) / (100 * chunk * dt)
    assert decay == pytest.approx(zeta_l * w_l, rel=0.05)


# ----------------------------------------------------------------------------- two models
@pytest.mark.parametrize("scene", ["table1_axial_pulse", "table1_torsional_pulse"])
def test_axial_torsional_model_equals_full3d_on_its_scenes(scene):
    sc = load_scene(scene)
    assert sc.model == "axial_torsional"
    a = DrillstringModel(sc.plant, "axial_torsional")
    b = DrillstringModel(sc.plant, "full3d")
    ya, yb = a.initial_state(), b.initial_state()
    dt = 2e-4
    for k in range(10):
        a.advance(k * 0.05, ya, 250, dt)
        b.advance(k * 0.05, yb, 250, dt)
        oa = a.output_dict((k + 1) * 0.05, ya)
        ob = b.output_dict((k + 1) * 0.05, yb)
        # absolute tolerance: 1e-9 of each signal's scale (m, rad, N, N m)
        scales = {"bit_axial_displacement": 1e-3, "bit_twist": 1e-2, "hook_load": 1e4,
                  "top_torque": 1e3}
        for name, scale in scales.items():
            assert ob[name] == pytest.approx(oa[name], rel=1e-9, abs=1e-9 * scale), name


# ----------------------------------------------------------------------------- spinning
def test_linearization_in_the_top_drive_frame_is_time_invariant():
    """If the rotating-frame transformation were wrong, A would depend on the time."""
    from drillcosim.analysis.linearize import linearize

    prm = replace(quiet(gravity=9.81, pipe=PipeParams(n_segments=10)),
                  top_drive=TopDriveParams(rotary_speed=20.0))
    a1 = linearize(prm, spin=20.0, time=2.0).A
    a2 = linearize(prm, spin=20.0, time=2.37).A
    assert np.max(np.abs(a1 - a2)) < 1e-6 * np.max(np.abs(a1))


def test_spin_leaves_axial_torsional_modes_and_barely_moves_lateral():
    """Axisymmetric string: spin does not couple into axial/torsion; for this slender pipe
    (J_polar / J_transverse = 0.003) the gyroscopic split of the lateral mode is < 0.1 %."""
    from drillcosim.analysis.modal import operating_modes

    prm = quiet(gravity=9.81)

    def first(spin):
        out = {}
        for md in operating_modes(prm, "full3d", spin):
            out.setdefault(md.kind, md)
        return out

    rest, spun = first(0.0), first(20.0)
    rest_ref = first_modes(DrillstringModel(prm))
    for k in ("axial", "torsional", "lateral"):
        assert rest[k].frequency_rad_s == pytest.approx(rest_ref[k].frequency_rad_s, rel=1e-6)
    for k in ("axial", "torsional"):
        assert spun[k].frequency_rad_s == pytest.approx(rest[k].frequency_rad_s, rel=1e-6)
    assert spun["lateral"].frequency_rad_s == pytest.approx(rest["lateral"].frequency_rad_s,
                                                            rel=1e-3)


def test_internal_damping_destabilizes_supercritical_whirl():
    """Rotordynamics (Kimball-Newkirk): damping that rotates with the shaft (joint dampers) makes
    forward whirl unstable above the first critical speed; external drag keeps it stable."""
    from drillcosim.analysis.modal import operating_modes

    def min_lateral_damping(model: str) -> float:
        prm = quiet(damping=DampingParams(lateral_model=model))
        return min(m.damping_ratio for m in operating_modes(prm, "full3d", 20.0)
                   if m.kind == "lateral")

    assert min_lateral_damping("drag") > 0.0
    assert min_lateral_damping("joint") < 0.0
