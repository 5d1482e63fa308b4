"""The blocks for bilateral set-ups, each in a BlockHarness against its equation: the spring-damper with its
anchor as an input, the two-port coupling, and a world's force brought to the handle."""

import math

import numpy as np
import pytest

from hapticop.testing import BlockHarness, allocation_stats


def _clip(f, limit):
    f = np.asarray(f, dtype=float)
    n = np.linalg.norm(f)
    return f * (limit / n) if n > limit else f


def _running(block, params, **feeds):
    harness = BlockHarness(block, params)
    harness.configure()
    for port, value in feeds.items():
        harness.feed(port, value)
    harness.step()
    return harness


# --- spring_damper, anchor as an input -----------------------------------------------------------------------

def test_the_spring_keeps_its_ports_and_its_anchor_parameter_unless_asked_for_an_input():
    assert set(BlockHarness("spring_damper").interface.inputs) == {"position", "velocity"}
    ports = BlockHarness("spring_damper", {"anchor": "input"}).interface.inputs
    assert ports["anchor"].unit == "m" and ports["anchor"].required and ports["anchor"].range is not None
    assert ports["anchor_velocity"].unit == "m/s" and not ports["anchor_velocity"].required


@pytest.mark.parametrize(("k", "b", "q", "v", "a", "va"), [
    (100.0, 1.0, [0.01, -0.02, 0.0], [0.1, 0.0, 0.0], [0.0, 0.0, 0.01], None),
    (100.0, 1.0, [0.01, -0.02, 0.0], [0.1, 0.0, 0.0], [0.0, 0.0, 0.01], [0.05, -0.2, 0.3]),
    (2500.0, 0.0, [0.05, 0.05, -0.05], [0.0, 0.0, 0.0], [-0.05, -0.05, 0.05], [1.0, 1.0, 1.0]),
    (0.0, 3.0, [0.0, 0.0, 0.0], [-0.4, 0.2, 0.0], [0.03, 0.0, 0.0], [0.1, 0.1, 0.1]),
    (500.0, 2.0, [0.02, 0.02, 0.02], [0.1, 0.1, 0.1], [0.02, 0.02, 0.02], [0.1, 0.1, 0.1]),  # together: nothing
])
def test_a_spring_to_an_anchor_input_renders_k_times_the_gap_less_b_times_the_relative_velocity(k, b, q, v, a, va):
    feeds = {"position": q, "velocity": v, "anchor": a}
    if va is not None:
        feeds["anchor_velocity"] = va
    params = {"anchor": "input", "spring": {"anchor_m": [9.0, 9.0, 9.0], "kp_n_per_m": k, "kd_ns_per_m": b}}
    harness = _running("spring_damper", params, **feeds)
    expected = k * (np.array(a) - np.array(q)) - b * (np.array(v) - np.array(va if va is not None else [0.0] * 3))
    np.testing.assert_allclose(harness.outputs.force.value, expected, rtol=1e-12, atol=1e-12)


def test_a_spring_without_its_anchor_or_with_a_bad_one_pulls_nowhere():
    params = {"anchor": "input", "spring": {"kp_n_per_m": 100.0}}
    harness = _running("spring_damper", params, position=[0.01, 0.0, 0.0])
    np.testing.assert_array_equal(harness.outputs.force.value, 0.0)  # never an anchor: not the parameter's
    harness.feed("anchor", [0.0, 0.0, 0.0])
    harness.step()
    np.testing.assert_allclose(harness.outputs.force.value, [-1.0, 0.0, 0.0])
    for bad in ([math.nan, 0.0, 0.0], [11.0, 0.0, 0.0]):
        harness.feed("anchor", bad)
        harness.step()
        np.testing.assert_array_equal(harness.outputs.force.value, 0.0)
    harness.feed("anchor", [0.0, 0.0, 0.0])
    harness.feed("anchor_velocity", [math.inf, 0.0, 0.0])
    harness.step()
    np.testing.assert_array_equal(harness.outputs.force.value, 0.0)
    assert sum(b.refused for b in harness.block.bounds.values()) == 3
    warnings = [line for line in harness.log_lines() if line.startswith("warning:")]
    assert len(warnings) == 2 and "anchor:" in warnings[0] and "anchor_velocity" in warnings[1]  # once per burst


def test_a_spring_to_a_stale_anchor_pulls_nowhere():
    harness = BlockHarness("spring_damper", {"anchor": "input"}, max_age_ns={"anchor": 5_000_000})
    harness.configure()
    harness.feed("position", [0.01, 0.0, 0.0])
    harness.feed("anchor", [0.0, 0.0, 0.0])
    harness.step()
    assert harness.outputs.force.value[0] < 0
    harness.step(10)
    np.testing.assert_array_equal(harness.outputs.force.value, 0.0)


# --- coupling ---------------------------------------------------------------------------------------------------

