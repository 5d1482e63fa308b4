"""Scenes on MuJoCo: the six hallways as scene files, located findings for broken scenes, contact
pushed back to the robot, and the simulated TiM561 scanning a scene as it scanned the hallway."""

from __future__ import annotations

import math

import numpy as np
import pytest

from hapticop.devices.link import published_address
from hapticop.devices.memory_stream import MEMORY_SOCKETS
from hapticop.devices.ropod.pdo import RXPDO_BYTES, TXPDO_BYTES
from hapticop.devices.ropod.plant import RopodPlant
from hapticop.devices.sick.client import ColaClient
from hapticop.devices.sick.device_model import ANGLES_RAD
from hapticop.runtime.clock import VirtualClock
from hapticop.sim import scene_files
from hapticop.sim.devices.tim561 import Tim561Simulator
from hapticop.sim.engine import Engine, SceneError
from hapticop.sim.scene import Block3, Movable, Robot, Scene, to_mjcf
from hapticop.sim.scene_world import SceneWorld, SceneWorldParams
from hapticop.sim.world_share import publish_world, withdraw_world
from hapticop.validation import validate_path

from .runtime_helpers import standalone

HALLWAYS = ("H1", "H2", "H3", "H4", "H5", "H6")


SIZES = {"H1": (2.0, 10.0), "H2": (2.0, 10.0), "H3": (1.5, 8.0), "H4": (2.0, 10.0), "H5": (2.0, 10.0),
         "H6": (2.0, 20.0)}
"""Each hallway's width and end wall (docs/hallway-experiment.md §2); H4's pillar stands 0.25 m out of the
right wall over x 4.8 to 5.2."""


def _slab_ranges(origin, angles, boxes, low=0.05, high=10.0):
    """Where each beam from `origin` first enters one of the axis-aligned `boxes` ((x0, x1, y0, y1)), by the
    slab method: an independent check of MuJoCo's ray cast. NaN outside [low, high]."""
    dx, dy = np.cos(angles), np.sin(angles)
    best = np.full(len(angles), np.inf)
    with np.errstate(divide="ignore", invalid="ignore"):
        for x0, x1, y0, y1 in boxes:
            tx0, tx1 = (x0 - origin[0]) / dx, (x1 - origin[0]) / dx
            ty0, ty1 = (y0 - origin[1]) / dy, (y1 - origin[1]) / dy
            enter = np.maximum(np.minimum(tx0, tx1), np.minimum(ty0, ty1))
            leave = np.minimum(np.maximum(tx0, tx1), np.maximum(ty0, ty1))
            best = np.where((enter <= leave) & (enter > 0) & (enter < best), enter, best)
    return np.where((best >= low) & (best <= high), best, np.nan)


@pytest.mark.parametrize("name", HALLWAYS)
def test_each_hallway_scene_scans_and_measures_as_its_dimensions_say(name):
    loaded, found = scene_files.load(name)
    assert found == [] and loaded is not None
    engine = Engine(loaded.xml)
    width, length = SIZES[name]
    h = 0.5 * width
    boxes = [(0.0, length, h, h + 0.1), (0.0, length, -h - 0.1, -h), (length, length + 0.1, -h - 0.1, h + 0.1)]
    if name == "H4":
        boxes.append((4.8, 5.2, -1.0, -0.75))
    angles = np.asarray(ANGLES_RAD, dtype=float)
    ranges = np.zeros(len(angles))
    start = loaded.scene.robot.start
    for x, y, theta in ((start[0], start[1], math.radians(start[2])), (length - 1.5, 0.2, 0.3),
                        (length / 2 - 2.0, -0.3, -0.5)):
        engine.place_robot(np.array([x, y, theta]))
        engine.scan(angles, ranges, 0.05, 10.0)
        expected = _slab_ranges((x + 0.25 * math.cos(theta), y + 0.25 * math.sin(theta)), angles + theta, boxes)
        assert np.array_equal(np.isnan(ranges), np.isnan(expected))
        assert np.nanmax(np.abs(ranges - expected)) < 1e-9
        # the footprint's corners nearest the end wall and a side wall (no pillar is as near at these poses)
        reach_x = 0.35 * abs(math.cos(theta)) + 0.30 * abs(math.sin(theta))
        reach_y = 0.35 * abs(math.sin(theta)) + 0.30 * abs(math.cos(theta))
        assert engine.clearance() == pytest.approx(min(length - x - reach_x, h - abs(y) - reach_y), abs=1e-9)


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


