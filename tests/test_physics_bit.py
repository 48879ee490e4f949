"""The cutting bit (``bit.model = "cutting"``) against independent references.

* A torsional pendulum with the same bit law (written here from the formulas of docs/physics.md),
  integrated by scipy DOP853 at rtol 1e-10: stick-slip period and peak bit speed.
* The stick-slip (Hopf) threshold of that pendulum: steady rotation is unstable when the bit
  torque's slope beats the damping, c + dT/dOmega < 0 (Brett 1992, SPE Drilling Engineering
  7(3): the negative-damping criterion); growth rate -(c + T') / (2 J).
* The bit lift-off threshold: with the bit on bottom the axial chain is linear, so the contact
  force oscillates by A |G(N Omega)| about the weight on bit (G from a frequency-domain model of
  the chain assembled here); the bit leaves the bottom when that exceeds the weight on bit.
* Steady drilling: Detournay & Defourny (2008) - the depth of cut per revolution and the
  specific-energy / drilling-strength line E = eps (1 - mu gamma zeta) + mu gamma S.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp
from scipy.signal import find_peaks

from drillcosim.plant.model import DrillstringModel, series
from drillcosim.plant.scene import SceneError, load_scene, scene_from_dict
from drillcosim.plant.simulator import PlantSimulator, simulate
from support.torsional import bit_torque as _bit_torque
from support.torsional import two_dof


def _pendulum_parameters(plant) -> tuple[float, float, float]:
    """(J [kg m^2], k [N m/rad], c [N m s/rad]) of the one-DOF torsional pendulum.

    Rayleigh-Ritz with the static twist shape under a torque at the bit: body k turns by
    phi_k = (k + 1/2) / (n - 1/2) of the bit body; k = G J_p / (L - dx/2) (rigid drive, half a
    segment to body 1); the stiffness-proportional joint damping c = beta k,
    beta = 2 zeta_t / w_t with w_t the first fixed-free rod frequency.
    """
    two = two_dof(plant)  # the same Rayleigh-Ritz shape; a rigid drive keeps only the bit row
    return float(two.mass[1, 1]), two.k, two.c


def _steady_simulator(plant, kind: str, omega: float, torque: float) -> PlantSimulator:
    """A simulator started in steady drilling at ``omega`` [rad/s]: every body spinning, the
    string twisted by ``torque`` [N m] and moving down at the rate of penetration of the weight
    on bit: no start-up transient of the lightly damped pendulum mode (1 % here). Needs
    ``top_drive.ramp_time = 0``."""
    assert plant.top_drive.ramp_time == 0.0
    bit = plant.bit
    m = DrillstringModel(plant, kind)
    n, dx = plant.pipe.n_segments, plant.pipe.segment_length
    gj = plant.pipe.shear_modulus * plant.pipe.polar_moment
    sim = PlantSimulator(m)
    sim.y[n:2 * n] = -torque * (np.arange(n) + 0.5) * dx / gj
    sim.y[3 * n:4 * n] = omega
    cut = max(bit.weight_on_bit - bit.wearflat_force, 0.0)
    sim.y[2 * n:3 * n] = cut / (bit.radius * bit.cutting_force_ratio
                                * bit.intrinsic_specific_energy) * omega / (2 * math.pi)
    return sim


def _cycle(t: np.ndarray, w: np.ndarray, omega: float, t0: float) -> tuple[float, float, float]:
    """(period [s], mean peak bit speed [rad/s], min bit speed [rad/s]) after ``t0``."""
    sel = t > t0
    pk, _ = find_peaks(w[sel], height=1.2 * omega, distance=500)
    tp = t[sel][pk]
    assert len(tp) >= 4, "no stick-slip cycle"
    return float(np.diff(tp).mean()), float(w[sel][pk].mean()), float(w[sel].min())


def test_stick_slip_limit_cycle_matches_the_torsional_pendulum():
    sc = load_scene("stick_slip")
    plant = sc.plant
    J, k, c = _pendulum_parameters(plant)
    omega, tr = plant.top_drive.rotary_speed, plant.top_drive.ramp_time
    weight = plant.bit.weight_on_bit
    stop = 60.0

    def drive(t: float) -> tuple[float, float]:
        if t < tr:
            return 0.5 * omega * t * t / tr, omega * t / tr
        return omega * (t - 0.5 * tr), omega

    def f(t, x):
        a, ad = drive(t)
        return [x[1], (k * (a - x[0]) + c * (ad - x[1]) - _bit_torque(plant.bit, x[1], weight))
                / J]

    te = np.arange(round(stop / 1e-3) + 1) * 1e-3
    s1 = solve_ivp(f, (0, tr), [0.0, 0.0], method="DOP853", rtol=1e-10, atol=1e-12,
                   dense_output=True)
    s2 = solve_ivp(f, (tr, stop), s1.y[:, -1], method="DOP853", rtol=1e-10, atol=1e-12,
                   dense_output=True)
    w_ref = np.concatenate([s1.sol(te[te < tr])[1], s2.sol(te[te >= tr])[1]])
    model = DrillstringModel(plant, sc.model)
    t, v, res = simulate(model, stop, 1e-3, ["bit_rotary_speed", "bit_axial_force"])
    assert res.ok
    period, peak, low = _cycle(t, v["bit_rotary_speed"], omega, 30.0)
    period_ref, peak_ref, low_ref = _cycle(te, w_ref, omega, 30.0)
    # measured: 4.352 vs 4.346 s, 4.456 vs 4.448 rad/s
    assert period == pytest.approx(period_ref, rel=0.02)
    assert peak == pytest.approx(peak_ref, rel=0.02)
    assert low < 0.05 * omega and low_ref < 0.05 * omega  # the bit stops (creeps) each cycle
    # the axial chain keeps the weight on bit nearly constant (the pendulum's assumption)
    assert np.abs(v["bit_axial_force"][t > 30.0] / weight - 1).max() < 0.01


def test_stick_slip_threshold_of_the_negative_damping_criterion():
    """Steady rotation at Omega perturbed by 0.05 rad/s: the torsional oscillation grows below
    Omega_c = w_w ln(a mu gamma W_f (s - 1) / (2 w_w c)) and decays above it, at the pendulum's
    rate -(c + T'(Omega)) / (2 J) (measured within 10 %)."""
    sc0 = load_scene("stick_slip")
    plant = sc0.plant
    bit = plant.bit
    J, k, c = _pendulum_parameters(plant)
    wf = min(bit.weight_on_bit, bit.wearflat_force)
    slope0 = 0.5 * bit.radius * bit.friction_coefficient * wf * (bit.static_friction_ratio - 1) \
        / bit.weakening_speed
    omega_c = bit.weakening_speed * math.log(slope0 / c)
    assert 3.5 < omega_c < 4.5 and plant.top_drive.rotary_speed < omega_c
    n = plant.pipe.n_segments
    for factor in (0.7, 1.3):
        omega = factor * omega_c
        sc = load_scene("stick_slip", overrides={"top_drive": {"rotary_speed": omega,
                                                               "ramp_time": 0.0}})
        sim = _steady_simulator(sc.plant, sc.model, omega,
                                _bit_torque(bit, omega, bit.weight_on_bit))
        sim.y[4 * n - 1] += 0.05  # kick the bit
        m = sim.model
        i = m.output_names.index("bit_rotary_speed")
        rec = []
        for s in range(60000):
            assert sim.do_step(s * 1e-3, 1e-3).ok
            rec.append(sim.outputs()[i] - omega)
        w = np.abs(np.array(rec))
        t = (np.arange(w.size) + 1) * 1e-3
        pk, _ = find_peaks(w, distance=1000)
        sel = t[pk] > 5.0
        growth = np.polyfit(t[pk][sel], np.log(w[pk][sel]), 1)[0]
        slope = -slope0 * math.exp(-omega / bit.weakening_speed)
        predicted = -(c + slope) / (2 * J)
        assert np.sign(growth) == np.sign(predicted) == (1 if factor < 1 else -1)
        assert growth == pytest.approx(predicted, rel=0.1), (factor, growth, predicted)


def _lift_off_amplitude(plant) -> float:
    """A* [m]: the profile amplitude at which the linear steady contact force first touches 0.

    Frequency-domain model of the chain assembled here from the parameters: bodies m, joints
    k_a (1 + i w beta_a), free top; contact force W = k_b (u_n - z_h - s) + c_b (u_n' - s') on the
    bit body; the hole bottom deepens at z_h' = W Omega / (2 pi a zeta eps) (no wear flats);
    profile s = A e^{i w t}, w = lobes * Omega.
    """
    pipe, bit = plant.pipe, plant.bit
    n, dx = pipe.n_segments, pipe.segment_length
    m_seg = pipe.density * pipe.area * dx
    ka = pipe.youngs_modulus * pipe.area / dx
    beta = 2 * plant.damping.axial_ratio / (math.pi * pipe.axial_wave_speed / (2 * pipe.length))
    kb = series(bit.axial_stiffness, 2 * ka)
    cb = beta * kb
    om = plant.top_drive.rotary_speed
    w = bit.lobes * om
    rop = om / (2 * math.pi * bit.radius * bit.cutting_force_ratio * bit.intrinsic_specific_energy)
    M = np.zeros((n + 1, n + 1), complex)
    F = np.zeros(n + 1, complex)
    for a in range(n - 1):
        for i, j, s in ((a, a, 1), (a + 1, a + 1, 1), (a, a + 1, -1), (a + 1, a, -1)):
            M[i, j] += s * ka * (1 + 1j * w * beta)
    M[np.arange(n), np.arange(n)] -= w**2 * m_seg
    e = n - 1
    zb = kb + 1j * w * cb
    M[e, e] += zb
    M[e, n] -= kb
    F[e] += zb
    M[n, n] += 1j * w + rop * kb
    M[n, e] -= rop * zb
    F[n] -= rop * zb
    X = np.linalg.solve(M, F)
    g = kb * (X[e] - X[n] - 1) + 1j * w * cb * (X[e] - 1)
    return bit.weight_on_bit / abs(g)


def test_bit_lifts_off_above_the_linear_threshold():
    sc = load_scene("bit_bounce")
    a_star = _lift_off_amplitude(sc.plant)
    assert 0.8e-3 < a_star < 1.5e-3
    assert sc.plant.bit.displacement_amplitude > a_star  # the shipped scene bounces
    plant = sc.plant
    omega, w0 = plant.top_drive.rotary_speed, plant.bit.weight_on_bit
    for factor in (0.8, 0.9, 1.05, 1.2):
        s2 = load_scene("bit_bounce", overrides={
            "bit": {"displacement_amplitude": factor * a_star}, "top_drive": {"ramp_time": 0.0}})
        sim = _steady_simulator(s2.plant, s2.model, omega,
                                0.5 * plant.bit.radius * w0 / plant.bit.cutting_force_ratio)
        m = sim.model
        idx = [m.output_names.index(k) for k in ("bit_axial_force", "bit_on_bottom")]
        rec = []
        for s in range(6000):
            assert sim.do_step(s * 1e-3, 1e-3).ok
            rec.append(sim.outputs()[idx].copy())
        rec = np.array(rec)[4000:]
        if factor < 1.0:
            assert np.all(rec[:, 1] == 1.0), factor
            # steady minimum W0 (1 - A / A*): measured 6.02 / 3.05 kN vs 6.0 / 3.0 kN
            assert rec[:, 0].min() == pytest.approx(w0 * (1 - factor), rel=0.05)
        else:
            assert np.any(rec[:, 1] == 0.0), factor  # off bottom during part of every lobe
            assert rec[:, 0].min() == 0.0


def test_steady_drilling_follows_the_detournay_defourny_relations():
    """No weakening, 6 rad/s: depth of cut d = (W - W_f*) / (a zeta eps), rate of penetration
    d Omega / 2 pi, torque on the E-S line, drilled depth = integral of the rate."""
    sc = load_scene("stick_slip", overrides={"top_drive": {"rotary_speed": 6.0, "ramp_time": 0.0},
                                             "bit": {"static_friction_ratio": 1.0}})
    bit = sc.plant.bit
    sim = _steady_simulator(sc.plant, sc.model, 6.0, _bit_torque(bit, 6.0, bit.weight_on_bit))
    m = sim.model
    names = ["rate_of_penetration", "depth_of_cut", "bit_torque", "bit_axial_force",
             "drilled_depth", "bit_rotary_speed"]
    idx = np.array([m.output_names.index(k) for k in names])
    rec, res = sim.run_record(1e-3, 10000, idx)
    assert res.ok
    t = np.arange(rec.shape[0]) * 1e-3
    v = {k: rec[:, i] for i, k in enumerate(names)}
    last = {k: x[-1] for k, x in v.items()}
    W, om = last["bit_axial_force"], last["bit_rotary_speed"]
    a, zeta, eps, mu = (bit.radius, bit.cutting_force_ratio, bit.intrinsic_specific_energy,
                        bit.friction_coefficient)
    # steady state (the 1 %-damped pendulum mode keeps a few mrad/s of the start)
    assert np.mean(v["bit_rotary_speed"][-3000:]) == pytest.approx(6.0, rel=2e-3)
    assert np.mean(v["bit_axial_force"][-3000:]) == pytest.approx(bit.weight_on_bit, rel=2e-3)
    # the law, at the instantaneous weight on bit and speed
    d = (W - bit.wearflat_force) / (a * zeta * eps)
    assert last["depth_of_cut"] == pytest.approx(d, rel=1e-12)
    assert last["rate_of_penetration"] == pytest.approx(d * om / (2 * math.pi), rel=1e-12)
    E = 2 * last["bit_torque"] / (a * a * d)  # specific energy [Pa]
    S = W / (a * d)  # drilling strength [Pa]
    assert E == pytest.approx(eps * (1 - mu * zeta) + mu * S, rel=1e-9)
    # the hole bottom is the integral of the rate of penetration
    drilled = np.trapezoid(v["rate_of_penetration"], t)
    assert last["drilled_depth"] == pytest.approx(drilled, rel=1e-5)


def test_full_3d_model_carries_the_same_bit_law():
    """A straight string has no lateral motion: the 3D model's bit equals the chain's."""
    over = {"pipe": {"n_segments": 12}}
    names = ["bit_rotary_speed", "bit_torque", "bit_axial_force", "drilled_depth"]
    runs = []
    for kind in ("axial_torsional", "full3d"):
        sc = load_scene("stick_slip", overrides={**over, "model": kind})
        m = DrillstringModel(sc.plant, sc.model)
        t, v, res = simulate(m, 8.0, 1e-3, names, max_step=2e-3)
        assert res.ok
        runs.append(v)
    for k in names:
        scale = np.abs(runs[0][k]).max()
        assert np.abs(runs[0][k] - runs[1][k]).max() < 1e-6 * scale, k


def test_prescribed_bit_remains_the_default_and_adds_nothing():
    sc = load_scene("paper_open_loop")
    m = DrillstringModel(sc.plant, sc.model)
    assert sc.plant.bit.model == "prescribed" and m.n_state == 12 * m.n
    assert "rate_of_penetration" not in m.output_names


@pytest.mark.parametrize("table, message", [
    ({"model": "pdc"}, "bit.model = 'pdc' is not allowed: one of 'prescribed', 'cutting'"),
    ({"model": "cutting", "axial_stiffness": 0.0},
     "bit.axial_stiffness = 0 is not allowed with model = 'cutting'"),
    ({"radius": 0.0}, "bit.radius = 0.0 is out of range: allowed (0, 2] m"),
    ({"intrinsic_specific_energy": -1.0}, "bit.intrinsic_specific_energy = -1.0 is out of range"),
    ({"static_friction_ratio": 0.5}, "bit.static_friction_ratio = 0.5 is out of range: allowed "
                                     "[1, 100]"),
    ({"weakening_speed": 0.0}, "bit.weakening_speed = 0.0 is out of range: allowed (0, 1000] "
                               "rad/s"),
    ({"slip_speed": math.nan}, "bit.slip_speed = nan is not allowed"),
    ({"inertia": -5.0}, "bit.inertia = -5.0 is out of range: allowed [0, 1e+07] kg m^2"),
])
def test_bad_bit_parameters_are_refused_in_one_line(table, message):
    with pytest.raises(SceneError) as exc:
        scene_from_dict({"bit": table}, source="b.toml")
    assert message in str(exc.value) and "\n" not in str(exc.value)
