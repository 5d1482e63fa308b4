"""The simulated world as a scene on MuJoCo: `scene_world`.

It owns the scene's MuJoCo model and data (hapticop.sim.engine). Each cycle it puts the robot where its
plant says (the plant's pose from its start, composed with the scene's start) moving at the plant's twist,
steps the physics one period, and publishes what the plant and the others need: the robot's pose in the
scene (where the simulated LIDAR scans from), the contacts' wrench on the robot (the plant's external
force: a pushed box slows it, a wall stops it) and the movable bodies' poses (the LIDAR sees them where
they are). The robot touching static geometry is a collision; with the scene's `hallway` task the run is
judged as hallway_world judges it (docs/hallway-experiment.md §5).
"""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path
from typing import Literal

import numpy as np
from pydantic import Field, model_validator

from hapticop.blocks.interface import Display, Interface, Port
from hapticop.composition.diagnostics import Diagnostic
from hapticop.sim.scene import Scene
from hapticop.sim.world import HallwayWorld, HallwayWorldParams


class SceneWorldParams(HallwayWorldParams):
    hallway: Literal["H1", "H2", "H3", "H4", "H5", "H6"] | None = Field(
        None, description="the shipped scene of that hallway (docs/hallway-experiment.md §2): `scene: H2` said as "
        "hallway_world says it")
    operator: str | None = Field(None, description="the activity whose run this world judges (block "
                                 "blind_operator): its variant sets the targets")
    scene: str | Scene = Field("H1", description="the scene: written here, or a scene file (a shipped name such as "
                               "'H1', or a path beside the composition; .yaml, or .xml for MJCF): docs/scenes.md")

    @model_validator(mode="after")
    def _hallway_names_the_scene(self) -> SceneWorldParams:
        if self.hallway is not None:
            if "scene" in self.model_fields_set and self.scene != self.hallway:
                raise ValueError(f"hallway {self.hallway} and scene {self.scene!r} say different things: give one")
            object.__setattr__(self, "scene", self.hallway)
        return self


def _loaded(params: SceneWorldParams, folder: Path | None = None):
    from hapticop.sim import scene_files

    return scene_files.load(params.scene, folder, ("params", "scene"))


def _count_bodies(params: SceneWorldParams) -> int:
    """Movable bodies of the scene, for the shape of `body_poses` (0 when it cannot be read: validation says why)."""
    if isinstance(params.scene, Scene):
        return len(params.scene.bodies)
    loaded, _ = _loaded(params)
    if loaded is None:
        return 0
    if loaded.scene is not None:
        return len(loaded.scene.bodies)
    from hapticop.sim.engine import Engine

    return Engine(loaded.xml).bodies


