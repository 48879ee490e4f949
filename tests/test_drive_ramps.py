"""The top drive's prescribed motion (hoisting, a rotation ramp) is integrated to each method's
order by every method the automatic choice can pick.

Before the fix the automatic method of a linear axial-torsional scene, exponential Euler, held
the hoisting travel over each step: a hoisting vertical string's steady hook load was off the
buoyed weight by the top spring times half a step of travel (field_vertical_3km off bottom at
0.5 m/s: -1.19 % at 1 ms, -0.18 % at 0.25 ms, measured). The exact step adds the drive's
polynomial-in-time input through phi functions (``plant.integrators.add_drive_ramp``).

Checks: against the buoyed weight computed here from the scene file's numbers (Archimedes, no
wall friction in a vertical hole), and against an adaptive Dormand-Prince reference (a second
integrator) through the ramp, its end and the constant-speed phase.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from drillcosim.analysis.modal import first_modes
from drillcosim.plant.integrators import METHODS
from drillcosim.plant.model import DrillstringModel
from drillcosim.plant.scene import load_scene, read_scene_tables, scene_from_dict
from drillcosim.plant.simulator import PlantSimulator, simulate

G = 9.81
RHO_STEEL = 7850.0  # kg/m^3, the sections' default density (the scene sets none)
OFF_BOTTOM = {"model": "prescribed", "axial_stiffness": 0.0, "weight_on_bit": 0.0,
              "displacement_amplitude": 0.0, "torque": 0.0}


def _hoisting_tables(speed: float, ramp_time: float | None = None) -> dict:
    """field_vertical_3km with 540 m of drill pipe (781 m in all: the axial wave settles in
    seconds), the bit off bottom, no rotation, hoisting at ``speed`` [m/s] (> 0 lowers)."""
    data, _ = read_scene_tables("field_vertical_3km")
    data["sections"][0]["length"] = 540.0
    data["bit"] = dict(OFF_BOTTOM)
    data["top_drive"] = {**data["top_drive"], "rotary_speed": 0.0, "hoisting_speed": speed}
    if ramp_time is not None:
        data["top_drive"]["ramp_time"] = ramp_time
    return data


def _buoyed_weight(data: dict) -> float:
    """Buoyed weight [N] from the scene's own numbers: sum m' L g (1 - rho_mud / rho_steel),
    m' the section's linear mass or rho_steel pi/4 (OD^2 - ID^2)."""
    total = 0.0
    for s in data["sections"]:
        lin = s.get("linear_mass") or RHO_STEEL * math.pi / 4.0 * (
            s["outer_diameter"] ** 2 - s["inner_diameter"] ** 2)
        total += lin * s["length"]
    return total * G * (1.0 - data["fluid"]["density"] / RHO_STEEL)


@pytest.fixture(scope="module")
def ramp_time() -> float:
    """One period [s] of the first axial mode: a ramp of constant acceleration that long leaves
    (nearly) no axial wave behind, so that a few seconds show the steady hook load."""
    m = DrillstringModel(scene_from_dict(_hoisting_tables(0.5)).plant, "axial_torsional")
    return 2.0 * math.pi / first_modes(m)["axial"].frequency_rad_s


def _automatic_candidates() -> list[tuple[str, str]]:
    """(model kind, method) of every method the automatic choice can pick: the exact
    exponential step (axial-torsional chain) and the table's automatic methods per kind."""
    out = [("axial_torsional", "expeuler")]
    for kind in ("axial_torsional", "full3d"):
        out += [(kind, name) for name, spec in METHODS.items()
                if kind in spec.automatic and spec.radius]
    return out


def _marked(cases: list[tuple[str, str]]) -> list:
    """The 3D runs (~5 s each) are ``slow``."""
    return [pytest.param(*c, marks=pytest.mark.slow) if c[0] == "full3d" else c for c in cases]


def test_the_candidates_are_what_the_automatic_choice_picks():
    sc = scene_from_dict(_hoisting_tables(0.5))
    assert DrillstringModel(sc.plant, "axial_torsional").exponential_exclusions == []
    picked = {(kind, DrillstringModel(sc.plant, kind).method_for_step(h))
              for kind in ("axial_torsional", "full3d") for h in (2.5e-4, 1e-3)}
    assert picked <= set(_automatic_candidates())
    assert ("axial_torsional", "expeuler") in picked and ("full3d", "kutta3") in picked


@pytest.mark.parametrize(("kind", "method"), _marked(_automatic_candidates()))
def test_hoisting_hook_load_is_the_buoyed_weight(kind, method, ramp_time):
    """Steady sliding in a vertical hole: the hook load is the buoyed weight (no friction), at
    1 ms and 0.25 ms, tripping in and out; mean over 2-4 s (the ramp ends at ~0.95 s)."""
    T = 4.0
    for speed in (0.5, -0.5):
        data = _hoisting_tables(speed, ramp_time)
        weight = _buoyed_weight(data)
        assert weight == pytest.approx(332.46e3, rel=1e-4)  # 40.0 t of steel in 10 ppg mud
        m = DrillstringModel(scene_from_dict(data).plant, kind)
        for H in (1e-3, 2.5e-4):  # (each run starts from the model's initial state)
            t, v, res = simulate(m, T, H, outputs=["hook_load"], method=method)
            assert res.ok and t[-1] == pytest.approx(T)
            steady = v["hook_load"][t >= 2.0].mean()
            assert abs(steady / weight - 1.0) < 1e-3, (speed, H, steady, weight)


