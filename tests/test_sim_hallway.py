"""The simulated hallway on MuJoCo: the scene files carry docs/hallway-experiment.md §2's numbers, and the
scanner's ranges and the footprint's clearances (all, to the end wall, to the sides) are what geometry
worked out by hand says."""

import math

import numpy as np
import pytest

from hapticop.devices.sick.device_model import ANGLES_RAD
from hapticop.sim import scene_files
from hapticop.sim.engine import Engine
from hapticop.sim.hallway_task import Hallway
from hapticop.sim.scene import Block3, Lidar, Robot, Scene, to_mjcf
from hapticop.testing import grown_bytes

BOX = Scene(walls=(Block3(size_m=(4.2, 0.1, 1.0), position_m=(2.0, -1.05)),
                   Block3(size_m=(4.2, 0.1, 1.0), position_m=(2.0, 1.05)),
                   Block3(size_m=(0.1, 2.0, 1.0), position_m=(-0.05, 0.0)),
                   Block3(size_m=(0.1, 2.0, 1.0), position_m=(4.05, 0.0))))
"""A closed 4 m x 2 m room, x in [0, 4], y in [-1, 1] (its walls' inner faces)."""


def cast(scene, pose, angles_deg, yaw_rad=0.0, low=0.05, high=10.0):
    engine = Engine(to_mjcf(scene))
    engine.place_robot(np.array(pose, float))
    out = np.empty(len(angles_deg))
    return engine.scan(np.radians(np.asarray(angles_deg, float)), out, low, high, yaw_rad)


def with_lidar(scene, **mount):
    return scene.model_copy(update={"robot": Robot(lidar=Lidar(**mount))})


def test_ranges_in_a_room_are_exact():
    # The LIDAR 0.25 m ahead of the centre: at (1.25, 0) looking along +x.
    r = cast(BOX, (1.0, 0.0, 0.0), [0.0, 90.0, -90.0, 180.0])
    assert r == pytest.approx([2.75, 1.0, 1.0, 1.25], abs=1e-9)
    corner = math.degrees(math.atan2(1.0, 2.75))  # exactly into the corner (4, 1)
    r = cast(BOX, (1.0, 0.0, 0.0), [corner, -corner])
    assert r == pytest.approx([math.hypot(2.75, 1.0)] * 2, abs=1e-9)


def test_ranges_follow_the_pose_and_the_mount():
    # Facing +y from (2, 0.5): the LIDAR sits at (2, 0.75); its left is -x.
    r = cast(BOX, (2.0, 0.5, math.pi / 2), [0.0, 90.0, -90.0, 45.0])
    assert r == pytest.approx([0.25, 2.0, 2.0, 0.25 * math.sqrt(2)], abs=1e-9)
    # A scanner mounted backwards at the centre sees the rear wall straight ahead.
    r = cast(with_lidar(BOX, x_m=0.0, yaw_deg=180.0), (1.0, 0.0, 0.0), [0.0], yaw_rad=math.pi)
    assert r == pytest.approx([1.0], abs=1e-9)
    # Mounted off-centre to the left.
    r = cast(with_lidar(BOX, x_m=0.0, y_m=0.2), (1.0, 0.0, 0.0), [90.0, -90.0])
    assert r == pytest.approx([0.8, 1.2], abs=1e-9)


def test_no_return_beyond_max_range_below_min_range_or_into_the_open():
    h1 = scene_files.load("H1")[0].scene
    r = cast(h1, (0.5, 0.0, 0.0), [0.0, 135.0, -135.0])
    assert r[0] == pytest.approx(9.25)
    assert np.isnan(r[1:]).all(), "nothing behind the entrance"
    h6 = scene_files.load("H6")[0].scene
    assert np.isnan(cast(h6, (0.5, 0.0, 0.0), [0.0])).all(), "the end wall is 19 m away"
    assert cast(h6, (0.5, 0.0, 0.0), [0.0], high=25.0)[0] == pytest.approx(19.25)
    assert np.isnan(cast(BOX, (3.72, 0.0, 0.0), [0.0])).all(), "3 cm is below the 5 cm minimum"


def test_a_full_tim561_scan_hits_only_the_walls():
    angles = np.asarray(ANGLES_RAD, dtype=float)
    assert len(angles) == 811 and math.degrees(angles[0]) == pytest.approx(-135.0)
    engine = Engine(scene_files.load("H1")[0].xml)
    engine.place_robot(np.array([5.0, 0.0, 0.0]))
    out = np.empty(811, np.float32)
    engine.scan(angles, out, 0.05, 10.0)
    assert out[405] == pytest.approx(4.75 / math.cos(angles[405]), rel=1e-6)
    side = np.abs(np.sin(angles)) > 0.2
    assert np.isfinite(out[side]).all()
    ok = np.isfinite(out)
    hx, hy = 5.25 + out[ok] * np.cos(angles[ok]), out[ok] * np.sin(angles[ok])
    on_wall = np.isclose(np.abs(hy), 1.0, atol=1e-5) | np.isclose(hx, 10.0, atol=1e-5)
    assert on_wall.all()


def test_a_scan_and_the_clearances_allocate_nothing():
    engine = Engine(scene_files.load("H4")[0].xml)
    angles, out = np.asarray(ANGLES_RAD, dtype=float), np.empty(811, np.float32)
    front = Hallway.named("H4").front
    pose = np.array([5.0, 0.1, 0.05])

    def cycles():
        for _ in range(200):
            engine.place_robot(pose)
            engine.scan(angles, out, 0.05, 10.0)
            engine.clearances(front)

    cycles()
    assert grown_bytes(cycles) < 4096


