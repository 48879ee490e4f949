"""Top drive as an input (``top_drive.mode`` "speed" / "torque") against independent references.

References: the prescribed-ramp boundary condition (the paper's), the static twist of a uniform
shaft under a torque (T L / G J), the torque balance of a driven rotor in steady state, and the
convergence of a sampled speed command to the continuous ramp as the communication step falls.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from drillcosim.plant.model import DrillstringModel
from drillcosim.plant.params import PipeParams, TopDriveParams
from drillcosim.plant.scene import SceneError, load_scene, scene_from_dict
from drillcosim.plant.simulator import PlantSimulator, simulate

BIT_TORQUE = 500.0  # N m, constant resisting torque at the bit (smoothed sign of the speed)
OMEGA = 20.0  # rad/s


def _chain(**top_drive) -> DrillstringModel:
    """Axial-torsional chain, free bit with a constant resisting torque, no gravity."""
    sc = scene_from_dict({
        "gravity": 0.0,
        "top_drive": {"rotary_speed": OMEGA, **top_drive},
        "bit": {"axial_stiffness": 0.0, "displacement_amplitude": 0.0, "torque": BIT_TORQUE},
        "unbalance": {"enabled": False},
    })
    assert sc.model == "axial_torsional"
    return DrillstringModel(sc.plant, sc.model)


def _static_twist() -> float:
    """Twist [rad] of the bit body against the drive under the bit torque: the half segment at
    the top (rigid drive in series with it) and n - 1 joints, each dx / (G J)."""
    pipe = PipeParams()
    gj = pipe.shear_modulus * pipe.polar_moment
    return -BIT_TORQUE * (pipe.length - 0.5 * pipe.segment_length) / gj


def _steady(sim: PlantSimulator, u: np.ndarray, stop: float, h: float = 1e-3) -> dict:
    sim.set_inputs(u)
    for k in range(round(stop / h)):
        assert sim.do_step(k * h, h).ok
    return dict(zip(sim.model.output_names, sim.outputs().tolist()))


def test_inputs_and_auxiliary_states_are_named_with_units():
    m = _chain(mode="speed")
    assert m.input_names[-1] == "top_drive_speed_command"
    assert m.input_units["top_drive_speed_command"] == "rad/s"
    assert m.aux_names == ["top_drive.angle"] and m.n_state == 4 * m.n + 1
    mt = _chain(mode="torque", inertia=5.0)
    assert mt.input_names[-1] == "top_drive_torque" and mt.input_units["top_drive_torque"] == "N m"
    assert mt.aux_names == ["top_drive.angle", "top_drive.speed"]
    assert mt.aux_units == {"top_drive.angle": "rad", "top_drive.speed": "rad/s"}
    mp = _chain()
    assert mp.n_state == mp.n_body_state and "top_drive_speed_command" not in mp.input_names
    assert PlantSimulator(mt).input_names == mt.input_names


def test_constant_speed_command_reaches_the_prescribed_ramps_steady_state():
    """After the transients (3.4 % damping at 63 rad/s: e^-11 in 5 s) both boundary conditions
    give the static twist of the shaft under the bit torque and transmit that torque."""
    t, prescribed, res = simulate(_chain(), 6.0, 1e-3)
    assert res.ok
    sim = PlantSimulator(_chain(mode="speed"))
    u = np.zeros(sim.model.n_inputs)
    u[-1] = OMEGA
    speed = _steady(sim, u, 6.0)
    twist = _static_twist()
    for out in ({k: v[-1] for k, v in prescribed.items()}, speed):
        assert out["top_torque"] == pytest.approx(BIT_TORQUE, rel=1e-4)
        assert out["bit_rotary_speed"] == pytest.approx(OMEGA, rel=1e-5)
        assert out["bit_twist"] == pytest.approx(twist, rel=1e-4)
    assert speed["top_rotary_speed"] == OMEGA  # the ideal speed source outputs its command


def test_pi_speed_loop_on_the_torque_input_reaches_the_command():
    """A PI loop closed around PlantSimulator (sampled at 1 ms, held) spins the drive rotor up
    to the command; in steady state the motor torque balances the transmitted torque, which
    balances the bit torque (no acceleration anywhere)."""
    m = _chain(mode="torque", inertia=10.0)
    sim = PlantSimulator(m)
    i_speed = m.output_names.index("top_rotary_speed")
    kp, ki, h = 200.0, 2000.0, 1e-3  # N m s/rad, N m/rad
    integral = 0.0
    u = np.zeros(m.n_inputs)
    for k in range(8000):
        err = OMEGA - sim.outputs()[i_speed]
        integral += err * h
        u[-1] = kp * err + ki * integral
        sim.set_inputs(u)
        assert sim.do_step(k * h, h).ok
    out = dict(zip(m.output_names, sim.outputs().tolist()))
    assert out["top_rotary_speed"] == pytest.approx(OMEGA, abs=1e-6)
    assert out["bit_rotary_speed"] == pytest.approx(OMEGA, abs=1e-5)
    assert u[-1] == pytest.approx(BIT_TORQUE, rel=1e-5)
    assert out["top_torque"] == pytest.approx(BIT_TORQUE, rel=1e-5)
    assert out["bit_twist"] == pytest.approx(_static_twist(), rel=1e-4)


def test_torque_mode_without_control_conserves_angular_momentum_balance():
    """Motor torque T on a free rotor + string with a frictionless bit: the total angular
    momentum grows at exactly T (checked through the speeds after a short run)."""
    sc = scene_from_dict({"gravity": 0.0, "top_drive": {"mode": "torque", "inertia": 4.0},
                          "bit": {"axial_stiffness": 0.0, "displacement_amplitude": 0.0},
                          "unbalance": {"enabled": False}})
    m = DrillstringModel(sc.plant, sc.model)
    sim = PlantSimulator(m)
    T, stop = 300.0, 0.5
    u = np.zeros(m.n_inputs)
    u[-1] = T
    sim.set_inputs(u)
    for k in range(round(stop / 1e-3)):
        assert sim.do_step(k * 1e-3, 1e-3).ok
    n = m.n
    momentum = m.derived.j_polar * sim.y[3 * n:4 * n].sum() + 4.0 * sim.y[m.n_body_state + 1]
    assert momentum == pytest.approx(T * stop, rel=1e-9)


def test_sampled_speed_command_converges_to_the_prescribed_ramp_in_3d():
    """paper_open_loop (full 3D, contact, unbalance) over 1.5 s: the ramp fed as a speed command
    held over each communication step H (its mean over the step) reproduces the prescribed
    run; the difference falls with H (top torque ~ O(H): the held speed jumps by ~ramp rate * H)."""
    names = ["strain1_C", "body26_radial_deflection", "top_torque", "bit_rotary_speed"]

    def run(mode: str, h: float) -> np.ndarray:
        sc = load_scene("paper_open_loop", overrides={"top_drive": {"mode": mode}})
        m = DrillstringModel(sc.plant, sc.model)
        sim = PlantSimulator(m)
        idx = [m.output_names.index(k) for k in names]
        u = np.zeros(m.n_inputs)
        rows = []
        every = round(1e-2 / h)
        for k in range(round(1.5 / h)):
            if mode == "speed":
                u[-1] = OMEGA * min((k + 0.5) * h, 1.0)  # the ramp's mean speed over the step
                sim.set_inputs(u)
            assert sim.do_step(k * h, h).ok
            if (k + 1) % every == 0:
                rows.append(sim.outputs()[idx].copy())
        return np.array(rows)

    ref = run("prescribed", 1e-3)
    scale = np.abs(ref).max(axis=0)
    err = [np.abs(run("speed", h) - ref).max(axis=0) / scale for h in (1e-3, 2.5e-4)]
    assert np.all(err[0][[0, 1, 3]] < 2e-5), err[0]
    assert err[1][2] < err[0][2] / 2.5, err  # top torque: O(H)
    assert err[0][2] < 0.05


def test_prescribed_mode_keeps_the_papers_layout():
    """The default (prescribed) top drive adds no state and no input: the paper scenes and the
    FMU interface are unchanged."""
    sc = load_scene("paper_closed_loop")
    m = DrillstringModel(sc.plant, sc.model)
    assert m.n_state == 12 * m.n and m.n_inputs == 2 * m.n_sites
    assert m.input_names == [f"actuator{s}_force_{a}" for s in (1, 2) for a in "CE"]


@pytest.mark.parametrize("table, message", [
    ({"mode": "servo"}, "top_drive.mode = 'servo' is not allowed: one of 'prescribed', 'speed', "
                        "'torque'"),
    ({"mode": "torque"}, "top_drive.inertia = 0.0 is out of range for mode = 'torque'"),
    ({"inertia": -1.0}, "top_drive.inertia = -1.0 is out of range: allowed [0, 1e+06] kg m^2"),
    ({"mode": "speed", "torsional_stiffness": 0.0}, "top_drive.torsional_stiffness = 0 is not "
                                                    "allowed with mode = 'speed'"),
])
def test_bad_top_drive_parameters_are_refused_in_one_line(table, message):
    with pytest.raises(SceneError) as exc:
        scene_from_dict({"top_drive": table}, source="x.toml")
    text = str(exc.value)
    assert "\n" not in text and text.startswith("x.toml") and message in text
    with pytest.raises(ValueError):
        TopDriveParams(**table)


def test_wrong_number_of_inputs_is_refused_naming_them():
    sim = PlantSimulator(_chain(mode="speed"))
    with pytest.raises(ValueError, match=r"4 values given, the plant takes 5 \(.*"
                                         r"top_drive_speed_command\)"):
        sim.set_inputs(np.zeros(4))


def test_verlet_refuses_first_order_auxiliary_states():
    m = _chain(mode="speed")
    with pytest.raises(ValueError, match="verlet"):
        m.advance(0.0, m.initial_state(), 1, 1e-4, method="verlet")
    assert math.isfinite(m.stable_step())
