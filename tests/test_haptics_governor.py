"""S1 speed governor (docs/hallway-experiment.md §10): never adds speed, stops before obstacles, keeps
turns off the walls."""

import math

import numpy as np
import pytest

from hapticop.haptics.geometry import BeamGeometry
from hapticop.haptics.governor import GovernorParams, govern_cycle, govern_scan, govern_twist, stop_gap

from .scans import hallway, robot_scan, tim561_angles
from .test_haptics_handle import assert_no_allocation

ANGLES = tim561_angles(811)
BEAMS = BeamGeometry(ANGLES)


def governed(cmd, segments, pose=(0.0, 0.0, 0.0), params=GovernorParams()):
    return govern_twist(np.asarray(cmd, float), robot_scan(ANGLES, segments, pose), BEAMS, np.zeros(3), params)


def test_free_space_leaves_the_command_alone():
    cmd = np.array([1.0, 0.2, -0.7])
    out = govern_twist(cmd, np.full(811, np.nan), BEAMS, np.zeros(3))
    np.testing.assert_array_equal(out, cmd)
    np.testing.assert_array_equal(governed(cmd, hallway(4.0, 30.0)), cmd)


def test_never_increases_speed_or_changes_direction():
    rng = np.random.default_rng(7)
    out = np.zeros(3)
    for _ in range(300):
        segments = [((rng.uniform(-2, 4), rng.uniform(-3, 3)), (rng.uniform(-2, 4), rng.uniform(-3, 3)))
                    for _ in range(4)]
        pose = (0.0, 0.0, rng.uniform(-math.pi, math.pi))
        cmd = rng.uniform([-0.5, -0.3, -1.0], [1.0, 0.3, 1.0])
        ranges = robot_scan(ANGLES, segments, pose)
        govern_twist(cmd, ranges, BEAMS, out)
        assert np.all(np.abs(out) <= np.abs(cmd)), (cmd, out)
        assert np.all(out * cmd >= 0.0), (cmd, out)


def test_speed_limit_follows_the_braking_law():
    # End wall 2.5 m ahead of the front: g = 2.0 m, v ≤ √(2·0.5·2.0).
    wall = [((0.35 + 2.5, -5.0), (0.35 + 2.5, 5.0))]
    assert governed([1.6, 0, 0], wall)[0] == pytest.approx(math.sqrt(2.0), abs=1e-9)
    assert governed([0.8, 0, 0], wall)[0] == 0.8
    assert governed([-0.5, 0, 0], wall)[0] == -0.5  # reversing away is not limited


def test_an_operator_who_keeps_pushing_stops_at_dist2_before_the_end_wall():
    segments = hallway(2.0, 6.0)
    x, dt, v = 0.0, 0.01, 0.0
    front_min = math.inf
    for _ in range(3000):  # 30 s, full stick forward the whole time
        v = governed([1.0, 0, 0], segments, (x, 0.0, 0.0))[0]
        assert v <= 1.0
        x += v * dt
        front_min = min(front_min, 6.0 - (x + 0.35))
    front = 6.0 - (x + 0.35)
    assert v < 0.02
    assert front == pytest.approx(0.50, abs=0.02)
    assert front_min > 0.48  # no overshoot into the stop distance, far from the 0.10 m bumper


def test_turns_towards_a_near_wall_are_clipped_and_turns_away_are_not():
    near_left = [((-10.0, 0.38), (20.0, 0.38))]  # 0.08 m beside the body: inside dist3
    narrow = GovernorParams(corridor_margin_m=0.05)  # keep the wall out of the stop corridor
    assert governed([0.5, 0, 0.5], near_left, params=narrow)[2] == 0.0
    assert governed([0.5, 0, -0.5], near_left, params=narrow)[2] == -0.5
    # With the default margin (= dist3) a wall that close counts as ahead: the robot may not drive on.
    assert governed([0.5, 0, 0.5], near_left)[0] == 0.0
    # 0.2 m beside: turning left is allowed up to 2(c − dist3)/(v·T_p²).
    left = [((-10.0, 0.5), (20.0, 0.5))]
    assert governed([0.5, 0, 1.0], left)[2] == pytest.approx(2 * (0.2 - 0.1) / (0.5 * 1.5**2), abs=1e-9)
    right = [((-10.0, -0.5), (20.0, -0.5))]
    assert governed([0.5, 0, -1.0], right)[2] == pytest.approx(-2 * (0.2 - 0.1) / (0.5 * 1.5**2), abs=1e-9)
    assert governed([0.5, 0, 1.0], right)[2] == 1.0


def test_sideways_motion_brakes_for_the_side_wall():
    left = [((-10.0, 0.5), (20.0, 0.5))]  # 0.2 m beside the body
    assert governed([0.0, 0.5, 0], left)[1] == pytest.approx(math.sqrt(2 * 0.5 * (0.2 - 0.1)))
    assert governed([0.0, -0.5, 0], left)[1] == -0.5
    touching = [((-10.0, 0.35), (20.0, 0.35))]
    assert governed([0.0, 0.5, 0], touching)[1] == 0.0


