"""Scenes on MuJoCo: the six hallways as scene files, located findings for broken scenes, contact
pushed back to the robot, and the simulated TiM561 scanning a scene as it scanned the hallway."""

from __future__ import annotations

import math

import numpy as np
import pytest

from hapticop.devices.link import published_address
from hapticop.devices.ropod.pdo import RXPDO_BYTES, TXPDO_BYTES
from hapticop.devices.ropod.plant import RopodPlant
from hapticop.devices.sick.client import ColaClient
from hapticop.devices.sick.device_model import ANGLES_RAD
from hapticop.runtime.clock import VirtualClock
from hapticop.sim import scene_files
from hapticop.sim.devices.tim561 import Tim561Simulator
from hapticop.sim.engine import Engine, SceneError
from hapticop.sim.hallway import HallwayGeometry, World
from hapticop.sim.scene import Block3, Movable, Robot, Scene, to_mjcf
from hapticop.sim.scene_world import SceneWorld, SceneWorldParams
from hapticop.sim.world_share import publish_world, withdraw_world
from hapticop.validation import validate_path

from .runtime_helpers import standalone

HALLWAYS = ("H1", "H2", "H3", "H4", "H5", "H6")


@pytest.mark.parametrize("name", HALLWAYS)
def test_each_hallway_scene_scans_and_measures_as_the_hand_written_hallway(name):
    loaded, found = scene_files.load(name)
    assert found == [] and loaded is not None
    engine = Engine(loaded.xml)
    geometry = HallwayGeometry.named(name)
    walls = World.from_geometry(geometry)
    angles = np.asarray(ANGLES_RAD, dtype=float)
    old, new = np.zeros(len(angles)), np.zeros(len(angles))
    for pose in (geometry.start, (geometry.length_m - 1.5, 0.2, 0.3), (geometry.length_m / 2, -0.3, -0.5)):
        engine.place_robot(np.array(pose))
        engine.scan(angles, new, 0.05, 10.0)
        walls.raycast(pose, geometry.lidar.mount, angles, old, 10.0, 0.05)
        assert np.array_equal(np.isnan(old), np.isnan(new))
        assert np.nanmax(np.abs(old - new)) < 1e-9
        assert abs(engine.clearance() - walls.clearance(np.array(pose), geometry.footprint)[0]) < 1e-9


def _write(tmp_path, scene_text: str, params: str = "judge: false") -> str:
    (tmp_path / "room.yaml").write_text(scene_text)
    composition = tmp_path / "app.yaml"
    composition.write_text(f"""version: 1
name: app
threads:
  sim:
    period: 1ms
    deploy: main
    schedules: {{0: [mediator, world]}}
activities:
  mediator: {{block: mediator}}
  world:
    block: scene_world
    params: {{scene: room.yaml, {params}}}
""")
    return str(composition)


ROOM = """walls:
  - {name: north, size_m: [6.0, 0.1, 1.0], position_m: [3.0, 2.05]}
  - {name: south, size_m: [6.0, 0.1, 1.0], position_m: [3.0, -2.05]}
bodies:
  - {name: crate, size_m: [0.4, 0.4, 0.4], position_m: [2.0, 0.0], mass_kg: 10.0}
"""


def test_a_room_of_ones_own_validates(tmp_path):
    report = validate_path(_write(tmp_path, ROOM)).report
    assert report.ok, [d.to_text() for d in report.diagnostics]


@pytest.mark.parametrize("change, rule, line, field", [
    (("material: wall}", "material: marble}"), "scene-material", 2, "walls.0.material"),
    (("mass_kg: 10.0", "material: wood"), "scene-mass", 5, "bodies.0"),
    (("position_m: [3.0, -2.05]", "position_m: [3.0, 2.0]"), "scene-overlap", 3, "walls.1"),
    (("position_m: [2.0, 0.0]", "position_m: [0.5, 0.0]"), "scene-start-inside", 5, "bodies.0.position_m"),
    (("size_m: [6.0, 0.1", "size_m: [6.0, -0.1"), "scene-load", 0, ""),
])
def test_a_broken_scene_is_one_located_finding(tmp_path, change, rule, line, field):
    text = ROOM.replace("position_m: [3.0, 2.05]}", "position_m: [3.0, 2.05], material: wall}")
    old, new = change
    assert old in text
    report = validate_path(_write(tmp_path, text.replace(old, new))).report
    found = [d for d in report.diagnostics if d.rule == rule]
    assert len(found) == 1 and not report.ok, [d.to_text() for d in report.diagnostics]
    assert found[0].file.endswith("room.yaml") or rule == "scene-load"
    if line:
        assert found[0].line == line and found[0].dotted_path == field