def test_the_scene_files_carry_the_notes_numbers():
    h = {n: Hallway.named(n) for n in ("H1", "H2", "H3", "H4", "H5", "H6")}
    assert h["H2"].start == pytest.approx((0.5, 0.30, math.radians(8)))
    assert h["H3"].dist1_m == 0.30 and h["H3"].start[2] == pytest.approx(math.radians(-4))
    assert (h["H2"].dist2_m, h["H2"].dist3_m, h["H2"].collision_hysteresis_m) == (0.5, 0.1, 0.02)
    assert (h["H2"].footprint.length_m, h["H2"].footprint.width_m) == (0.70, 0.60)
    assert [h[n].middle_x_m for n in h] == [5.0, 5.0, 4.0, 5.0, 5.0, 10.0]
    assert scene_files.load("H5")[0].scene.robot.lidar.noise_sigma_m == 0.03
    assert h["H5"].start == h["H2"].start
    # Width and length from the walls: the robot at the centre line, 1.5 m before the end wall, squarely.
    for name, width, length in (("H1", 2.0, 10.0), ("H3", 1.5, 8.0), ("H6", 2.0, 20.0)):
        front_side = h[name].clearances(np.array([[length - 1.5, 0.0, 0.0]]))[0]
        assert front_side == pytest.approx([min(1.15, width / 2 - 0.3), 1.15, width / 2 - 0.3], abs=1e-9)
    # H6's end wall is beyond the scanner's range, not beyond the clearances' (T_ref is measured from it)
    assert h["H6"].clearances(np.array([h["H6"].start]))[0, 1] == pytest.approx(20.0 - 0.5 - 0.35, abs=1e-9)
    assert sum(h["H4"].front) == 1 and len(h["H4"].front) == 4  # the end wall; the sides and the pillar
    with pytest.raises(ValueError, match="H9"):
        Hallway.named("H9")


def _clearance_in(name: str):
    """The hallway's task, and the robot's clearance at a pose (x, y, theta) in its scene."""
    g = Hallway.named(name)
    engine = g.engine()

    def clear(pose):
        engine.place_robot(np.array(pose, float))
        return engine.clearance()

    return g, clear


def test_clearance_of_the_footprint():
    g, clear = _clearance_in("H4")
    assert clear(g.start) == pytest.approx(0.7)  # 1 m to each wall minus 0.3 m
    assert clear((5.0, 0.6, math.pi / 2)) == pytest.approx(0.05)  # long side across
    reach = (0.35 + 0.30) * math.sqrt(0.5)  # a corner at 45 degrees
    assert clear((9.0, 0.0, math.pi / 4)) == pytest.approx(1.0 - reach)
    assert clear((5.0, -0.3, 0.0)) == pytest.approx(0.15)  # over the 0.25 m deep pillar


def test_a_collision_when_the_footprint_touches_or_overlaps_a_wall():
    _, clear = _clearance_in("H4")
    assert clear((5.0, 0.7, 0.0)) == pytest.approx(0.0, abs=1e-9)  # touching
    assert clear((5.0, 0.7 + 1e-6, 0.0)) < 0.0  # just overlapping
    assert clear((5.0, 0.8, 0.0)) == pytest.approx(-0.1)  # 10 cm into the left wall
    assert clear((9.7, 0.0, 0.0)) < 0.0  # nose through the end wall
    assert clear((5.0, -0.5, 0.0)) < 0.0  # into the pillar


def test_clearances_over_a_trajectory_to_the_end_wall_and_the_sides():
    g = Hallway.named("H4")
    poses = np.column_stack([np.linspace(0.5, 9.0, 50), np.linspace(-0.2, 0.2, 50), np.linspace(-0.3, 0.3, 50)])
    both = g.clearances(poses)
    engine = g.engine()
    for pose, (least, front, side) in zip(poses, both):
        engine.place_robot(pose)
        assert engine.clearance() == least == min(front, side)
    # Worked out by hand: the end wall from the footprint's foremost corner, the side walls from the corner
    # nearest them (the pillar, 0.25 m deep at x 4.8 to 5.2, only where the footprint is beside it).
    hl, hw = 0.35, 0.30
    c, s = np.cos(poses[:, 2]), np.sin(poses[:, 2])
    reach_x = hl * np.abs(c) + hw * np.abs(s)
    reach_y = hl * np.abs(s) + hw * np.abs(c)
    np.testing.assert_allclose(both[:, 1], 10.0 - poses[:, 0] - reach_x, atol=1e-9)
    walls = 1.0 - np.abs(poses[:, 1]) - reach_y
    # the pillar is no nearer than the gap between it and the footprint's bounding box
    gap_x = np.maximum(np.maximum(4.8 - (poses[:, 0] + reach_x), (poses[:, 0] - reach_x) - 5.2), 0.0)
    gap_y = np.maximum((poses[:, 1] - reach_y) + 0.75, 0.0)
    away = np.hypot(gap_x, gap_y) > walls
    assert away.sum() > 30 and not away.all()
    np.testing.assert_allclose(both[away, 2], walls[away], atol=1e-9)
    assert (both[~away, 2] < walls[~away]).all()
