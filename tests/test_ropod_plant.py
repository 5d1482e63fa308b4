"""The simulated ropod: drive and sensor conventions, physics checks, and closed loop with the controller."""

from __future__ import annotations

import math

import numpy as np
import pytest

from hapticop.devices.ropod.pdo import (
    Com1,
    Stat1,
    new_rx_image,
    new_tx_image,
    rxpdo_view,
    txpdo_view,
)
from hapticop.devices.ropod.plant import PlantParams, RopodPlant
from hapticop.devices.ropod.velocity_controller import PlatformVelocityController
from hapticop.testing import allocation_stats

from .test_ropod_data import load

DT = 0.001
TORQUE = int(Com1.ENABLE1 | Com1.ENABLE2 | Com1.MODE_TORQUE)
CANDIDATES = load("sim_candidates")
STEP = CANDIDATES["step_0p5mps_time_domain"]


def _commands(command1: int, setpoint1: float, setpoint2: float) -> np.ndarray:
    rx = new_rx_image(4)
    rec = rxpdo_view(rx)
    rec["command1"], rec["setpoint1"], rec["setpoint2"] = command1, setpoint1, setpoint2
    rec["limit1_p"], rec["limit1_n"], rec["limit2_p"], rec["limit2_n"] = 10.0, -10.0, 10.0, -10.0
    return rx


def test_plant_parameters_are_the_candidate_models():
    p, common = PlantParams(), CANDIDATES["_about"]["plant_common"]
    assert (p.mass_kg, p.yaw_inertia_kgm2, p.linear_damping_ns_per_m, p.yaw_damping_nms) == (
        common["m_kg"], common["Iz_kgm2"], common["c_lin_Ns_per_m"], common["c_rot_Nms"])
    assert (p.geometry.wheel_radius_m, p.geometry.caster_offset_m, p.geometry.wheel_distance_m) == (
        common["r_w"], common["s_w"], common["d_w"])


def test_hardware_signs_currents_and_sensor_fields():
    """+1 A on motor 1 and -1 A on motor 2 push every wheel forward: 8 Kt / r / m of acceleration."""
    plant = RopodPlant(PlantParams(linear_damping_ns_per_m=0.0))
    rx, tx = _commands(TORQUE, 1.0, -1.0), new_tx_image(4)
    for _ in range(100):
        plant.step(rx, DT, tx)
    accel = 8 * 0.28 / 0.0525 / 36.5
    np.testing.assert_allclose(plant.twist, [accel * 0.1, 0, 0], atol=1e-12)
    np.testing.assert_allclose(plant.wheel_torques, 0.28)
    assert plant.pose[0] == pytest.approx(0.5 * accel * 0.1**2, rel=1e-9)
    rec = txpdo_view(tx)  # sampled at the start of the last step: 99 ms of motion
    speed = accel * 0.099 / 0.0525
    np.testing.assert_allclose(rec["velocity_1"], speed, rtol=1e-6)
    np.testing.assert_allclose(rec["velocity_2"], -speed, rtol=1e-6)  # hardware wheel 2 turns the other way
    np.testing.assert_allclose(rec["encoder_1"], -rec["encoder_2"])
    assert rec["encoder_1"][0] > 0
    np.testing.assert_allclose(rec["current_1_q"], 1.0)
    np.testing.assert_allclose(rec["current_2_q"], -1.0)
    assert rec["status1"].tolist() == [int(Stat1.ENCODERS_OK | Stat1.ENABLED1 | Stat1.ENABLED2)] * 4
    assert rec["sensor_ts"][0] == 99_000_000 and rec["setpoint_ts"][0] == 99_000_000
    assert rec["voltage_bus"][0] == pytest.approx(24.0)


def test_pivot_encoders_carry_the_offsets_and_wrap():
    offsets = (4.691878, 3.224157, 0.028178, 5.856820)
    plant = RopodPlant(PlantParams(initial_pivot_angles_rad=(0.0, 0.5, -0.25, 3.0)))
    tx = new_tx_image(4)
    plant.write_sensors(tx)
    enc = txpdo_view(tx)["encoder_pivot"].astype(float)
    assert np.all(np.abs(enc) <= math.pi)
    np.testing.assert_allclose(np.angle(np.exp(1j * (enc - offsets))), [0.0, 0.5, -0.25, 3.0], atol=1e-6)


