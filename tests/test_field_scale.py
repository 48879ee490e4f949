"""Field-scale strings: sections, a curved hole, drilling fluid, checked against
independent models: a soft-string torque-and-drag model (tests/support/soft_string.py), the
Dawson-Paslay buckling load, the exact frequency equation of a two-section rod, Archimedes and
the added mass of a confined cylinder, energy conservation."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.optimize import brentq
from threadpoolctl import threadpool_limits

from drillcosim.analysis.modal import modes
from drillcosim.plant import layout as lay
from drillcosim.plant.model import DrillstringModel
from drillcosim.plant.params import (
    BitParams,
    ContactParams,
    DampingParams,
    FluidParams,
    LoadParams,
    PipeParams,
    PlantParams,
    SectionParams,
    StabilizerParams,
    TopDriveParams,
    TrajectoryParams,
    UnbalanceParams,
)
from drillcosim.plant.scene import SceneError, list_scenes, load_scene, scene_from_dict
from drillcosim.plant.simulator import simulate
from drillcosim.plant.trajectory import WellPath
from support.soft_string import Element, soft_string

G = 9.81
STEEL = 7850.0
# 5-in drill pipe with tool joints, 6.75-in collars
DP = dict(kind="drill_pipe", outer_diameter=0.127, inner_diameter=0.1086, linear_mass=29.0,
          contact_diameter=0.165)
DC = dict(kind="collar", outer_diameter=0.1714, inner_diameter=0.0714)
HOLE = 0.2159


def area(od: float, idia: float) -> float:
    return math.pi / 4.0 * (od**2 - idia**2)


# --------------------------------------------------------------------------- the uniform pipe
def test_one_section_is_the_uniform_pipe():
    """[[sections]] with one section equal to [pipe] builds the same masses, inertias, springs
    and rhs (without damping: the damping's reference frequencies are defined differently, the
    continuous rod's for the pipe, the lumped chain's for sections)."""
    pipe = PipeParams()
    still = DampingParams(axial_ratio=0.0, torsional_ratio=0.0, lateral_ratio=0.0)
    base = PlantParams(gravity=9.81, damping=still)
    sec = SectionParams(kind="collar", length=pipe.length, outer_diameter=pipe.outer_diameter,
                        inner_diameter=pipe.inner_diameter, segment_length=pipe.segment_length)
    one = PlantParams(sections=(sec,), stabilizers=StabilizerParams(heights=(0.0, 26.67)),
                      contact=ContactParams(bodies=(11, 26)), damping=still,
                      actuators=base.actuators.__class__(joints=(11, 26)), gravity=9.81)
    a = DrillstringModel(base)
    b = DrillstringModel(one)
    body = slice(lay.NP, None)
    assert np.array_equal(a.p[body], b.p[body])
    d = a.derived
    assert a.bodies.mass[0] == d.mass and a.bodies.k_axial[0] == d.k_axial
    rng = np.random.default_rng(3)
    y = a.initial_state() + 1e-3 * rng.standard_normal(a.n_state)
    # the stabilizer at 26.67 m is placed by the sections' cumulative lengths: 1 ulp apart
    assert np.allclose(a.fp, b.fp, rtol=0.0, atol=1e-12)
    da, db = a.rhs(0.3, y), b.rhs(0.3, y)
    assert np.allclose(da, db, rtol=1e-12, atol=1e-12 * np.abs(da).max())


# --------------------------------------------------------------------------- trajectory
def test_minimum_curvature_follows_the_circle_and_the_rotating_tangent():
    # build and hold in the vertical plane of azimuth 0: a circular arc of radius R
    path = WellPath([(0.0, 0.0, 0.0), (300.0, 0.0, 0.0), (900.0, 60.0, 0.0),
                     (1300.0, 60.0, 0.0)])
    R = 600.0 / math.radians(60.0)
    for md in (150.0, 450.0, 899.0, 1200.0):
        if md <= 300.0:
            exp = (0.0, md)
        elif md <= 900.0:
            a = (md - 300.0) / R
            exp = (R * (1.0 - math.cos(a)), 300.0 + R * math.sin(a))
        else:
            a = math.radians(60.0)
            exp = (R * (1 - math.cos(a)) + (md - 900) * math.sin(a),
                   300 + R * math.sin(a) + (md - 900) * math.cos(a))
        p = path.point(md)
        assert p[0] == pytest.approx(exp[0], abs=1e-8) and p[2] == pytest.approx(exp[1], abs=1e-8)
        assert p[1] == pytest.approx(0.0, abs=1e-12)
    # a turning 3D segment: the position is the integral of the tangent, which turns at a
    # constant rate in one plane (integrated here by Simpson's rule)
    path = WellPath([(0.0, 10.0, 20.0), (500.0, 50.0, 110.0)])
    s = np.linspace(0.0, 400.0, 4001)
    t = np.array([path.tangent(x) for x in s])
    ang = np.arccos(np.clip(np.einsum("ij,j->i", t, t[0]), -1, 1))
    assert np.allclose(np.diff(ang), ang[1] - ang[0], rtol=1e-6)  # uniform rotation
    w = np.ones(s.size)
    w[1:-1:2], w[2:-1:2] = 4.0, 2.0
    integ = (s[1] - s[0]) / 3.0 * (w[:, None] * t).sum(axis=0)
    assert np.allclose(path.point(400.0) - path.point(0.0), integ, atol=1e-6)


def _td_params(mu: float, mode: str, **over) -> PlantParams:
    """The torque-and-drag well: 1170 m of 5-in drill pipe and 30 m of collars, build and hold
    (kick-off 300 m, 10 deg/100 m to 60 deg at 900 m, azimuth 45 deg), 10 ppg mud."""
    td = dict(rotary_speed=0.0, ramp_time=2.0)
    if mode == "rotate":
        td["rotary_speed"] = 2.0
    elif mode in ("out", "in"):
        td["hoisting_speed"] = 0.2 if mode == "in" else -0.2
    return PlantParams(
        sections=(SectionParams(length=1170.0, segment_length=30.0, **DP),
                  SectionParams(length=30.0, segment_length=5.0, **DC)),
        trajectory=TrajectoryParams(survey=((0, 0, 45), (300, 0, 45), (900, 60, 45),
                                            (1300, 60, 45)), hole=((1300.0, HOLE),)),
        fluid=FluidParams(enabled=True, density=1200.0),
        contact=ContactParams(stiffness=1e7, friction_coefficient=mu, friction_velocity=0.005),
        bit=BitParams(axial_stiffness=0.0, radius=0.0857),  # off bottom; bit at the collar gauge
        unbalance=UnbalanceParams(enabled=False),
        # quasi-static: strong torsional and lateral damping settle the run, little axial
        # damping (stiffness-proportional bending dampers would add torque in a rotating bend)
        damping=DampingParams(axial_ratio=0.005, torsional_ratio=0.2, lateral_ratio=1.0,
                              lateral_reference_frequency=5.0, max_joint_rate=0.0),
        top_drive=TopDriveParams(**td), gravity=G, **over)


def _td_angles(s: float) -> tuple[float, float]:
    inc = 0.0 if s <= 300.0 else min(60.0, 60.0 * (s - 300.0) / 600.0)
    return math.radians(inc), math.radians(45.0)


def _td_soft_string(mu: float, mode: str, lateral_friction: bool = False) -> tuple[float, float]:
    bf = 1.0 - 1200.0 / STEEL
    string = [Element(1170.0, 29.0 * G * bf, 0.165 / 2),
              Element(30.0, STEEL * area(0.1714, 0.0714) * G * bf, 0.1714 / 2)]
    return soft_string(string, _td_angles, mu, mode, step=1.0, lateral_friction=lateral_friction)


def test_string_starts_along_the_hole_in_axial_equilibrium():
    m = DrillstringModel(_td_params(0.3, "static"))
    y = m.initial_state()
    n = m.n
    lz = m.lay
    # every body's bottom end lies on the hole axis (the independent circle of the build)
    R = 600.0 / math.radians(60.0)
    eob = np.array([R * (1.0 - math.cos(math.radians(60))), 300.0 + R * math.sin(math.radians(60))])
    u = np.array([math.sin(math.radians(60)), math.cos(math.radians(60))])

    def distance_to_axis(q: np.ndarray) -> float:
        d_vert = math.hypot(q[0], max(0.0, q[1] - 300.0)) if q[1] >= 0 else math.inf
        rel = q - np.array([R, 300.0])
        ang = math.degrees(math.atan2(rel[1], rel[0]))
        d_arc = abs(math.hypot(*rel) - R) if 120.0 <= ang <= 180.0 else math.inf
        s = float(np.dot(q - eob, u))
        r = q - eob
        d_tan = abs(u[0] * r[1] - u[1] * r[0]) if s >= 0.0 else math.inf
        return min(d_vert, d_arc, d_tan)

    for k in range(n):
        b = lz.centre[k] + m.bodies.half[k] * lz.axis[k]
        q = np.array([math.hypot(b[0], b[1]), b[2]])  # in the vertical plane of azimuth 45
        assert abs(b[0] - b[1]) < 1e-9 * max(1.0, abs(b[0]))
        assert distance_to_axis(q) < 1e-6, (k, distance_to_axis(q))
    # no joint starts with a shear offset; axial accelerations vanish (static axial balance)
    acc = m.rhs(0.0, y)[6 * n: 9 * n].reshape(n, 3)
    assert np.abs(acc[:, 2]).max() < 1e-5
    # frictionless hook load: the buoyed weight's axial components (soft string, mu = 0); the
    # laid string's joints carry no shear yet: 1.1 % less (the runs below settle to it)
    hook = m.output_dict(0.0, y)["hook_load"]
    assert hook == pytest.approx(_td_soft_string(0.0, "rotate")[0], rel=0.02)


@pytest.mark.slow
@pytest.mark.parametrize("mu", [0.2, 0.3])
def test_hook_load_and_torque_against_the_soft_string_model(mu):
    """Johancsik et al. (1984) soft string: hook load tripping out / in within 3 %; surface
    torque rotating off bottom within 3 % of the soft string with the wall friction's lateral
    balance, and below plain Johancsik by at most the climb's 1 - 1/sqrt(1 + mu^2) (+ 1 %)
    (docs/field_scale.md, section 3)."""
    T = 10.0
    res = {}
    for mode in ("out", "in", "rotate"):
        m = DrillstringModel(_td_params(mu, mode))
        ts, v, r = simulate(m, T, 0.01, outputs=["hook_load", "top_torque"])
        assert r.ok, r.message
        late = ts >= T - 4.0
        res[mode] = (v["hook_load"][late].mean(), v["top_torque"][late].mean())
    for mode in ("out", "in"):
        ref = _td_soft_string(mu, mode)[0]
        assert res[mode][0] == pytest.approx(ref, rel=0.03), (mode, res[mode][0], ref)
    F0 = _td_soft_string(mu, "rotate")[0]
    assert res["rotate"][0] == pytest.approx(F0, rel=0.01)  # rotating: no axial drag
    torque = res["rotate"][1]
    plain = _td_soft_string(mu, "rotate")[1]
    balanced = _td_soft_string(mu, "rotate", lateral_friction=True)[1]
    # the rotating pipe climbs the wall by atan(mu) until the wall's reaction N n + mu N t
    # balances the lateral load P: N = P / sqrt(1 + mu^2), where Johancsik sets N = P. So the
    # torque lies below plain Johancsik by that factor; 1 % either way for the lumped string
    # (30 m pipe bodies against 1 m soft-string elements) and the regularized friction
    climb = 1.0 - 1.0 / math.sqrt(1.0 + mu * mu)
    assert plain * (1.0 - climb - 0.01) <= torque <= plain * 1.01, (torque, plain)
    assert torque == pytest.approx(balanced, rel=0.03), (torque, balanced)
    # drag brackets the frictionless hook load
    assert res["in"][0] < F0 < res["out"][0]


# --------------------------------------------------------------------------- buckling
def _buckling_model(dx: float, F: float) -> DrillstringModel:
    """A horizontal straight hole; 5-in pipe resting on the low side, compressed by F [N]
    between a load on the top body and the bit; 24 m end pieces 10x stiffer keep the free
    ends from swinging (the end loads are dead loads)."""
    pipe = dict(kind="drill_pipe", outer_diameter=0.127, inner_diameter=0.1086,
                segment_length=dx)
    end = dict(pipe, kind="sub", youngs_modulus=10 * 208e9, length=24.0)
    return DrillstringModel(PlantParams(
        sections=(SectionParams(**end), SectionParams(length=144.0, **pipe),
                  SectionParams(**end)),
        trajectory=TrajectoryParams(survey=((0.0, 90.0, 0.0),), hole=((1e4, HOLE),)),
        contact=ContactParams(stiffness=1e7),
        bit=BitParams(axial_stiffness=1e9, weight_on_bit=F, radius=0.01,
                      displacement_amplitude=0.0),
        top_drive=TopDriveParams(lateral_stiffness=0.0, axial_stiffness=0.0, rotary_speed=0.0),
        loads=(LoadParams(kind="force", body=1, direction="x", magnitude=F),),
        unbalance=UnbalanceParams(enabled=False), gravity=G), "full3d")


def _buckled(dx: float, F: float) -> bool:
    """Is the straight pipe on the low side unstable at compression F? (divergence: the
    linearized stiffness has a negative eigenvalue)"""
    m = _buckling_model(dx, F)
    n = m.n
    y = m.initial_state()
    clr = (HOLE - 0.127) / 2.0
    for k in range(n):  # rest on the low side: local -x in this hole
        y[3 * k] = -(clr + m.p[lay.NP + lay.NB * k + lay.B_W] / 1e7)
    assert np.abs(m.rhs(0.0, y)[6 * n:]).max() < 1e-5  # an exact equilibrium
    nq = 6 * n
    J = np.empty((nq, nq))
    for i in range(nq):
        h = 1e-7 * max(1.0, abs(y[i]))
        yp = y.copy()
        yp[i] += h
        fp = m.rhs(0.0, yp)[nq:]
        yp[i] -= 2 * h
        J[:, i] = (fp - m.rhs(0.0, yp)[nq:]) / (2 * h)
    # at zero Cardan angles (psi, theta, phi)'' = (wz, wy, wx)': reorder the angular rows
    perm = np.arange(nq)
    for k in range(n):
        perm[3 * n + 3 * k: 3 * n + 3 * k + 3] = 3 * n + 3 * k + np.array([2, 1, 0])
    with threadpool_limits(1):
        lam = np.linalg.eigvals(J[perm])  # -M^-1 K
    return float(lam.real.max()) > 1e-6


def test_sinusoidal_buckling_onset_against_dawson_paslay():
    E, od, idia = 208e9, 0.127, 0.1086
    I = math.pi / 64 * (od**4 - idia**4)
    w = STEEL * area(od, idia) * G
    r = (HOLE - od) / 2
    F_dp = 2.0 * math.sqrt(E * I * w * math.sin(math.pi / 2) / r)  # Dawson and Paslay 1984
    errs = []
    for dx in (4.0, 3.0, 2.0):
        lo, hi = 0.7 * F_dp, 1.2 * F_dp
        assert _buckled(dx, hi) and not _buckled(dx, lo)
        for _ in range(7):
            mid = 0.5 * (lo + hi)
            lo, hi = (lo, mid) if _buckled(dx, mid) else (mid, hi)
        errs.append(0.5 * (lo + hi) / F_dp - 1.0)
    # measured: -13 %, -6.8 %, -2.4 %: converging to F_dp as the segments shorten
    assert abs(errs[2]) < 0.10
    assert abs(errs[0]) > abs(errs[1]) > abs(errs[2])


# --------------------------------------------------------------------------- frequencies
def _two_section_roots(Z1, c1, L1, Z2, c2, L2, count):
    """Exact natural frequencies [rad/s] of a two-section rod, fixed at the top, free at the
    bottom: Z1 cos(w L1/c1) cos(w L2/c2) = Z2 sin(w L1/c1) sin(w L2/c2)."""
    def f(w):
        return Z1 * math.cos(w * L1 / c1) * math.cos(w * L2 / c2) - Z2 * math.sin(
            w * L1 / c1) * math.sin(w * L2 / c2)

    grid = np.linspace(1e-6, 200.0, 200001)
    vals = np.array([f(x) for x in grid])
    idx = np.flatnonzero(np.sign(vals[:-1]) != np.sign(vals[1:]))[:count]
    return [brentq(f, grid[i], grid[i + 1]) for i in idx]


def test_two_section_axial_and_torsional_frequencies_against_the_exact_equation():
    L1, L2 = 1000.0, 200.0
    pipe = dict(kind="drill_pipe", outer_diameter=0.127, inner_diameter=0.1086)
    p = PlantParams(
        sections=(SectionParams(length=L1, segment_length=10.0, **pipe),
                  SectionParams(length=L2, segment_length=5.0, **DC)),
        top_drive=TopDriveParams(axial_stiffness=math.inf, rotary_speed=0.0),
        bit=BitParams(axial_stiffness=0.0, displacement_amplitude=0.0),
        damping=DampingParams(axial_ratio=0.0, torsional_ratio=0.0, lateral_ratio=0.0),
        contact=ContactParams(enabled=False, bodies=(1,)),
        unbalance=UnbalanceParams(enabled=False))
    m = DrillstringModel(p, "axial_torsional")
    found = {"axial": [], "torsional": []}
    for md in modes(m):
        found[md.kind].append(md.frequency_rad_s)
    E, Gm = 208e9, 81e9
    sec = [(0.127, 0.1086, L1), (0.1714, 0.0714, L2)]
    ax = [(math.sqrt(E * area(o, i) * STEEL * area(o, i)), math.sqrt(E / STEEL), L)
          for o, i, L in sec]
    J = [math.pi / 32 * (o**4 - i**4) for o, i, _ in sec]
    to = [(math.sqrt(Gm * j * STEEL * j), math.sqrt(Gm / STEEL), L)
          for j, (_, _, L) in zip(J, sec)]
    for kind, s in (("axial", ax), ("torsional", to)):
        exact = _two_section_roots(*s[0], *s[1], count=3)
        for k, w in enumerate(exact):
            assert found[kind][k] == pytest.approx(w, rel=0.005), (kind, k, found[kind][k], w)


def test_buoyed_hook_load_is_the_buoyed_weight():
    rho_m = 1500.0
    secs = (SectionParams(length=1500.0, segment_length=30.0, **DP),
            SectionParams(length=60.0, segment_length=6.0, **DC))
    for traj in (None, TrajectoryParams(hole=((5000.0, HOLE),))):
        p = PlantParams(sections=secs, trajectory=traj, gravity=G,
                        fluid=FluidParams(enabled=True, density=rho_m),
                        bit=BitParams(axial_stiffness=0.0, radius=HOLE / 2),
                        contact=ContactParams(bodies=(1,)),
                        unbalance=UnbalanceParams(enabled=False))
        weight = (1500.0 * 29.0 + 60.0 * STEEL * area(0.1714, 0.0714)) * G * (1 - rho_m / STEEL)
        for kind in ("axial_torsional", "full3d"):
            m = DrillstringModel(p, kind)
            assert m.output_dict(0.0, m.initial_state())["hook_load"] == pytest.approx(
                weight, rel=1e-9)
        _, v, r = simulate(m, 0.2, 0.01, outputs=["hook_load"])  # and it stays there
        assert r.ok and np.allclose(v["hook_load"], weight, rtol=1e-6)


def test_added_mass_lowers_the_lateral_span_frequency():
    L = 20.0
    rho_m = 1200.0
    od, idia = 0.1714, 0.0714

    def first_lateral(fluid: bool) -> float:
        p = PlantParams(
            sections=(SectionParams(length=L, segment_length=0.5, **DC),),
            trajectory=TrajectoryParams(hole=((100.0, HOLE),)),
            fluid=FluidParams(enabled=fluid, density=rho_m, drag_coefficient=0.0),
            stabilizers=StabilizerParams(heights=(0.0,)),  # pinned at the bit and the top
            top_drive=TopDriveParams(rotary_speed=0.0),
            bit=BitParams(axial_stiffness=0.0, radius=0.09),
            damping=DampingParams(lateral_ratio=0.0), unbalance=UnbalanceParams(enabled=False))
        m = DrillstringModel(p, "full3d")
        return next(md.frequency_rad_s for md in modes(m) if md.kind == "lateral")

    ca = (HOLE**2 + od**2) / (HOLE**2 - od**2)  # confined potential flow
    m_pipe = STEEL * area(od, idia)
    m_add = rho_m * math.pi * ((idia / 2) ** 2 + ca * (od / 2) ** 2)  # mud inside + displaced
    ratio = first_lateral(True) / first_lateral(False)
    assert ratio == pytest.approx(math.sqrt(m_pipe / (m_pipe + m_add)), rel=1e-3)


# --------------------------------------------------------------------------- consistency
def test_energy_is_conserved_in_a_curved_hole():
    """No damping, no friction, no mud drag: the string released from the hole axis falls onto
    the low side and bounces; kinetic + elastic + gravity + contact energy stays constant."""
    p = PlantParams(
        sections=(SectionParams(length=570.0, segment_length=30.0, **DP),
                  SectionParams(length=30.0, segment_length=5.0, **DC)),
        trajectory=TrajectoryParams(survey=((0, 0, 0), (100, 0, 0), (400, 30, 60),
                                            (700, 30, 60)), hole=((700.0, HOLE),)),
        contact=ContactParams(stiffness=1e7), gravity=G,
        damping=DampingParams(axial_ratio=0.0, torsional_ratio=0.0, lateral_ratio=0.0),
        top_drive=TopDriveParams(rotary_speed=0.0),
        bit=BitParams(axial_stiffness=0.0, radius=HOLE / 2), unbalance=UnbalanceParams(enabled=False))
    drift = []
    for div in (1, 4):
        m = DrillstringModel(p, "full3d")
        _, v, r = simulate(m, 1.0, 0.001, outputs=["total_energy", "wall_contact_force"],
                           max_step=m.stable_step() / div)
        assert r.ok
        assert v["wall_contact_force"].max() > 1e3  # it did hit the wall
        drift.append(np.abs(v["total_energy"] - v["total_energy"][0]).max())
    fall = 0.5 * m.bodies.mass.sum() * (2 * G * 0.02)  # the energy of a 2 cm fall, for scale
    # measured: 3e-4 of it at h*, 8e-6 at h*/4: the integrator's error, going to zero
    assert drift[0] < 1e-3 * fall and drift[1] < drift[0] / 10.0


def test_vertical_field_string_axial_torsional_equals_3d():
    """In a vertical hole with no lateral excitation the 3D model's lateral DOFs stay at zero:
    its axial-torsional outputs equal the chain's (per-body arrays consistent in both kernels)."""
    sc = load_scene("field_vertical_3km")
    outs = ["bit_rotary_speed", "top_torque", "hook_load", "bit_axial_force", "drilled_depth"]
    res = {}
    for kind in ("axial_torsional", "full3d"):
        m = DrillstringModel(sc.plant, kind)
        _, v, r = simulate(m, 1.0, 0.01, outputs=outs)
        assert r.ok
        res[kind] = v
    for o in outs:
        scale = max(1.0, np.abs(res["full3d"][o]).max())
        assert np.abs(res["full3d"][o] - res["axial_torsional"][o]).max() < 1e-7 * scale, o