def test_a_scene_beside_the_composition_is_the_one_run_whatever_the_working_folder_holds(tmp_path):
    """Validation reads the scene beside the composition; so must the run, even when the folder it is started
    from (first on Python's search path under `python -m`) has a file of the same name."""
    import subprocess
    import sys

    app = tmp_path / "app"
    app.mkdir()
    composition = _write(app, ROOM)
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    (elsewhere / "room.yaml").write_text("walls: [not a wall]\n")
    done = subprocess.run([sys.executable, "-m", "hapticop.cli", "compose", composition, "--clock", "virtual",
                           "--duration", "50ms", "--run-dir", str(tmp_path / "run")], cwd=elsewhere,
                          capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stdout[-2000:] + done.stderr[-2000:]


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
    client = ColaClient(*published_address(tmp_path, "lidar_sim"), backoff=(0.05, 0.1), clock_ns=clock.now_ns,
                        sockets=MEMORY_SOCKETS)  # under the virtual clock the simulator serves in memory
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


DESK = """walls:
  - {name: wall, size_m: [0.6, 0.1, 0.6], position_m: [0.0, 0.075]}
handles:
  - {name: tip, origin_m: [0.0, 0.0, 0.3], axes: [-y, z, -x]}
robot: {start: [-2.0, 0.0, 0.0]}
"""


@pytest.mark.parametrize("change, rule, line, field", [
    (("axes: [-y, z, -x]}\n", "axes: [-y, z, -x]}\n  - {name: tip, origin_m: [0.0, -0.2, 0.3]}\n"), "scene-handle", 5,
     "handles.1.name"),
    (("origin_m: [0.0, 0.0, 0.3]", "origin_m: [0.0, 0.07, 0.3]"), "scene-start-inside", 4, "handles.0.origin_m"),
    (("axes: [-y, z, -x]", "axes: [y, z, -x]"), "model", 4, "handles.0.axes"),
    (("axes: [-y, z, -x]", "axes: [y, y, -x]"), "model", 4, "handles.0.axes"),
    (("axes: [-y, z, -x]", "axes: [-y, z, w]"), "model", 4, "handles.0.axes"),
    (("name: tip", "name: Tip-1"), "model", 4, "handles.0.name"),
])
def test_a_wrong_handle_is_one_finding_located_in_the_scene_file(tmp_path, change, rule, line, field):
    old, new = change
    path = tmp_path / "desk.yaml"
    path.write_text(DESK.replace(old, new))
    loaded, found = scene_files.load(str(path))
    assert loaded is None and len(found) == 1, [d.to_text() for d in found]
    [finding] = found
    assert (finding.line, finding.dotted_path, finding.file) == (line, field, str(path)), finding.to_text()
    assert rule == "model" or finding.rule == rule


def test_the_desk_with_a_handle_loads():
    path_found = scene_files.load("desk.yaml", _desk_folder())
    assert path_found[1] == [] and path_found[0].scene.handles[0].name == "tip"


def _desk_folder():
    import tempfile
    from pathlib import Path

    folder = Path(tempfile.mkdtemp())
    (folder / "desk.yaml").write_text(DESK)
    return folder


def test_a_handles_contact_is_the_declared_spring_and_damper_in_the_devices_frame():
    """The wall's face is at scene y = 0.025, the handle's sphere (5 mm) at the device's origin when the device is
    at its origin; the device is turned (its z is the scene's -x, its x the scene's -y): pushing the device
    along its -x moves the tip into the wall, and the wall pushes back along the device's +x."""
    from hapticop.sim.scene import Handle

    handle = Handle(name="tip", origin_m=(0.0, 0.0, 0.3), axes=("-y", "z", "-x"), stiffness_n_per_m=3000.0,
                    damping_ns_per_m=4.0, mass_kg=0.2)
    scene = Scene(walls=(Block3(size_m=(0.6, 0.1, 0.6), position_m=(0.0, 0.075)),), handles=(handle,),
                  robot=Robot(start=(-2.0, 0.0, 0.0)))
    engine = Engine(to_mjcf(scene))
    assert engine.handles == ["tip"]
    force = np.zeros(3)
    for x in (0.0, -0.019, -0.021, -0.025):
        for vx in (-0.2, 0.0, 0.05, 0.5):
            engine.place_handle(0, np.array([x, 0.0, 0.0]), np.array([vx, 0.0, 0.0]))
            engine.step()
            engine.handle_force(0, force)
            depth = -0.02 - x
            expected = max(3000.0 * depth + 4.0 * -vx, 0.0) if depth >= 0 else 0.0
            assert force[0] == pytest.approx(expected, abs=1e-6), (x, vx)
            assert abs(force[1]) < 1e-9 and abs(force[2]) < 1e-9
    # without a velocity the handle is at rest: the spring alone
    engine.place_handle(0, np.array([-0.022, 0.0, 0.0]))
    engine.step()
    assert engine.handle_force(0, force)[0] == pytest.approx(6.0, abs=1e-6)


def test_the_scene_world_has_a_handles_ports_and_ignores_a_position_not_finite(tmp_path):
    from hapticop.sim.scene import Handle

    clock = VirtualClock()
    scene = Scene(walls=(Block3(size_m=(0.6, 0.1, 0.6), position_m=(0.0, 0.075)),),
                  handles=(Handle(name="tip", origin_m=(0.0, 0.0, 0.3), axes=("-y", "z", "-x")),),
                  robot=Robot(start=(-2.0, 0.0, 0.0)))
    declared = SceneWorld.declare(SceneWorldParams(scene=scene, judge=False))
    assert {"tip_handle_position", "tip_handle_velocity"} <= set(declared.inputs)
    assert not declared.inputs["tip_handle_velocity"].required and "tip_handle_force" in declared.outputs
    world = standalone(SceneWorld, "world", {"scene": scene.model_dump(), "judge": False}, tmp_path, clock)
    world.create()
    position, force = world.inputs.tip_handle_position, world.outputs.tip_handle_force
    felt = []
    for i, x in enumerate((0.0, -0.021, float("nan"), 1e6)):  # free, 1 mm in, then two samples not taken
        clock.advance_to(clock.now_ns() + 1_000_000)
        position.value[:] = (x, 0.0, 0.0)
        position.meta[0] = i + 1
        world.compute()
        felt.append(float(force.value[0]))
    assert felt[0] == 0.0
    assert felt[1] == pytest.approx(2.0, abs=1e-6) and felt[2:] == pytest.approx([2.0, 2.0], abs=1e-6)