def test_current_limit_disable_emergency_and_unsupported_modes():
    plant, tx = RopodPlant(), new_tx_image(4)
    plant.step(_commands(TORQUE, 25.0, -25.0), DT, tx)
    np.testing.assert_allclose(plant.currents_hw, [10.0, -10.0] * 4)  # the drive's own limit
    for command in (int(Com1.ENABLE1 | Com1.ENABLE2 | Com1.EMERGENCY1 | Com1.EMERGENCY2), 0,
                    int(Com1.ENABLE1 | Com1.ENABLE2 | Com1.MODE_DTORQUE)):
        plant.step(_commands(command, 3.0, 3.0), DT, tx)
        assert not plant.currents_hw.any()
    plant.step(_commands(int(Com1.ENABLE1 | Com1.EMERGENCY2 | Com1.ENABLE2), 3.0, 3.0), DT, tx)
    assert plant.currents_hw.tolist() == [3.0, 0.0] * 4
    plant.step(_commands(int(Com1.ENABLE1), 3.0, 3.0), DT, tx)
    assert txpdo_view(tx)["status1"].tolist() == [int(Stat1.ENCODERS_OK | Stat1.ENABLED1)] * 4


def test_velocity_mode_spins_the_units_about_their_pivots():
    """The ropod's start-up phase: both motors at +2 rad/s (hardware signs) turn each unit about its pivot.

    Without tyre slip a unit can only yaw if its pivot moves sideways by s per radian, so the platform
    circles at s * Omega (2.6 cm/s) and the P speed loop settles near, not at, the setpoints."""
    plant, tx = RopodPlant(), new_tx_image(4)
    rx = _commands(int(Com1.ENABLE1 | Com1.ENABLE2 | Com1.MODE_VELOCITY), 2.0, 2.0)
    for _ in range(1000):
        plant.step(rx, DT, tx)
    rec = txpdo_view(tx)
    np.testing.assert_allclose(rec["velocity_1"], 2.0, atol=0.15)
    np.testing.assert_allclose(rec["velocity_2"], 2.0, atol=0.15)
    unit_yaw = (-rec["velocity_2"].astype(float) - rec["velocity_1"]) * 0.0525 / 0.08
    np.testing.assert_allclose(plant.pivot_rates + plant.twist[2], unit_yaw, rtol=1e-3)
    assert unit_yaw.max() < -2.4
    assert np.hypot(*plant.twist[:2]) == pytest.approx(0.01 * -unit_yaw[0], rel=0.05)


def test_free_rolling_conserves_energy():
    """No losses, no torque: platform + caster yaw energy stays constant (checks the Level 1 equations)."""
    plant = RopodPlant(PlantParams(linear_damping_ns_per_m=0.0, yaw_damping_nms=0.0, substeps=4,
                                   initial_twist=(0.4, 0.1, 0.3), initial_pivot_angles_rad=(0.5, 2.0, -1.0, 3.0)))

    def energy() -> float:
        kin, v = plant.kinematics, plant.twist
        kin.update_jacobian(plant.pivot_angles)
        unit_yaw = kin.Q @ v / 0.01
        return 0.5 * (36.5 * (v[0] ** 2 + v[1] ** 2) + 2.6 * v[2] ** 2) + 0.5 * 0.011 * unit_yaw @ unit_yaw

    e0, rx, tx = energy(), _commands(0, 0.0, 0.0), new_tx_image(4)
    for _ in range(1000):
        plant.step(rx, DT, tx)
    assert abs(plant.pivot_angles - (0.5, 2.0, -1.0, 3.0)).max() > 0.5  # the casters did swing
    assert energy() == pytest.approx(e0, rel=1e-7)


def test_deterministic_with_noise_from_the_generator():
    params = PlantParams(wheel_velocity_noise_rad_s=0.05, pivot_noise_rad=0.001)
    images = []
    for seed in (1, 1, 2):
        plant, tx, rx = RopodPlant(params, np.random.default_rng(seed)), new_tx_image(4), _commands(TORQUE, 1.0, -0.5)
        for _ in range(50):
            plant.step(rx, DT, tx)
        images.append(tx.copy())
    assert np.array_equal(images[0], images[1]) and not np.array_equal(images[0], images[2])


def _closed_loop(plant: RopodPlant, schedule) -> dict[str, np.ndarray]:
    """Controller and plant at 1 kHz through the PDO images; schedule(k) -> (setpoint, stop)."""
    ctrl, tx, rx, v_meas = PlatformVelocityController(), new_tx_image(4), new_rx_image(4), np.zeros(3)
    plant.write_sensors(tx)
    log = {k: [] for k in ("twist", "pose", "delta", "tau_applied", "wrench", "v_meas")}
    k = 0
    while (command := schedule(k)) is not None:
        ctrl.step(command[0], tx, rx, v_meas, stop=command[1])
        plant.step(rx, DT, tx)
        for key, value in (("twist", plant.twist), ("pose", plant.pose), ("delta", plant.pivot_angles),
                           ("tau_applied", plant.wheel_torques), ("wrench", ctrl.wrench), ("v_meas", v_meas)):
            log[key].append(value.copy())
        k += 1
    return {key: np.array(value) for key, value in log.items()}