def test_field_scenes_load_and_run():
    for name, kind in (("field_vertical_3km", "axial_torsional"),
                       ("field_deviated_3km", "full3d")):
        sc = load_scene(name)
        assert sc.model == kind
        m = DrillstringModel(sc.plant, sc.model)
        assert 100 < m.n < 150
        assert set(sc.outputs) <= set(m.output_names)
        assert not any(nm.startswith("body") for nm in m.output_names)  # a summary by default
        _, v, r = simulate(m, 0.2, 0.01, outputs=list(sc.outputs))
        assert r.ok, r.message


def test_field_scenes_through_the_api_equal_the_plant_alone():
    """``drillcosim.simulate`` (typed configuration, builder, master, in-process slaves) of the
    field scenes: the plant's outputs equal the plant stepped alone (a second path: no master),
    and the controlled variants run their loops (strain controller at a BHA site, top-drive
    controller) with every signal the scene names."""
    import drillcosim

    T, H = 0.05, 1e-3
    res = drillcosim.simulate("field_deviated_3km", stop_time=T, engine="inprocess")
    assert res.completed
    sc = load_scene("field_deviated_3km")
    m = DrillstringModel(sc.plant, sc.model)
    _, v, r = simulate(m, T, H, outputs=list(sc.outputs))
    assert r.ok
    for name in sc.outputs:
        got = res[f"plant.{name}"]
        assert got.shape == v[name].shape
        assert np.abs(got - v[name]).max() <= 1e-12 * np.abs(v[name]).max() + 1e-9, name
    for scene, control in (("field_deviated_3km_bha_control", "controller.actuator1_force_C"),
                           ("field_vertical_3km_soft_torque",
                            "top_drive_controller.top_drive_torque")):
        res = drillcosim.simulate(scene, stop_time=T, engine="inprocess")
        assert res.completed, (scene, res.failure)
        assert {f"plant.{o}" for o in load_scene(scene).outputs} <= set(res.columns)
        assert np.ptp(res[control]) > 0, scene  # the controller acts