class SceneWorld(HallwayWorld):
    Params = SceneWorldParams
    outputs = {}

    @classmethod
    def interface(cls, params: SceneWorldParams) -> Interface:
        outputs = {
            "pose_in_hallway": Port("float64", (3,), "m, m, rad", "the robot's pose in the scene (x, y, theta "
                                    "counter-clockwise)"),
            "contact_wrench": Port("float64", (3,), "N, N, N m", "the contacts' force and torque on the robot, in its "
                                   "frame (the plant's external force)"),
            "collision": Port("uint8", (), "1", "1 while the robot touches static geometry"),
        }
        bodies = _count_bodies(params)
        if bodies:
            outputs["body_poses"] = Port("float64", (bodies, 3), "m, m, rad", "each movable body's x, y and yaw, "
                                         "in the order the scene lists them")
        base = super().interface(params)
        inputs = dict(base.inputs)
        if not params.judge:  # nobody's run to judge: the operator's ports may stay unconnected
            for name in ("operator_time", "operator_done"):
                inputs[name] = dataclasses.replace(inputs[name], required=False)
        return Interface(inputs=inputs, outputs=outputs, flags_written=base.flags_written, rate=base.rate)

    @classmethod
    def promises(cls, params: SceneWorldParams) -> tuple[str, ...]:
        if not params.judge and params.operator is None:  # no operator's clock to keep a trajectory by: the
            return ()                                      # streams (--record) are the run's record
        return super().promises(params)

    @classmethod
    def findings(cls, params: SceneWorldParams, folder: Path | None) -> list[Diagnostic]:
        loaded, found = _loaded(params, folder)
        if loaded is not None and params.judge and (loaded.scene is None or loaded.scene.hallway is None):
            found.append(Diagnostic("scene-judge", "the run is judged by the hallway experiment's targets, but the "
                                    "scene has no 'hallway' task", ("params", "judge"),
                                    hint="judge: false, or a 'hallway:' section in the scene"))
        return found

    @classmethod
    def displays(cls, params: SceneWorldParams) -> tuple[Display, ...]:
        return (Display("frames", {"pose": "pose_in_hallway"}),)

    def create(self) -> None:
        from hapticop.sim.engine import Engine
        from hapticop.sim.world_share import PublishedScene, publish_world

        loaded, found = _loaded(self.params)
        if loaded is None:
            raise ValueError("; ".join(d.to_text() for d in found))
        self.scene = scene = loaded.scene or Scene()
        self.engine = Engine(loaded.xml, self.name)
        self.geometry = _judged_geometry(scene)
        start = scene.robot.start
        self.start = (start[0], start[1], math.radians(start[2]))
        lidar = scene.robot.lidar
        publish_world(self.run_dir, self.name, PublishedScene(loaded.xml, self.start, lidar.noise_sigma_m,
                                                           lidar.min_range_m, lidar.max_range_m,
                                                           math.radians(lidar.yaw_deg)))
        out = self.outputs
        self.prepare(out.pose_in_hallway.value)
        self.pose[:] = self.start
        self.wrench = out.contact_wrench.value
        self.bodies = out.body_poses.value if self.engine.bodies else None
        self.engine.place_robot(self.pose)
        self.twist = np.zeros(3)

    def compute(self) -> None:
        inputs, engine, out = self.inputs, self.engine, self.outputs
        if inputs.robot_pose.seq:
            from hapticop.sim.world import place

            place(self.start, inputs.robot_pose.value, self.pose)
        engine.place_robot(self.pose, inputs.robot_twist.value if inputs.robot_twist.seq else None)
        engine.step()
        engine.place_robot(self.pose)  # the step moved the robot's joints; the plant moves the robot
        clearance = engine.clearance()
        engine.contact_wrench(self.wrench)
        out.collision.value[...] = clearance <= 0.0
        out.pose_in_hallway.publish()
        out.contact_wrench.publish()
        out.collision.publish()
        if self.bodies is not None:
            engine.body_poses(self.bodies)
            out.body_poses.publish()
        if inputs.operator_time.seq and not self.ended:
            self.judge(clearance, clearance <= 0.0)


def _judged_geometry(scene: Scene):
    """The hallway experiment's task constants for the judge (metrics and targets) from the scene."""
    from hapticop.devices.ropod.body import Footprint
    from hapticop.sim.hallway import HallwayGeometry, LidarModel, Pillar, SensorMount

    r, task = scene.robot, scene.hallway
    lidar = LidarModel(mount=SensorMount(x_m=r.lidar.x_m, y_m=r.lidar.y_m, yaw_rad=math.radians(r.lidar.yaw_deg)),
                       noise_sigma_m=r.lidar.noise_sigma_m, min_range_m=r.lidar.min_range_m,
                       max_range_m=r.lidar.max_range_m)
    common = dict(start=(r.start[0], r.start[1], math.radians(r.start[2])), lidar=lidar,
                  footprint=Footprint(length_m=r.length_m, width_m=r.width_m))
    if task is None:
        return HallwayGeometry(name="scene", **common)
    return HallwayGeometry(name=task.name, width_m=task.width_m, length_m=task.length_m,
                           entrance_x_m=task.entrance_x_m, dist1_m=task.dist1_m, dist2_m=task.dist2_m,
                           dist3_m=task.dist3_m, pillars=tuple(Pillar(p.x_m, p.along_m, p.depth_m, p.side)
                                                               for p in task.pillars), **common)
