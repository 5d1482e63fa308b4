"""The full 1 kHz controller cycle (docs/devices/ropod.md §7) on model quantities and on PDO images."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from hapticop.devices.ropod.controller_params import LinearControllerParams
from hapticop.devices.ropod.pdo import (
    Com1,
    Stat1,
    new_rx_image,
    new_tx_image,
    rxpdo_view,
    txpdo_view,
)
from hapticop.devices.ropod.velocity_controller import (
    THESIS_PIVOT_OFFSETS_RAD,
    PlatformControllerParams,
    PlatformVelocityController,
)
from hapticop.testing import BlockHarness, allocation_stats

from .test_ropod_data import load

REF = load("reference")
OPEN_LOOP = REF["full_controller_open_loop"]
HEALTHY = int(Stat1.ENCODERS_OK | Stat1.ENABLED1 | Stat1.ENABLED2)
RUNNING = int(Com1.ENABLE1 | Com1.ENABLE2 | Com1.MODE_TORQUE)
ATTRS = {"v_meas": "v_meas", "wrench": "wrench", "tau_dist": "tau_dist", "tau_wheel": "tau_wheel",
         "tau_total": "tau", "current_model_A": "current", "current_hw_setpoint_A": "current_hw"}


def _sensors(delta, phidot, offsets=THESIS_PIVOT_OFFSETS_RAD, status=HEALTHY) -> np.ndarray:
    """A sensor image as the drives would report model pivot angles and wheel speeds."""
    image = new_tx_image(4)
    rec = txpdo_view(image)
    rec["status1"] = status
    rec["encoder_pivot"] = np.asarray(delta) + np.asarray(offsets)
    rec["velocity_1"] = np.asarray(phidot)[0::2]
    rec["velocity_2"] = -np.asarray(phidot)[1::2]
    return image


def test_reference_params_are_the_defaults():
    p, ref = PlatformControllerParams(), OPEN_LOOP["params"]
    assert p.platform_xy == LinearControllerParams.from_mapping(ref["xy"])
    assert p.platform_theta == LinearControllerParams.from_mapping(ref["theta"])
    assert p.wheel == LinearControllerParams.from_mapping(ref["wheel"])
    assert (p.torque_constant_nm_per_a, p.tau_max, p.distribution) == (
        ref["Kt_Nm_per_A"], pytest.approx(ref["tau_max_Nm"]), ref["distribution"])


def test_open_loop_cycles_match_the_reference():
    """Five cycles from zero state, every intermediate value, to 1e-9 (drive clip left to the drive)."""
    ctrl = PlatformVelocityController(PlatformControllerParams(clip_current=False))
    inp = OPEN_LOOP["input"]
    for step in OPEN_LOOP["steps"]:
        ctrl.update(np.array(inp["v_sp"]), np.array(inp["delta"]), np.array(inp["phidot_meas"]),
                    np.array(inp["enable"], float))
        for key, attr in ATTRS.items():
            np.testing.assert_allclose(getattr(ctrl, attr), step[key], rtol=0, atol=1e-9, err_msg=key)


def test_currents_are_clipped_to_the_drive_limit_by_default():
    ctrl = PlatformVelocityController()
    inp = OPEN_LOOP["input"]
    for step in OPEN_LOOP["steps"]:
        ctrl.update(np.array(inp["v_sp"]), np.array(inp["delta"]), np.array(inp["phidot_meas"]),
                    np.array(inp["enable"], float))
        limit = step["hw_current_limit_A"]
        np.testing.assert_allclose(ctrl.current_hw, np.clip(step["current_hw_setpoint_A"], -limit, limit), atol=1e-9)
    assert np.abs(OPEN_LOOP["steps"][-1]["current_hw_setpoint_A"]).max() > 10.0  # the clip was exercised


def test_open_loop_cycles_through_the_process_data_images():
    inp = OPEN_LOOP["input"]
    delta = np.array(inp["delta"])
    # Offsets chosen so that float32(encoder) - offset == delta exactly: isolates the float32 setpoints.
    enc32 = delta.astype(np.float32).astype(np.float64)
    ctrl = PlatformVelocityController(PlatformControllerParams(pivot_offsets_rad=tuple(enc32 - delta)))
    tx = _sensors(enc32, inp["phidot_meas"], offsets=np.zeros(4))
    rx, v_meas = new_rx_image(4), np.full(3, np.nan)
    cmd = rxpdo_view(rx)
    for step in OPEN_LOOP["steps"]:
        ctrl.step(np.array(inp["v_sp"]), tx, rx, v_meas)
        np.testing.assert_array_equal(ctrl.delta, delta)
        expected = np.clip(step["current_hw_setpoint_A"], -10, 10)
        np.testing.assert_allclose(cmd["setpoint1"], expected[0::2], rtol=1e-6, atol=1e-6)
        np.testing.assert_allclose(cmd["setpoint2"], expected[1::2], rtol=1e-6, atol=1e-6)
        np.testing.assert_array_equal(v_meas, step["v_meas"])
    assert cmd["command1"].tolist() == [RUNNING] * 4 and cmd["command2"].tolist() == [0] * 4
    assert cmd["limit1_p"].tolist() == [10.0] * 4 and cmd["limit2_n"].tolist() == [-10.0] * 4


def test_sensor_conversion_example():
    ex = REF["sensor_conversion_example"]
    assert tuple(ex["pivot_offsets_thesis_rad"]) == THESIS_PIVOT_OFFSETS_RAD
    ctrl = PlatformVelocityController()
    phidot = np.arange(1.0, 9.0)
    ctrl.step(np.zeros(3), _sensors(np.array(ex["encoder_pivot_rad"]) - THESIS_PIVOT_OFFSETS_RAD, phidot),
              new_rx_image(4), np.zeros(3))
    np.testing.assert_allclose(ctrl.delta, ex["delta_rad"], atol=5e-7)  # float32 encoder
    np.testing.assert_array_equal(ctrl.phidot, phidot)  # phidot_model = [velocity_1, -velocity_2]


def test_rest_gives_zero_currents():
    ctrl, rx = PlatformVelocityController(), new_rx_image(4)
    tx = _sensors([0.3, -1.0, 2.0, 0.5], np.zeros(8))
    for _ in range(20):
        ctrl.step(np.zeros(3), tx, rx, np.zeros(3))
    cmd = rxpdo_view(rx)
    assert not cmd["setpoint1"].any() and not cmd["setpoint2"].any()
    assert cmd["command1"].tolist() == [RUNNING] * 4


def test_forward_setpoint_gives_symmetric_forward_currents():
    ctrl, rx = PlatformVelocityController(), new_rx_image(4)
    tx = _sensors(np.zeros(4), np.zeros(8))
    for _ in range(10):
        ctrl.step(np.array([0.3, 0.0, 0.0]), tx, rx, np.zeros(3))
    assert ctrl.wrench[0] > 0 and ctrl.wrench[1:] == pytest.approx([0, 0], abs=1e-5)
    # Equal up to the float32 pivot encoders (thesis offsets make delta = 0 only to ~1e-7 rad).
    assert ctrl.current.min() > 0 and np.ptp(ctrl.current) < 1e-5 * ctrl.current.max()
    cmd = rxpdo_view(rx)
    np.testing.assert_allclose(cmd["setpoint1"], ctrl.current[0::2], rtol=1e-6)
    np.testing.assert_allclose(cmd["setpoint2"], -ctrl.current[1::2], rtol=1e-6)  # setpoint_2 = -i_w2


def test_stop_holds_a_zero_setpoint_and_brakes_with_the_drives_enabled():
    ctrl, rx = PlatformVelocityController(), new_rx_image(4)
    moving = _sensors(np.zeros(4), np.full(8, 0.3 / 0.0525))  # 0.3 m/s forward, casters trailing
    v_meas = np.zeros(3)
    for _ in range(5):
        ctrl.step(np.array([0.3, 0.0, 0.0]), moving, rx, v_meas, stop=True)
    np.testing.assert_allclose(v_meas, [0.3, 0, 0], atol=1e-6)
    assert not ctrl.v_sp.any()
    assert ctrl.wrench[0] < 0 and ctrl.current.max() < 0
    assert rxpdo_view(rx)["command1"].tolist() == [RUNNING] * 4


def test_unhealthy_units_are_left_out_and_two_are_needed():
    ctrl, rx = PlatformVelocityController(), new_rx_image(4)
    status = np.full(4, HEALTHY)
    status[1] &= ~int(Stat1.ENC_PIVOT_OK)
    status[3] |= int(Stat1.OVERTEMP_1)
    tx = _sensors(np.zeros(4), np.zeros(8), status=status)
    cmd = rxpdo_view(rx)
    ctrl.step(np.array([0.2, 0.0, 0.0]), tx, rx, np.zeros(3))
    assert ctrl.operational and ctrl.unit_enable.tolist() == [1, 0, 1, 0]
    assert cmd["command1"].tolist() == [RUNNING, 0, RUNNING, 0]
    assert cmd["setpoint1"][[1, 3]].tolist() == [0, 0] and cmd["setpoint1"][[0, 2]].min() > 0
    txpdo_view(tx)["status1"][2] = 0
    ctrl.step(np.array([0.2, 0.0, 0.0]), tx, rx, np.zeros(3))
    assert not ctrl.operational
    assert cmd["command1"].tolist() == [0] * 4 and not cmd["setpoint1"].any() and not cmd["setpoint2"].any()
    assert not ctrl.bank.xi.any()  # integrators reset while not operational


def test_an_empty_image_and_disable_give_safe_commands():
    ctrl, rx = PlatformVelocityController(), new_rx_image(4)
    rxpdo_view(rx)["setpoint1"] = 5.0
    ctrl.step(np.array([0.5, 0.0, 0.0]), new_tx_image(4), rx, np.zeros(3))  # before the first exchange
    cmd = rxpdo_view(rx)
    assert cmd["command1"].tolist() == [0] * 4 and not cmd["setpoint1"].any()
    tx = _sensors(np.zeros(4), np.zeros(8))
    ctrl.step(np.array([0.5, 0.0, 0.0]), tx, rx, np.zeros(3))
    assert cmd["command1"].tolist() == [RUNNING] * 4 and cmd["setpoint1"].min() > 0
    ctrl.disable()
    ctrl.step(np.array([0.5, 0.0, 0.0]), tx, rx, np.zeros(3))
    assert cmd["command1"].tolist() == [0] * 4 and not cmd["setpoint1"].any()
    ctrl.enable()
    ctrl.step(np.array([0.5, 0.0, 0.0]), tx, rx, np.zeros(3))
    assert cmd["command1"].tolist() == [RUNNING] * 4
    ctrl.write_safe_commands(rx)
    assert cmd["command1"].tolist() == [0] * 4 and not cmd["setpoint2"].any()


def test_setpoint_conditioning():
    ctrl = PlatformVelocityController()
    ctrl.update(np.array([3.0, -3.0, 2.0]), np.zeros(4), np.zeros(8), np.ones(4))
    assert ctrl.v_sp.tolist() == [2.0, -2.0, 1.6]
    ramp = PlatformVelocityController(PlatformControllerParams(max_acceleration=(2.0, 2.0, 1.6)))
    for k in range(1, 4):
        ramp.update(np.array([1.0, -1.0, 1.0]), np.zeros(4), np.zeros(8), np.ones(4))
        np.testing.assert_allclose(ramp.v_sp, [0.002 * k, -0.002 * k, 0.0016 * k])


def test_qp_distribution_agrees_while_nothing_saturates():
    inp = OPEN_LOOP["input"]
    a = PlatformVelocityController(PlatformControllerParams(clip_current=False))
    b = PlatformVelocityController(PlatformControllerParams(clip_current=False, distribution="qp"))
    for _ in range(3):
        for ctrl in (a, b):
            ctrl.update(np.array(inp["v_sp"]), np.array(inp["delta"]), np.zeros(8), np.ones(4))
        np.testing.assert_allclose(b.tau_dist, a.tau_dist, atol=1e-8)


def test_step_allocates_nothing():
    """Nothing retained, and no array-sized temporaries: numpy.linalg's inv/pinv/solve alone peak at
    3-6 KiB. What remains is numpy's own transient iterator scratch for matmul and broadcasting."""
    ctrl, rx, v = PlatformVelocityController(), new_rx_image(4), np.zeros(3)
    tx = _sensors([0.3, -1.0, 2.0, 0.5], np.linspace(-5, 5, 8))
    sp = np.array([0.3, 0.1, 0.2])
    retained, peak = allocation_stats(lambda: ctrl.step(sp, tx, rx, v), 1000)
    assert retained < 256 and peak < 2048