@pytest.mark.parametrize(
    ("data", "words"),
    [
        ({"pipe": {"length": 100.0}, "sections": [{"length": 10.0}]}, ["[pipe]", "[[sections]]"]),
        ({"sections": [{"length": -1.0}]}, ["sections.length", "-1"]),
        ({"sections": [{"length": 10.0, "kind": "pipe"}]}, ["sections.kind", "'pipe'"]),
        ({"sections": [{"length": 10.0, "segment_length": 1.0}],
          "trajectory": {"survey": [[0, 0, 0], [100, 10, 0]], "hole": [[100, 0.1]]},
          "bit": {"radius": 0.04}},
         ["does not fit the hole"]),
        ({"sections": [{"length": 10.0, "segment_length": 1.0}],
          "trajectory": {"survey": [[10, 0, 0]], "hole": [[100, 0.3]]}},
         ["trajectory.survey", "measured depth 0"]),
        ({"sections": [{"length": 10.0, "segment_length": 1.0}],
          "trajectory": {"survey": [[0, 0, 0], [0, 5, 0]], "hole": [[100, 0.3]]}},
         ["trajectory.survey", "rising MD"]),
        ({"sections": [{"length": 10.0, "segment_length": 1.0}], "trajectory": {}},
         ["trajectory.hole"]),
        ({"sections": [{"length": 10.0, "segment_length": 1.0, "stabilizers": [2.0],
                        "stabilizer_diameter": 0.2}]}, ["stabilizers", "[trajectory]"]),
        # a bit or a stabilizer blade larger than the hole at its depth
        ({"sections": [{"length": 10.0, "segment_length": 1.0}],
          "trajectory": {"hole": [[100, HOLE]]}, "bit": {"radius": 0.108}},
         ["bit.radius = 0.108 m", "gauge diameter 0.216 m", "hole diameter 0.2159 m"]),
        ({"sections": [{"length": 20.0, "segment_length": 1.0, "stabilizers": [2.0, 15.0],
                        "stabilizer_diameter": 0.22}],
          "trajectory": {"hole": [[10.0, 0.2205], [100.0, HOLE]]}, "bit": {"radius": 0.1}},
         ["section 1 (drill_pipe)", "stabilizer_diameter = 0.22 m", "hole diameter 0.2159 m",
          "measured depth 15 m"]),
        ({"fluid": {"density": -5.0}}, ["fluid.density", "-5"]),
        ({"sections": [{"length": 10.0}]}, ["at least 2"]),
    ],
)
def test_bad_field_input_is_one_clear_line(data, words):
    with pytest.raises((SceneError, ValueError)) as info:
        sc = scene_from_dict({"contact": {"bodies": [1]}, **data}, source="f.toml")
        DrillstringModel(sc.plant, sc.model)
    msg = str(info.value)
    assert "\n" not in msg
    for w in words:
        assert w in msg, (w, msg)