def _t90_and_overshoot(v: np.ndarray, target: float) -> tuple[float, float]:
    return (int(np.argmax(v >= 0.9 * target)) + 1) * DT, (v.max() / target - 1.0) * 100.0


def test_forward_turn_and_stop_in_closed_loop():
    """0.3 m/s forward (3 s), then turning at 0.5 rad/s (2 s), then stop (2 s)."""
    forward, turn = np.array([0.3, 0.0, 0.0]), np.array([0.3, 0.0, 0.5])

    def schedule(k):
        return None if k >= 7000 else (forward, False) if k < 3000 else (turn, False) if k < 5000 else (forward, True)

    log = _closed_loop(RopodPlant(), schedule)
    vx = log["twist"][:3000, 0]
    # The linear regime scales the candidates' 0.5 m/s step (same model, controller and delay) to 0.3 m/s.
    ref = STEP["slip_x0.5_aligned"]
    assert ref == STEP["rigid_x0.5_aligned"]  # aligned casters never yaw: Level 0 = 1 = 2
    t90, overshoot = _t90_and_overshoot(vx, 0.3)
    assert t90 == pytest.approx(ref["t90_s"], abs=0.002)  # 1 ms late: we time the state after the step
    assert overshoot == pytest.approx(ref["overshoot_pct"], abs=0.05)
    assert vx[999] / 0.3 == pytest.approx(ref["vx_at_1s"] / 0.5, abs=5e-4)
    assert vx[2999] / 0.3 == pytest.approx(ref["vx_at_3s"] / 0.5, abs=5e-4)
    assert np.abs(log["tau_applied"][:3000]).max() / 0.6 == pytest.approx(ref["max_abs_tau"], abs=2e-3)
    assert log["wrench"][:3000, 0].max() / 0.6 == pytest.approx(ref["wrench_x_peak"], abs=0.02)
    assert np.abs(log["twist"][:3000, 1:]).max() < 1e-6 and np.abs(log["delta"][2999]).max() < 1e-6
    np.testing.assert_allclose(log["v_meas"][2999], log["twist"][2997], atol=1e-6)  # sampled 1 ms before the cycle
    # Turning: the casters swing to their new trailing angles and the twist is tracked.
    np.testing.assert_allclose(log["twist"][4999], [0.3, 0.0, 0.5], atol=0.01)
    assert log["pose"][4999, 2] - log["pose"][2999, 2] == pytest.approx(1.0, abs=0.05)
    assert np.abs(log["delta"][4999]).min() > 0.1
    # Stop: the setpoint is held at zero and the platform comes to rest where it is.
    assert np.abs(log["twist"][5999]).max() < 0.02
    assert np.abs(log["twist"][6999]).max() < 0.01
    assert np.abs(log["pose"][6999, :2] - log["pose"][6499, :2]).max() < 0.005


def test_casters_starting_sideways_realign_and_the_step_settles():
    """Level 1 (caster yaw inertia, no slip) against the candidates' Level 2 (stiff tyres) from the same start."""
    ref = STEP["slip_x0.5_casters_sideways"]
    setpoint = np.array([0.5, 0.0, 0.0])
    log = _closed_loop(RopodPlant(PlantParams(initial_pivot_angles_rad=(math.pi / 2,) * 4)),
                       lambda k: None if k >= 3000 else (setpoint, False))
    t90, overshoot = _t90_and_overshoot(log["twist"][:, 0], 0.5)
    assert t90 == pytest.approx(ref["t90_s"], abs=0.003)
    assert overshoot == pytest.approx(ref["overshoot_pct"], abs=0.3)
    assert log["twist"][999, 0] == pytest.approx(ref["vx_at_1s"], abs=2e-3)
    assert log["twist"][2999, 0] == pytest.approx(ref["vx_at_3s"], abs=2e-3)
    assert np.abs(log["twist"][:, 1]).max() == pytest.approx(ref["vy_maxabs"], abs=5e-3)
    assert np.abs(log["tau_applied"]).max() == pytest.approx(ref["max_abs_tau"], abs=1e-6)  # the 10 A clip
    np.testing.assert_allclose(log["delta"][-1], ref["delta_final"], atol=5e-3)


def test_step_allocates_nothing():
    plant, tx, rx = RopodPlant(PlantParams(initial_twist=(0.3, 0.1, 0.2))), new_tx_image(4), _commands(TORQUE, 1, -1)
    retained, peak = allocation_stats(lambda: plant.step(rx, DT, tx), 300)
    assert retained < 256 and peak < 2048