def test_params_must_fit_the_geometry():
    with pytest.raises(ValueError):
        PlatformVelocityController(replace(PlatformControllerParams(), pivot_offsets_rad=(0.0, 0.0)))


def test_configured_units_and_the_update_path_agree_with_the_image_path():
    params = PlatformControllerParams(units_enabled=(True, True, False, True), pivot_offsets_rad=(0.0,) * 4)
    a, b = PlatformVelocityController(params), PlatformVelocityController(params)
    phidot, rx = np.array([-4.0, -2.5, -1.0, 0.5, 1.0, 2.25, 3.0, 4.5]), new_rx_image(4)  # float32-exact
    tx = _sensors([0.3, -1.0, 2.0, 0.5], phidot, offsets=np.zeros(4))
    delta32 = txpdo_view(tx)["encoder_pivot"].astype(np.float64)
    a.update(np.array([0.2, 0.1, 0.3]), delta32, phidot, np.ones(4))
    b.step(np.array([0.2, 0.1, 0.3]), tx, rx, np.zeros(3))
    assert a.unit_enable.tolist() == b.unit_enable.tolist() == [1, 1, 0, 1]
    np.testing.assert_array_equal(a.current_hw, b.current_hw)
    assert not a.current_hw[4:6].any() and a.current_hw.any()
    assert rxpdo_view(rx)["command1"].tolist() == [RUNNING, RUNNING, 0, RUNNING]