def test_a_robot_starting_inside_a_wall_is_refused_where_it_starts(tmp_path):
    report = validate_path(_write(tmp_path, ROOM + "robot: {start: [3.0, 1.9, 0.0]}\n")).report
    [found] = [d for d in report.diagnostics if d.rule == "scene-start-inside"]
    assert (found.line, found.dotted_path) == (6, "robot.start") and "walls[0] 'north'" in found.message


def test_an_mjcf_file_mujoco_cannot_load_is_one_message(tmp_path):
    (tmp_path / "broken.xml").write_text("<mujoco><worldbody><geom type='box'/></worldbody></mujoco>")
    report = validate_path(_mjcf_app(tmp_path)).report
    [found] = [d for d in report.diagnostics if d.rule == "scene-load"]
    assert found.file.endswith("broken.xml") and "\n" not in found.message and "MuJoCo" in found.message


def _mjcf_app(tmp_path) -> str:
    path = _write(tmp_path, ROOM)
    text = open(path).read().replace("room.yaml", "broken.xml")
    open(path, "w").write(text)
    return path


def test_a_judged_scene_needs_a_hallway_task(tmp_path):
    report = validate_path(_write(tmp_path, ROOM, params="judge: true")).report
    assert "scene-judge" in [d.rule for d in report.errors]


def _pushing(mass_kg: float, steps: int = 400) -> tuple[float, float]:
    """The robot driven at 0.3 m/s into a crate of `mass_kg`: the mean push back on it, and how far the crate went."""
    scene = Scene(bodies=(Movable(size_m=(0.4, 0.4, 0.4), position_m=(1.0, 0.0), mass_kg=mass_kg),),
                  robot=Robot(start=(0.5, 0.0, 0.0)))
    engine = Engine(to_mjcf(scene))
    pose, twist, wrench, poses = np.array([0.4, 0.0, 0.0]), np.array([0.3, 0.0, 0.0]), np.zeros(3), np.zeros((1, 3))
    pushes = []
    for _ in range(steps):
        engine.place_robot(pose, twist)
        engine.step()
        engine.contact_wrench(wrench)
        pushes.append(wrench[0])
        pose[0] += 0.3 * engine.model.opt.timestep  # the plant's motion, held at its speed
    engine.body_poses(poses)
    return -float(np.mean(pushes[200:])), float(poses[0, 0] - 1.0)


def test_a_pushed_crate_pushes_back_more_the_heavier_it_is():
    light, moved_light = _pushing(5.0)
    heavy, moved_heavy = _pushing(40.0)
    assert 0.0 < light < heavy  # felt through the contact: friction grows with the weight
    assert moved_light > 0.02 and moved_heavy > 0.02  # the crate is pushed ahead of the robot


def test_a_wall_stops_the_plant_and_counts_as_a_collision():
    scene = Scene(walls=(Block3(size_m=(0.1, 4.0, 1.0), position_m=(1.5, 0.0)),), robot=Robot(start=(0.5, 0.0, 0.0)))
    engine = Engine(to_mjcf(scene))
    plant = RopodPlant()
    rx, tx = np.zeros((4, RXPDO_BYTES), np.uint8), np.zeros((4, TXPDO_BYTES), np.uint8)
    plant.reset_state(pose=(0.5, 0.0, 0.0), twist=(0.5, 0.0, 0.0))  # coasting at 0.5 m/s towards the wall
    wrench = np.zeros(3)
    touched, furthest = False, 0.0
    for _ in range(3000):
        engine.place_robot(plant.pose, plant.twist)
        engine.step()
        engine.place_robot(plant.pose)
        touched |= engine.clearance() <= 0.0
        plant.external[:] = engine.contact_wrench(wrench).tolist()
        plant.step(rx, 0.001, tx)
        furthest = max(furthest, float(plant.pose[0]))
    assert touched
    assert plant.twist[0] < 0.01  # stopped (or bounced off), not going on
    assert furthest + 0.35 < 1.45 + 0.01  # its front at the wall's face, give or take the contact's softness


def test_an_exploding_body_stops_the_run_with_one_message():
    scene = Scene(bodies=(Movable(size_m=(0.2, 0.2, 0.2), position_m=(3.0, 0.0), mass_kg=1.0),))
    engine = Engine(to_mjcf(scene))
    engine.qvel[engine.dof_robot[-1] + 1] = 1e7  # the crate thrown
    with pytest.raises(SceneError, match="left the scene"):
        for _ in range(1000):
            engine.step()