def _level1_derivative(y: np.ndarray, tau: np.ndarray, p: PlantParams) -> np.ndarray:
    """The Level 1 equations (docs/devices/ropod.md §8) written out with numpy's linear algebra."""
    g = p.geometry
    theta, v, delta = y[2], y[3:6], y[6:10]
    px, py = np.array(g.pivots_m).T
    c, s = np.cos(delta), np.sin(delta)
    u = np.stack([c, s, px * s - py * c], axis=1)
    q = np.stack([-s, c, px * c + py * s], axis=1)
    jac = np.stack([u - g.k * q, u + g.k * q], axis=1).reshape(8, 3) / g.wheel_radius_m
    pivot_rates = q @ v / g.caster_offset_m - v[2]
    ic = p.unit_yaw_inertia_kgm2 / g.caster_offset_m**2
    m, vx, vy, wz = p.mass_kg, *v
    rhs = (jac.T @ tau + [m * wz * vy - p.linear_damping_ns_per_m * vx, -m * wz * vx - p.linear_damping_ns_per_m * vy,
                          -p.yaw_damping_nms * wz + p.pivot_damping_nms * pivot_rates.sum()]
           - p.pivot_damping_nms / g.caster_offset_m * q.T @ pivot_rates + ic * q.T @ ((u @ v) * pivot_rates))
    mass = np.diag([m, m, p.yaw_inertia_kgm2]) + ic * q.T @ q
    rotation = np.array([[np.cos(theta), -np.sin(theta)], [np.sin(theta), np.cos(theta)]])
    return np.concatenate([rotation @ v[:2], [wz], np.linalg.solve(mass, rhs), pivot_rates, jac @ v])


def test_a_step_is_one_runge_kutta_step_of_the_level1_equations():
    """The float evaluation against the equations in matrix form, on random seeded states and torques."""
    rng = np.random.default_rng(5)
    for trial in range(20):
        params = PlantParams(pivot_damping_nms=0.02 * (trial % 2), unit_yaw_inertia_kgm2=0.011 * (trial % 3 != 0),
                             initial_pose=tuple(rng.normal(size=3)), initial_twist=tuple(rng.normal(0, 0.5, 3)),
                             initial_pivot_angles_rad=tuple(rng.uniform(-4, 4, 4)))
        plant, tx, rx = RopodPlant(params), new_tx_image(4), _commands(TORQUE, 0.0, 0.0)
        rec = rxpdo_view(rx)
        rec["setpoint1"], rec["setpoint2"] = rng.normal(0, 4, 4), rng.normal(0, 4, 4)
        y, h = plant.state.copy(), 0.002
        plant.step(rx, h, tx)
        tau = plant.wheel_torques
        currents = np.clip(np.stack([rec["setpoint1"], -rec["setpoint2"]], axis=1).ravel().astype(float), -10.0, 10.0)
        np.testing.assert_allclose(tau, currents * 0.28, rtol=1e-15)
        k1 = _level1_derivative(y, tau, params)
        k2 = _level1_derivative(y + 0.5 * h * k1, tau, params)
        k3 = _level1_derivative(y + 0.5 * h * k2, tau, params)
        k4 = _level1_derivative(y + h * k3, tau, params)
        np.testing.assert_allclose(plant.state, y + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4), rtol=1e-12, atol=1e-14)


def test_standstill_hold_keeps_a_stopped_robot_from_drifting_back():
    """Braking along a ramp winds the platform integrators up against the motion; the plain PI then drives
    the stopped robot backwards (the hallway run's drift after its stop). With the standstill hold the
    integrators stay at zero once the setpoint is zero and the robot nearly still."""
    from dataclasses import replace

    from hapticop.devices.ropod.velocity_controller import PlatformControllerParams

    def run(hold_below):
        ctrl = PlatformVelocityController(replace(PlatformControllerParams(), hold_below=hold_below))
        plant, tx, rx, v_meas = RopodPlant(), new_tx_image(4), new_rx_image(4), np.zeros(3)
        plant.write_sensors(tx)
        vx = []
        for k in range(6000):  # 0.5 m/s for 2 s, braked along a 1 s ramp, then a zero setpoint for 3 s
            speed = 0.5 if k < 2000 else max(0.0, 0.5 * (3000 - k) / 1000)
            ctrl.step(np.array([speed, 0.0, 0.0]), tx, rx, v_meas)
            plant.step(rx, DT, tx)
            vx.append(float(plant.twist[0]))
        return np.array(vx), float(plant.pose[0])

    plain, _ = run(None)
    held, _ = run(0.02)
    assert plain[3000:].min() < -0.01  # the plain PI reverses the robot after the stop
    assert held[3000:].min() > -0.002 and abs(held[-1]) < 1e-3  # held: it stays where it stopped
    np.testing.assert_allclose(held[:2900], plain[:2900])  # and driving is untouched