def test_model_quantities_of_the_wrong_size_are_refused_by_name():
    ctrl = PlatformVelocityController()
    with pytest.raises(ValueError, match="delta"):
        ctrl.update(np.zeros(3), np.zeros(3), np.zeros(8), np.ones(4))
    with pytest.raises(ValueError, match="phidot"):
        ctrl.update(np.zeros(3), np.zeros(4), np.zeros(4), np.ones(4))
    with pytest.raises(ValueError, match="11 channels"):
        ctrl.bank.step(np.zeros(6), np.zeros(6))
    with pytest.raises(ValueError, match="enable"):
        ctrl.kinematics.update(np.zeros(4), [1, 1])


# -- the block: what the robot executes, whatever its setpoint says -----------------------------------------
def _ropod(**params) -> BlockHarness:
    """The platform controller block with its robot-side limits, its setpoint stale after 100 ms, and
    healthy wheels at rest."""
    harness = BlockHarness("ropod_controller", {"max_velocity": [1.5, 1.0, 1.6],
                                                "max_acceleration": [3.0, 3.0, 6.0], **params},
                           max_age_ns={"velocity_setpoint": 100_000_000})
    harness.configure()
    harness.feed("wheel_sensors", _sensors(np.zeros(4), np.zeros(8)))
    return harness