def _scans(tmp_path, world, count: int = 3) -> dict[int, np.ndarray]:
    clock = VirtualClock()
    scanner = standalone(Tim561Simulator, "lidar_sim", {"world": "world"}, tmp_path, clock, seed=3)
    scanner.create()
    publish_world(tmp_path, "world", world)
    assert scanner.configure_resources() is True
    client = ColaClient(*published_address(tmp_path, "lidar_sim"), backoff=(0.05, 0.1), clock_ns=clock.now_ns)
    pose = scanner.inputs.pose_in_hallway
    pose.value[:] = (4.0, 0.25, 0.2)
    pose.meta[0] = 1
    ranges, scans = np.zeros(811), {}
    try:
        for _ in range(200):
            clock.advance_to(clock.now_ns() + 66_666_667)
            scanner.compute()
            # by scan counter: on a busy machine a telegram may reach the client a step later
            if client.poll(clock.now_ns()) >= 1 and client.latest_scan(ranges):
                scans[client.header.scan_counter] = ranges.copy()
                if len(scans) == count:
                    return scans
        raise AssertionError("no scans")
    finally:
        client.close()
        scanner.clean()
        withdraw_world(tmp_path, "world")


def test_the_scanner_on_a_scene_sends_the_engines_ray_cast(tmp_path):
    from hapticop.sim.world_share import PublishedScene

    loaded, _ = scene_files.load("H4")
    scene = PublishedScene(loaded.xml, (0.5, 0.0, 0.0), 0.0, 0.05, 10.0, 0.0)  # without noise
    engine, expected = Engine(loaded.xml), np.zeros(811)
    engine.place_robot(np.array([4.0, 0.25, 0.2]))  # where _scans puts the robot
    engine.scan(np.asarray(ANGLES_RAD, dtype=float), expected, 0.05, 10.0)
    scans = _scans(tmp_path, scene, count=3)
    for ranges in scans.values():  # the telegram's millimetres; no echo is 0 on the wire
        assert np.allclose(np.nan_to_num(ranges), np.nan_to_num(expected), atol=1e-3)


def test_the_scene_world_publishes_contact_and_bodies(tmp_path):
    clock = VirtualClock()
    scene = Scene(bodies=(Movable(size_m=(0.4, 0.4, 0.4), position_m=(1.2, 0.0), mass_kg=5.0),),
                  robot=Robot(start=(0.5, 0.0, 0.0)))
    world = standalone(SceneWorld, "world", {"scene": scene.model_dump(), "judge": False}, tmp_path, clock)
    assert set(SceneWorld.declare(SceneWorldParams(scene=scene, judge=False)).outputs) == {
        "pose_in_hallway", "contact_wrench", "collision", "body_poses"}
    world.create()
    robot_pose, twist = world.inputs.robot_pose, world.inputs.robot_twist
    pushed = 0.0
    for i in range(900):
        clock.advance_to(clock.now_ns() + 1_000_000)
        robot_pose.value[:] = (0.3 * i * 1e-3, 0.0, 0.0)  # from its start: into the crate at 0.3 m/s
        twist.value[:] = (0.3, 0.0, 0.0)
        robot_pose.meta[0] = twist.meta[0] = i + 1
        world.compute()
        pushed = min(pushed, float(world.outputs.contact_wrench.value[0]))
    assert pushed < -1.0  # the crate pushes back
    assert world.outputs.body_poses.value[0, 0] > 1.2 + 0.02  # and moves
    assert not world.outputs.collision.value  # a movable body is not a collision
    assert math.isclose(world.outputs.pose_in_hallway.value[0], 0.5 + 0.3 * 899e-3)


def test_the_scene_world_judges_touching_a_wall_a_collision(tmp_path):
    clock = VirtualClock()
    scene = Scene(walls=(Block3(size_m=(0.1, 4.0, 1.0), position_m=(1.5, 0.0)),), robot=Robot(start=(0.5, 0.0, 0.0)))
    world = standalone(SceneWorld, "world", {"scene": scene.model_dump(), "judge": False}, tmp_path, clock)
    world.create()
    robot_pose = world.inputs.robot_pose
    touched = []
    for i, x in enumerate((0.5, 0.59, 0.61)):  # the front at 1.35 + x: clear, clear, into the wall's face at 1.45
        clock.advance_to(clock.now_ns() + 1_000_000)
        robot_pose.value[:] = (x, 0.0, 0.0)
        robot_pose.meta[0] = i + 1
        world.compute()
        touched.append(int(world.outputs.collision.value))
    assert touched == [0, 0, 1]
    assert world.outputs.contact_wrench.value[0] < 0.0  # the wall pushes back


def test_a_composition_naming_hallway_world_is_told_to_use_the_scene_world(tmp_path):
    path = tmp_path / "old.yaml"
    path.write_text("""version: 1
name: old
threads:
  sim:
    period: 1ms
    deploy: main
    schedules: {0: [mediator, world]}
activities:
  mediator: {block: mediator}
  world: {block: hallway_world, params: {hallway: H2, judge: false}}
""")
    (error,) = validate_path(str(path)).report.errors
    assert error.rule == "unknown-block" and error.line == 10 and error.path[-1] == "block"
    assert "scene_world" in error.hint and "scene: H1" in error.hint