def _ramped_chain(hoist: float, rotary: float, ramp_time: float) -> DrillstringModel:
    """The paper's 80 m chain in gravity, bit free, hoisting and turning from rest."""
    sc = load_scene("table1_axial_pulse", overrides={
        "loads": [], "gravity": 9.81, "bit": dict(OFF_BOTTOM),
        "top_drive": {"hoisting_speed": hoist, "rotary_speed": rotary,
                      "ramp_time": ramp_time}})
    return DrillstringModel(sc.plant, "axial_torsional")


def _reference(m: DrillstringModel, T: float, H: float) -> np.ndarray:
    sim = PlantSimulator(m, method="dopri5", rtol=1e-12, atol=1e-14)
    for k in range(int(round(T / H))):
        assert sim.do_step(k * H, H).ok
    return sim.y.copy()


@pytest.mark.parametrize(("hoist", "rotary", "ramp_time", "tol"),
                         [(0.5, 0.0, 0.0127, 1e-9), (-0.5, 2.0, 0.0127, 2e-8),
                          (0.5, 0.0, 0.0, 1e-9)])
def test_exponential_step_is_exact_through_the_drive_ramps(hoist, rotary, ramp_time, tol):
    """Exponential Euler at 1 ms (the ramp's end, 12.7 ms, inside a step: the step is split
    there) equals an adaptive Dormand-Prince run (rtol 1e-12) through the ramp and beyond, also
    with the hoisting speed jumping at t = 0 (no ramp), to 1e-9 of the state's travel; turning,
    to the first-order remainder of the twist's sine (joint twists ~1e-3 rad at 2 rad/s: the
    error grows as the speed squared, 8e-7 at 20 rad/s). The same steps with the drive's motion
    held over each step (what exponential Euler did before) are > 1e-3 off, so the check can
    fail."""
    m = _ramped_chain(hoist, rotary, ramp_time)
    assert m.method_for_step(1e-3) == "expeuler" and m.exponential_exclusions == []
    T, H = 0.05, 1e-3
    ref = _reference(m, T, H)
    sim = PlantSimulator(m)
    for k in range(int(round(T / H))):
        assert sim.do_step(k * H, H).ok
    assert sim.method == "expeuler"
    scale = np.abs(ref - m.initial_state()).max()
    assert np.abs(sim.y - ref).max() < tol * scale
    # the drive's motion held over each step: the same steps without the ramp vectors
    held = _ramped_chain(hoist, rotary, ramp_time)
    held._drive_ramp = lambda dt: np.zeros((0, held.n_state))
    sim = PlantSimulator(held)
    for k in range(int(round(T / H))):
        assert sim.do_step(k * H, H).ok
    assert np.abs(sim.y - ref).max() > 1e-3 * scale


def test_exclusions_name_what_the_exact_step_cannot_take():
    m = _ramped_chain(0.5, 20.0, 1.0)
    assert m.exponential_exclusions == [] and m.default_method == "expeuler"
    sc = load_scene("table1_axial_pulse", overrides={"bit": {"torque": 100.0}})
    why = DrillstringModel(sc.plant, "axial_torsional").exponential_exclusions
    assert len(why) == 1 and "bit.torque" in why[0]
    sc = load_scene("stick_slip")
    m = DrillstringModel(sc.plant, sc.model)
    assert any("cutting" in w for w in m.exponential_exclusions)
    assert m.default_method == "rk4"
    m = DrillstringModel(load_scene("paper_open_loop").plant, "full3d")
    assert any("full3d" in w for w in m.exponential_exclusions)


def test_compiled_paths_take_the_ramp_like_python():
    """The compiled recording loop and the compiled step (the FMU's) give the Python step's
    bits for a hoisting, turning chain (the ramp's end on a step boundary)."""
    T, H = 0.03, 1e-3
    idx = np.arange(len(_ramped_chain(0.5, 2.0, 0.01).output_names))
    a = PlantSimulator(_ramped_chain(0.5, 2.0, 0.01))
    rec, res = a.run_record(H, int(round(T / H)), idx)
    assert res.ok and a.method == "expeuler"
    b = PlantSimulator(_ramped_chain(0.5, 2.0, 0.01))
    c = PlantSimulator(_ramped_chain(0.5, 2.0, 0.01))
    buf = np.zeros(idx.size)
    step = c.compiled_step(c.u.copy(), np.arange(c.u.size), buf, idx)
    rows_b, rows_c = [b.outputs().copy()], [c.outputs().copy()]
    for k in range(int(round(T / H))):
        assert b.do_step(k * H, H).ok and step.step(k * H, H).ok
        rows_b.append(b.outputs().copy())
        rows_c.append(buf.copy())
    np.testing.assert_array_equal(rec, np.array(rows_b))
    np.testing.assert_array_equal(np.array(rows_c), np.array(rows_b))
    np.testing.assert_array_equal(c.y, b.y)