def test_bits_and_blades_fit_their_hole():
    """Every shipped scene with a hole: the bit's gauge and every stabilizer blade are no
    larger than the hole at their measured depth (the 8.5-in bit in the 8.5-in hole: equal);
    the same blades pass where the hole is larger (a blade in the casing)."""
    for name in list_scenes():
        p = load_scene(name).plant
        if p.trajectory is None:
            continue
        assert 2.0 * p.bit.radius <= p.trajectory.hole_diameter(p.string_length), name
        top = 0.0
        for sec in p.sections:
            for z in sec.stabilizers:
                assert sec.stabilizer_diameter <= p.trajectory.hole_diameter(top + z), name
            top += sec.length
    sc = load_scene("field_vertical_3km")
    assert 2.0 * sc.plant.bit.radius == HOLE  # gauge = hole
    ok = {"sections": [{"length": 20.0, "segment_length": 1.0, "stabilizers": [2.0],
                        "stabilizer_diameter": 0.22}],
          "trajectory": {"hole": [[10.0, 0.2205], [100.0, HOLE]]}, "bit": {"radius": HOLE / 2}}
    scene_from_dict({"contact": {"bodies": [1]}, **ok})


def test_cli_refuses_a_bit_larger_than_its_hole(tmp_path):
    """``drillcosim run`` on a scene whose bit is larger than the hole: exit 2, one line naming
    both diameters with their unit, no traceback, no run."""
    import subprocess
    import sys

    bad = tmp_path / "big_bit.toml"
    bad.write_text('extends = "field_vertical_3km"\n[bit]\nradius = 0.11\n')
    proc = subprocess.run([sys.executable, "-c", "import sys; from drillcosim.cosim.cli import "
                           "console_main; sys.argv[0] = 'drillcosim'; sys.exit(console_main())",
                           "run", str(bad), "--no-plots", "--out", str(tmp_path / "out")],
                          capture_output=True, text=True, timeout=300, cwd=tmp_path)
    assert proc.returncode == 2, proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in proc.stderr, proc.stderr
    for words in ("big_bit.toml", "bit.radius = 0.11 m", "gauge diameter 0.22 m",
                  "hole diameter 0.2159 m"):
        assert words in lines[0], (words, lines[0])
    assert not (tmp_path / "out").exists()


