"""The simulated world as a scene on MuJoCo: `scene_world`.

It owns the scene's MuJoCo model and data (hapticop.sim.engine). Each cycle it puts the robot where its
plant says (the plant's pose from its start, composed with the scene's start) moving at the plant's twist,
steps the physics one period, and publishes what the plant and the others need: the robot's pose in the
scene (where the simulated LIDAR scans from), the contacts' wrench on the robot (the plant's external
force: a pushed box slows it, a wall stops it) and the movable bodies' poses (the LIDAR sees them where
they are). The robot touching static geometry is a collision; with the scene's `hallway` task the run is
judged as hallway_world judges it (docs/hallway-experiment.md §5), and by the `targets` declared on the
world with the judge users configure (hapticop.sim.judge, docs/scenes.md §5).
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
from hapticop.sim.judge import Targets
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
    targets: Targets = ()

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
    def findings(cls, params: SceneWorldParams, folder: Path | None) -> list[Diagnostic]:
        loaded, found = _loaded(params, folder)
        if loaded is not None and params.judge and (loaded.scene is None or loaded.scene.hallway is None):
            found.append(Diagnostic("scene-judge", "the run is judged by the hallway experiment's targets, but the "
                                    "scene has no 'hallway' task", ("params", "judge"),
                                    hint="judge: false, or a 'hallway:' section in the scene"))
        if loaded is not None and params.targets:
            found += _target_findings(params, loaded)
        return found

    @classmethod
    def promises(cls, params: SceneWorldParams) -> tuple[str, ...]:
        return super().promises(params) + (("judge.json", "results.json") if params.targets else ())

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
        capacity = self.recorder.capacity
        self.contact = np.zeros(capacity)  # |contact force| on the robot, per recorded sample
        self.body_track = np.zeros((capacity, self.engine.bodies, 3))
        self.body_aliases = _body_aliases(scene if loaded.scene is not None else None, self.engine.body_names)

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
        if (inputs.operator_time.seq or self.params.targets) and not self.ended:
            if self.started_ns is None and not inputs.operator_time.seq:  # no operator: the run is the whole run
                self.started_ns = self.clock.now_ns()
            # a collision ends the run (a crash), unless the scene is judged by targets of its own: then it is counted
            touching = clearance <= 0.0
            self.judge(clearance, touching and (self.params.judge or not self.params.targets))
            i = self.recorder.n - 1
            wrench = self.wrench
            self.contact[i] = math.sqrt(wrench[0] * wrench[0] + wrench[1] * wrench[1])
            if self.bodies is not None:
                self.body_track[i] = self.bodies

    def clean(self) -> None:
        super().clean()
        if self.params.targets and self.recorder.n >= 2:
            self._judge_targets()

    def _judge_targets(self) -> None:
        """judge.json (the generic metrics and each target's verdict) and the rows `hapticop compose` prints."""
        import json

        from hapticop.sim.judge import Run, judge, metric_rows, run_metrics
        from hapticop.sim.metrics import json_plain  # NaN as null: JSON has no such number
        from hapticop.sim.recording import as_channels

        n, d = self.recorder.n, as_channels(self.recorder)
        zeros = np.zeros((n, 3))
        r = self.scene.robot
        run = Run(t=d["t"], pose=d["pose"], clearance=d["clearance"], contact_n=self.contact[:n],
                  handle_force=d.get("force_device", zeros), handle_velocity=d.get("handle_velocity", zeros),
                  bodies=self.body_track[:n], body_names=self.body_aliases, footprint=(r.length_m, r.width_m),
                  ended=self.ended)
        metrics = run_metrics(run)
        rows = judge(run, self.params.targets, metrics)
        ok = all(row["ok"] for row in rows)
        (self.run_dir / "judge.json").write_text(json.dumps(json_plain({"metrics": metrics, "targets": rows, "ok": ok}),
                                                            indent=2))
        self.log.info("targets %s (%d of %d met)", "met" if ok else "missed", sum(r["ok"] for r in rows), len(rows))
        results = self.run_dir / "results.json"
        if self.params.judge and results.exists():  # the hallway's rows first, the scene's targets after
            table = json.loads(results.read_text())
            table["rows"] += rows
        else:
            table = {"title": f"scene {self.name}", "rows": metric_rows(metrics) + rows, "picture": None}
        results.write_text(json.dumps(json_plain(table), indent=2))


def _body_aliases(scene: Scene | None, mjcf_names: list[str]) -> tuple[tuple[str, ...], ...]:
    """Each movable body's names a target may use: its scene name (if it has one) and its MJCF name."""
    if scene is None:
        return tuple((name,) for name in mjcf_names)
    return tuple(((b.name,) if b.name else ()) + (f"bodies[{i}]",) for i, b in enumerate(scene.bodies))


def _target_findings(params: SceneWorldParams, loaded) -> list[Diagnostic]:
    """A target naming a body the scene does not have, located at the name."""
    if loaded.scene is not None:
        aliases = _body_aliases(loaded.scene, [])
    else:
        from hapticop.sim.engine import Engine

        aliases = _body_aliases(None, Engine(loaded.xml).body_names)
    from hapticop.sim.judge import body_index

    found = []
    for i, target in enumerate(params.targets):
        push = target.push_body
        if push is not None and body_index(aliases, push.body) is None:
            known = ", ".join(a[0] for a in aliases) or "none"
            found.append(Diagnostic("scene-target", f"push_body names {push.body!r}, which is no movable body of "
                                    f"the scene", ("params", "targets", i, "push_body", "body"),
                                    expected=f"one of: {known}"))
    return found


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