def _executed(harness: BlockHarness) -> np.ndarray:
    """The setpoint the controller executes this cycle (after the robot's limits)."""
    return harness.block.controller.v_sp


def test_the_wheel_controller_ignores_a_stale_setpoint():
    """The setpoint stops arriving (the link, the governor, the operator): older than its max_age it is no
    setpoint, and the controller itself brings the platform to zero, governor or not."""
    ropod = _ropod()
    for _ in range(200):  # up to speed at the robot's own acceleration
        ropod.feed("velocity_setpoint", [0.5, 0.0, 0.0])
        ropod.step()
    assert _executed(ropod)[0] == pytest.approx(0.5)
    ropod.step(90)  # 90 ms after the last sample: not stale yet, still followed
    assert _executed(ropod)[0] == pytest.approx(0.5)
    ropod.step(20)  # 110 ms: stale
    ropod.step(300)  # the ramp down at the robot's own deceleration
    np.testing.assert_array_equal(_executed(ropod), np.zeros(3))


def test_the_wheel_controller_obeys_its_stop_flag_with_a_fresh_setpoint():
    ropod = _ropod()
    for _ in range(200):
        ropod.feed("velocity_setpoint", [0.5, 0.0, 0.3])
        ropod.step()
    assert _executed(ropod)[0] == pytest.approx(0.5)
    ropod.flags["stop"] = True
    for _ in range(300):
        ropod.feed("velocity_setpoint", [0.5, 0.0, 0.3])  # fresh, and still not followed
        ropod.step()
    np.testing.assert_array_equal(_executed(ropod), np.zeros(3))
    assert any("stop raised" in line for line in ropod.log_lines())