@pytest.mark.slow
@pytest.mark.needs_cc
def test_field_scene_runs_through_its_fmu_as_in_process(tmp_path):
    """``drillcosim run field_deviated_3km`` builds the plant FMU for the scene's layout and runs
    it; its outputs equal the in-process model's (the same physics in the FMU; the master counts
    time in ticks, the in-process loop adds steps: communication times differ in the last bit,
    hence 1e-12 of each signal's range plus 1e-9 in SI units)."""
    from drillcosim.cosim.cli import main

    fmus, res = tmp_path / "fmus", tmp_path / "run"
    assert main(["run", "field_deviated_3km", "--fmu-dir", str(fmus), "--stop-time", "0.1",
                 "--out", str(res), "--no-plots", "--no-progress"]) == 0
    assert (fmus / "DrillstringPlant_field_deviated_3km.fmu").is_file()
    header = (res / "results.csv").read_text().splitlines()[0].split(",")
    data = np.loadtxt(res / "results.csv", delimiter=",", skiprows=1)
    sc = load_scene("field_deviated_3km")
    m = DrillstringModel(sc.plant, sc.model)
    cols = {c[len("plant."):]: i for i, c in enumerate(header) if c.startswith("plant.")}
    assert "hook_load" in cols and "top_torque" in cols
    _, v, r = simulate(m, 0.1, 1e-3, outputs=list(cols))
    assert r.ok
    # the bit's axial force is the bit spring times the bit's axial position, 3 km down: one last
    # bit of that position (np.spacing, 4.5e-13 m) is k_b * 4.5e-13 m = 4.5e-4 N at 1e9 N/m, so
    # the bit's force is held to a few of those and its torque (friction on that force at most
    # the bit's radius out) to that times the radius (the time's last bit moves the drive's ramp)
    depth = sum(s.length for s in sc.plant.sections)
    ulp_force = 4 * sc.plant.bit.axial_stiffness * np.spacing(depth)
    extra = {"bit_axial_force": ulp_force, "bit_torque": ulp_force * sc.plant.bit.radius}
    off = {}
    for c, i in cols.items():
        err = np.abs(data[:, i] - v[c]).max()
        if err > 1e-12 * np.abs(v[c]).max() + 1e-9 + extra.get(c, 0.0):
            off[c] = err
    assert not off, off