def _coupling(xl, vl, xf, vf, k, b, s, max_l, max_f):
    f = -k * (np.array(xl) - s * np.array(xf)) - b * (np.array(vl) - s * np.array(vf))
    return _clip(f, max_l), _clip(-f, max_f)


@pytest.mark.parametrize(("xl", "vl", "xf", "vf", "k", "b", "s", "max_l", "max_f"), [
    ([0.01, 0.0, 0.0], [0.0] * 3, [0.0] * 3, [0.0] * 3, 200.0, 2.0, 1.0, 8.0, 8.0),
    ([0.01, -0.02, 0.005], [0.1, 0.0, -0.2], [0.0, 0.01, 0.0], [0.0, 0.3, 0.1], 300.0, 1.5, 1.0, 50.0, 50.0),
    ([0.02, 0.0, 0.0], [0.0] * 3, [0.01, 0.0, 0.0], [0.1, 0.0, 0.0], 400.0, 2.0, 2.0, 8.0, 8.0),  # scaled: equal
    ([0.05, 0.05, 0.05], [0.0] * 3, [-0.05, -0.05, -0.05], [0.0] * 3, 1000.0, 0.0, 1.0, 8.0, 3.0),  # both limited
    ([0.05, 0.0, 0.0], [0.0] * 3, [0.0] * 3, [0.0] * 3, 1000.0, 0.0, 1.0, 0.0, 8.0),  # the leader gets nothing
    ([0.0, 0.03, 0.0], [0.0, 0.5, 0.0], [0.0, 0.01, 0.0], [0.0, -0.5, 0.0], 100.0, 4.0, 0.5, 6.0, 100.0),
])
def test_the_coupling_renders_its_equation_and_each_sides_limit(xl, vl, xf, vf, k, b, s, max_l, max_f):
    params = {"kp_n_per_m": k, "kd_ns_per_m": b, "scale": s, "leader_max_n": max_l, "follower_max_n": max_f}
    harness = _running("coupling", params, leader_position=xl, leader_velocity=vl, follower_position=xf,
                       follower_velocity=vf)
    leader, follower = _coupling(xl, vl, xf, vf, k, b, s, max_l, max_f)
    np.testing.assert_allclose(harness.outputs.leader_force.value, leader, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(harness.outputs.follower_force.value, follower, rtol=1e-12, atol=1e-12)
    assert np.linalg.norm(harness.outputs.leader_force.value) <= max_l + 1e-12
    assert np.linalg.norm(harness.outputs.follower_force.value) <= max_f + 1e-12


def test_the_coupling_without_velocities_couples_positions_alone():
    harness = _running("coupling", {"kp_n_per_m": 200.0, "kd_ns_per_m": 5.0},
                       leader_position=[0.01, 0.0, 0.0], follower_position=[0.0, 0.0, 0.0])
    np.testing.assert_allclose(harness.outputs.leader_force.value, [-2.0, 0.0, 0.0])
    np.testing.assert_allclose(harness.outputs.follower_force.value, [2.0, 0.0, 0.0])


def test_the_coupling_renders_nothing_without_both_positions_or_with_a_bad_sample():
    harness = _running("coupling", {}, leader_position=[0.01, 0.0, 0.0])
    np.testing.assert_array_equal(harness.outputs.leader_force.value, 0.0)
    np.testing.assert_array_equal(harness.outputs.follower_force.value, 0.0)
    harness.feed("follower_position", [0.0, 0.0, 0.0])
    harness.step()
    assert harness.outputs.leader_force.value[0] < 0
    for port, bad in (("follower_position", [0.0, math.nan, 0.0]), ("leader_velocity", [0.0, 0.0, 1e3])):
        harness.feed(port, bad)
        harness.step()
        np.testing.assert_array_equal(harness.outputs.leader_force.value, 0.0)
        np.testing.assert_array_equal(harness.outputs.follower_force.value, 0.0)
        harness.feed(port, [0.0, 0.0, 0.0])
    assert sum(b.refused for b in harness.block.bounds.values()) == 2


# --- contact_to_handle ------------------------------------------------------------------------------------------

def _r(yaw, pitch, roll):
    cz, sz, cy, sy, cx, sx = np.cos(yaw), np.sin(yaw), np.cos(pitch), np.sin(pitch), np.cos(roll), np.sin(roll)
    rz = np.array([[cz, -sz, 0], [sz, cz, 0], [0, 0, 1]])
    ry = np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
    rx = np.array([[1, 0, 0], [0, cx, -sx], [0, sx, cx]])
    return rz @ ry @ rx


@pytest.mark.parametrize(("f", "yaw", "pitch", "roll", "gain", "dead", "limit"), [
    ([1.0, 0.0, 0.0], math.pi / 2, 0.0, 0.0, 1.0, 0.0, 8.0),  # world x is device y
    ([3.0, -4.0, 12.0], 0.3, -0.7, 1.1, 0.5, 0.0, 8.0),
    ([3.0, -4.0, 12.0], 0.3, -0.7, 1.1, 0.5, 5.0, 8.0),  # the dead-band takes 5 N of 13
    ([30.0, 40.0, 0.0], -math.pi, math.pi, 0.2, 2.0, 1.0, 8.0),  # limited
    ([0.3, 0.4, 0.0], 0.0, 0.0, 0.0, 10.0, 0.5, 8.0),  # at the dead-band's edge: nothing
    ([0.3, 0.4, 0.0], 0.4, 0.0, 0.0, 10.0, 2.0, 8.0),  # inside the dead-band: nothing
    ([0.3, 0.4, 0.0], 0.0, 0.0, 0.0, 10.0, 0.49, 8.0),  # just past it: a little
])
def test_a_world_force_reaches_the_handle_rotated_scaled_dead_banded_and_limited(f, yaw, pitch, roll, gain, dead,
                                                                               limit):
    params = {"yaw_rad": yaw, "pitch_rad": pitch, "roll_rad": roll, "gain": gain, "dead_band_n": dead, "max_n": limit}
    harness = _running("contact_to_handle", params, world_force=f)
    f = np.array(f)
    n = np.linalg.norm(f)
    expected = _clip(gain * max(n - dead, 0.0) / n * (_r(yaw, pitch, roll) @ f), limit)
    np.testing.assert_allclose(harness.outputs.force.value, expected, rtol=1e-12, atol=1e-12)


def test_a_planar_wrench_is_felt_by_its_force_and_not_its_torque():
    """`measured: planar_wrench` takes scene_world's contact wrench [fx, fy, torque] (its unit says so): the
    robot's x to the handle's -z and y to -x, as systems/push_box.yaml turns it, and no torque felt."""
    from hapticop.blocks.coupling import ContactToHandle, ContactToHandleParams

    params = {"measured": "planar_wrench", "pitch_rad": math.pi / 2, "roll_rad": -math.pi / 2, "max_n": 100.0}
    assert ContactToHandle.interface(ContactToHandleParams(**params)).inputs["world_force"].unit == "N, N, N m"
    harness = _running("contact_to_handle", params, world_force=[-3.0, 4.0, 50.0])
    np.testing.assert_allclose(harness.outputs.force.value, [-4.0, 0.0, 3.0], atol=1e-12)


def test_a_world_force_not_finite_is_felt_as_nothing_and_said_once():
    harness = _running("contact_to_handle", {"gain": 1.0}, world_force=[1.0, 0.0, 0.0])
    np.testing.assert_allclose(harness.outputs.force.value, [1.0, 0.0, 0.0])
    for bad in ([math.nan, 0.0, 0.0], [0.0, math.inf, 0.0], [0.0, 0.0, -math.inf]):
        harness.feed("world_force", bad)
        harness.step()
        np.testing.assert_array_equal(harness.outputs.force.value, 0.0)
    assert harness.block.refused == 3
    harness.feed("world_force", [0.0, 2.0, 0.0])
    harness.step()
    np.testing.assert_allclose(harness.outputs.force.value, [0.0, 2.0, 0.0])
    lines = harness.log_lines()
    assert sum(line.startswith("warning:") for line in lines) == 1 and any("after 3 refused" in line for line in lines)


def test_a_retuned_rotation_applies_at_the_next_cycle():
    harness = _running("contact_to_handle", {}, world_force=[1.0, 0.0, 0.0])
    harness.retune({"yaw_rad": math.pi / 2})
    harness.step()
    np.testing.assert_allclose(harness.outputs.force.value, [0.0, 1.0, 0.0], atol=1e-15)


# --- nothing allocated per cycle --------------------------------------------------------------------------------

@pytest.mark.parametrize(("block", "params", "feeds"), [
    ("spring_damper", {"anchor": "input"}, {"position": [0.01, 0.0, 0.0], "velocity": [0.1, 0.0, 0.0],
                                            "anchor": [0.0, 0.02, 0.0], "anchor_velocity": [0.0, 0.1, 0.0]}),
    ("coupling", {"kp_n_per_m": 1000.0}, {"leader_position": [0.05, 0.0, 0.0], "leader_velocity": [0.1, 0.0, 0.0],
                                          "follower_position": [0.0, 0.0, 0.0], "follower_velocity": [0.0] * 3}),
    ("contact_to_handle", {"yaw_rad": 0.5, "dead_band_n": 0.1}, {"world_force": [20.0, 0.0, 3.0]}),
])
def test_the_new_blocks_compute_without_allocating(block, params, feeds):
    harness = _running(block, params, **feeds)
    retained, peak = allocation_stats(harness.block.compute, 2000)
    assert retained < 256 and peak < 2048, (retained, peak)