@pytest.mark.parametrize("bad", [[1e300, 0.0, 0.0], [0.0, 0.0, np.inf], [np.nan, 0.0, 0.0], [0.0, -11.0, 0.0]])
def test_a_setpoint_not_finite_or_out_of_range_is_not_executed_and_the_next_good_one_is(bad):
    ropod = _ropod()
    for _ in range(200):
        ropod.feed("velocity_setpoint", bad)
        ropod.step()
        assert np.all(np.isfinite(_executed(ropod)))
    np.testing.assert_array_equal(_executed(ropod), np.zeros(3))
    assert ropod.block.bounds.refused == 200
    lines = ropod.log_lines()
    assert sum("refused" in line for line in lines) == 1  # once per burst
    for _ in range(200):
        ropod.feed("velocity_setpoint", [0.3, 0.0, 0.0])
        ropod.step()
    assert _executed(ropod)[0] == pytest.approx(0.3)
    assert any("following again after 200" in line for line in ropod.log_lines())


def test_the_robots_own_limits_bound_what_it_executes_inside_the_declared_range():
    """5 m/s is inside the port's range (a plausible command) but beyond the robot: its own speed limit
    clips it, and its acceleration limit bounds every change of the executed setpoint."""
    ropod = _ropod()
    previous = _executed(ropod)
    for _ in range(1000):
        ropod.feed("velocity_setpoint", [5.0, -5.0, 9.0])
        ropod.step()
        now = _executed(ropod)
        assert np.all(np.abs(now - previous) <= np.array([3.0, 3.0, 6.0]) * 1e-3 + 1e-12)
        previous = now
    np.testing.assert_allclose(_executed(ropod), [1.5, -1.0, 1.6])


def test_the_library_controller_executes_no_nan_whatever_it_is_given():
    ctrl = PlatformVelocityController(PlatformControllerParams())
    tx, rx, v_meas = _sensors(np.zeros(4), np.zeros(8)), new_rx_image(4), np.zeros(3)
    ctrl.step(np.array([np.nan, np.inf, -np.inf]), tx, rx, v_meas)
    np.testing.assert_array_equal(ctrl.v_sp, [0.0, 2.0, -1.6])
    assert np.all(np.isfinite(rxpdo_view(rx)["setpoint1"]))