def test_governor_allocates_nothing():
    ranges = robot_scan(ANGLES, hallway(2.0, 4.0), (0.5, 0.3, math.radians(8))).astype(np.float32)
    cmd, out = np.array([0.8, 0.05, 0.4]), np.zeros(3)
    assert_no_allocation(lambda: govern_twist(cmd, ranges, BEAMS, out))


def test_blind_limit_keeps_direction_and_clips_turning():
    from hapticop.haptics.governor import limit_blind

    twist = np.array([0.3, 0.4, -1.0])  # 0.5 m/s
    limit_blind(twist, 0.1, 0.2)
    assert np.allclose(twist, [0.06, 0.08, -0.2])
    slow = np.array([0.05, 0.0, 0.1])
    assert np.array_equal(limit_blind(slow.copy(), 0.1, 0.2), slow)  # within the limits: untouched
    assert np.array_equal(limit_blind(np.array([0.5, -0.2, 0.7]), 0.0, 0.0), [0.0, -0.0, 0.0])


def test_scan_work_once_then_every_cycle_matches_the_full_evaluation():
    """govern_scan once per scan and govern_cycle per command give what govern_twist gives each time."""
    rng = np.random.default_rng(3)
    once, every = BeamGeometry(ANGLES), BeamGeometry(ANGLES)
    out_once, out_every = np.zeros(3), np.zeros(3)
    for _ in range(20):
        ranges = robot_scan(ANGLES, hallway(rng.uniform(1.2, 3.0), 8.0), (rng.uniform(0, 5), rng.uniform(-0.2, 0.2),
                                                                           rng.uniform(-0.3, 0.3)))
        gap = govern_scan(ranges, once)
        for _ in range(30):
            cmd = rng.uniform([-0.5, -0.3, -1.0], [1.5, 0.3, 1.0])
            govern_cycle(cmd, once, gap, out_once)
            np.testing.assert_array_equal(out_once, govern_twist(cmd, ranges, every, out_every))


def test_the_braking_fields_beams_serve_the_governor_as_its_own_would():
    """What the haptic controller does when the field and the governor share one BeamGeometry."""
    from hapticop.haptics.force_models import BrakingField

    rng = np.random.default_rng(9)
    field, own = BrakingField(), BeamGeometry(ANGLES)
    field.configure(ANGLES)
    shared_out, own_out, force = np.zeros(3), np.zeros(3), np.zeros(3)
    for _ in range(10):
        ranges = robot_scan(ANGLES, hallway(rng.uniform(1.2, 3.0), 8.0), (rng.uniform(0, 5), rng.uniform(-0.2, 0.2),
                                                                           rng.uniform(-0.3, 0.3)))
        field.update_scan(ranges)
        shared_gap, own_gap = stop_gap(field.beams), govern_scan(ranges, own)
        assert shared_gap == own_gap
        for _ in range(20):
            cmd = rng.uniform([-0.5, -0.3, -1.0], [1.5, 0.3, 1.0])
            field.render(np.array([0.0, 0.0, -0.01]), cmd + [0.0, 1e-9, 0.0], force, 0.02)  # its own shift first
            govern_cycle(cmd, field.beams, shared_gap, shared_out)
            np.testing.assert_array_equal(shared_out, govern_cycle(cmd, own, own_gap, own_out))


def test_the_governor_block_refuses_a_bad_command_and_follows_the_next_good_one():
    """A command not finite or outside its port's range (from the link or a buggy block) is no command:
    the governor allows no motion until the next good command, which it follows again."""
    from hapticop.testing import BlockHarness

    governor = BlockHarness("speed_governor", {"scan_points": 9})
    governor.feed("angles", np.linspace(-2.0, 2.0, 9, dtype=np.float32))
    governor.feed("ranges", np.full(9, 20.0, dtype=np.float32))  # nothing near
    governor.configure()
    governor.feed("command", [0.3, 0.0, 0.1])
    governor.step()
    np.testing.assert_allclose(governor.outputs.twist.value, [0.3, 0.0, 0.1])
    for bad in ([1e300, 0.0, 0.0], [0.0, 0.0, np.inf], [np.nan, 0.0, 0.0], [0.0, -10.5, 0.0]):
        governor.feed("ranges", np.full(9, 20.0, dtype=np.float32))
        governor.feed("command", bad)
        governor.step()
        np.testing.assert_array_equal(governor.outputs.twist.value, np.zeros(3))
        governor.feed("command", [0.3, 0.0, 0.1])
        governor.step()
        np.testing.assert_allclose(governor.outputs.twist.value, [0.3, 0.0, 0.1])
    assert governor.block.bounds.refused == 4
