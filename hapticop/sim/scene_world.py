"""The simulated world as a scene on MuJoCo: `scene_world`.

It owns the scene's MuJoCo model and data (hapticop.sim.engine). Each cycle it puts the robot where its
plant says (the plant's pose from its start, composed with the scene's start) moving at the plant's twist,
steps the physics one period, and publishes what the plant and the others need: the robot's pose in the
scene (where the simulated LIDAR scans from), the contacts' wrench on the robot (the plant's external
force: a pushed box slows it, a wall stops it) and the movable bodies' poses (the LIDAR sees them where
they are). The robot touching static geometry is a collision. Once the operator drives it records the run
(robot pose and velocity, handle, forces, clearance) and raises `finished` when the operator is done and
the robot still, the robot crashes, or time is up. It is judged by the targets its scene and its params
declare, with the judge users configure (hapticop.sim.judge, docs/scenes.md §5); with the scene's
`hallway` task, on the hallway experiment's metrics among them (docs/hallway-experiment.md §5, §6).
"""

from __future__ import annotations

import dataclasses
import json
import math
from pathlib import Path
from typing import Literal

import numpy as np
from pydantic import Field, model_validator

from hapticop.blocks.base import Block
from hapticop.blocks.interface import Display, Interface, Params, Port
from hapticop.composition.diagnostics import Diagnostic
from hapticop.sim.judge import STILL_MPS, STILL_S, Target, Targets
from hapticop.sim.scene import Scene


class SceneWorldParams(Params):
    hallway: Literal["H1", "H2", "H3", "H4", "H5", "H6"] | None = Field(
        None, description="the shipped scene of that hallway (docs/hallway-experiment.md §2): the same as "
        "`scene: H2`")
    operator: str | None = Field(None, description="the activity whose run this world judges (block "
                                 "blind_operator): its variant sets the targets")
    scene: str | Scene = Field("H1", description="the scene: written here, or a scene file (a shipped name such as "
                               "'H1', or a path relative to the composition's folder; .yaml, or .xml for MJCF): "
                               "docs/scenes.md")
    targets: Targets = ()
    time_limit_s: float = Field(90.0, gt=0, description="the run ends here at the latest")
    plot: bool = Field(True, description="draw the run to run.png (needs matplotlib)")
    judge: bool = Field(True, description="judge the run as a hallway run: the scene's hallway task's metrics "
                        "(metrics.json) with the verdicts of the targets on them; false for an application that "
                        "does not drive the robot down a hallway (the desk): its trajectory is kept, the scene's "
                        "targets do not apply, only the world's own `targets` are judged")

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
    return _scene_parts(params)[0]


def _scene_parts(params: SceneWorldParams) -> tuple[int, tuple[str, ...]]:
    """The scene's movable bodies (how many) and handles (their names), for the world's ports; none when it
    cannot be read (validation says why)."""
    if isinstance(params.scene, Scene):
        return len(params.scene.bodies), tuple(h.name for h in params.scene.handles)
    loaded, _ = _loaded(params)
    if loaded is None:
        return 0, ()
    if loaded.scene is not None:
        return len(loaded.scene.bodies), tuple(h.name for h in loaded.scene.handles)
    from hapticop.sim.engine import Engine

    engine = Engine(loaded.xml)
    return engine.bodies, tuple(engine.handles)


def _handle_ports(name: str) -> tuple[dict[str, Port], dict[str, Port]]:
    """A handle's ports on the world: its device's position and velocity in, the contacts' force out."""
    return ({f"{name}_handle_position": Port("float64", (3,), "m", f"where handle '{name}' is: its device's "
                                             "position, device frame"),
             f"{name}_handle_velocity": Port("float64", (3,), "m/s", f"handle '{name}''s velocity, device frame "
                                             "(unconnected: at rest)", required=False)},
            {f"{name}_handle_force": Port("float64", (3,), "N", f"the contacts' force on handle '{name}', device "
                                          "frame")})


class SceneWorld(Block):
    Params = SceneWorldParams
    simulator = True  # everything it does is the simulation
    provides = frozenset({"hallway"})
    needs = {"operator": "operator"}
    inputs = {
        "robot_pose": Port("float64", (3,), "m, m, rad", "the simulated robot's pose from its start", required=False),
        "robot_twist": Port("float64", (3,), "m/s, m/s, rad/s", "the simulated robot's twist", required=False),
        "velocity_setpoint": Port("float64", (3,), "m/s, m/s, rad/s", "the commanded twist", required=False),
        "executed_setpoint": Port("float64", (3,), "m/s, m/s, rad/s", "the twist a safety layer let through of "
                                  "the command (shared control): its authority is measured", required=False),
        "environment_force": Port("float64", (3,), "N", "the obstacle force on the handle", required=False),
        "device_force": Port("float64", (3,), "N", "the whole force the Falcon renders", required=False),
        "hand_force": Port("float64", (3,), "N", "the operator's hand on the grip", required=False),
        "tank_level": Port("float64", (), "J", "an energy tank's level on the Falcon's port: its lowest goes "
                           "into the metrics", required=False),
        "round_trip": Port("float64", (), "s", "a link's measured round trip: its largest goes into the metrics",
                           required=False),
        "link_jitter": Port("float64", (), "s", "a link's measured jitter: its largest goes into the metrics",
                            required=False),
        "link_loss": Port("float64", (), "1", "a link's measured loss: its largest goes into the metrics",
                          required=False),
        "handle_position": Port("float64", (3,), "m", "true handle position, device frame", required=False),
        "handle_velocity": Port("float64", (3,), "m/s", "true handle velocity, device frame", required=False),
        "operator_time": Port("float64", (), "s", "seconds the operator has driven: the recording's clock"),
        "operator_done": Port("uint8", (), "1", "the operator believes the task is over"),
    }
    outputs = {}
    flags_written = {"finished": "the operator is done, the robot crashed, time is up, or the simulation exploded"}

    @classmethod
    def interface(cls, params: SceneWorldParams) -> Interface:
        outputs = {
            "pose_in_hallway": Port("float64", (3,), "m, m, rad", "the robot's pose in the scene (x, y, theta "
                                    "counter-clockwise)"),
            "contact_wrench": Port("float64", (3,), "N, N, N m", "the contacts' force and torque on the robot, in its "
                                   "frame (the plant's external force)"),
            "collision": Port("uint8", (), "1", "1 while the robot touches static geometry"),
        }
        bodies, handles = _scene_parts(params)
        if bodies:
            outputs["body_poses"] = Port("float64", (bodies, 3), "m, m, rad", "each movable body's x, y and yaw, "
                                         "in the order the scene lists them")
        base = super().interface(params)
        inputs = dict(base.inputs)
        for name in handles:
            handle_in, handle_out = _handle_ports(name)
            inputs.update(handle_in)
            outputs.update(handle_out)
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
        """The trajectory (when an operator's clock or targets keep it); the hallway's metrics, the targets'
        verdicts and the picture when judged."""
        targets = _scene_targets(params)
        if not params.judge and not targets and params.operator is None:
            return ()  # nothing keeps a trajectory: the streams (--record) are the run's record
        promised = ["trajectory.npz"]
        if params.judge:
            promised += ["metrics.json", "results.json"]
        if targets:
            promised += ["judge.json", "results.json"]
        if params.plot and (params.judge or targets):
            promised.append("run.png")
        return tuple(dict.fromkeys(promised))

    @classmethod
    def displays(cls, params: SceneWorldParams) -> tuple[Display, ...]:
        return (Display("frames", {"pose": "pose_in_hallway"}),)

    def create(self) -> None:
        from hapticop.sim.engine import Engine
        from hapticop.sim.hallway_task import Hallway
        from hapticop.sim.world_share import PublishedScene, publish_world

        loaded, found = _loaded(self.params)
        if loaded is None:
            raise ValueError("; ".join(d.to_text() for d in found))
        self.loaded = loaded
        self.scene = scene = loaded.scene or Scene()
        self.engine = Engine(loaded.xml, self.name)
        self.hallway = Hallway.of(scene, loaded.xml) if scene.hallway is not None else None
        self.front = self.hallway.front if self.hallway is not None else None  # the end wall, for its clearance
        # the scene's targets and the world's: the hallway's table judges the bounds on its metrics, the rest
        # are the judge's rows (judge.json)
        self.targets = _all_targets(self.params, scene)
        self.scene_targets = _generic(self.params, scene, self.targets)
        shared = PublishedScene.of(scene, loaded.xml)
        self.start = shared.start
        publish_world(self.run_dir, self.name, shared)
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
        self.handles = [(getattr(self.inputs, f"{n}_handle_position"), getattr(self.inputs, f"{n}_handle_velocity"),
                         getattr(out, f"{n}_handle_force"), np.zeros(3)) for n in self.engine.handles]

    def compute(self) -> None:
        inputs, engine, out = self.inputs, self.engine, self.outputs
        if inputs.robot_pose.seq:
            place(self.start, inputs.robot_pose.value, self.pose)
        engine.place_robot(self.pose, inputs.robot_twist.value if inputs.robot_twist.seq else None)
        self._place_handles()
        try:
            engine.step()
        except RuntimeError as error:  # SceneError: said where the scene declares what exploded
            raise self._located(error) from None
        engine.place_robot(self.pose)  # the step moved the robot's joints; the plant moves the robot
        clearance, self.front_clearance, self.side_clearance = engine.clearances(self.front)
        engine.contact_wrench(self.wrench)
        out.collision.value[...] = clearance <= 0.0
        out.pose_in_hallway.publish()
        out.contact_wrench.publish()
        out.collision.publish()
        if self.bodies is not None:
            engine.body_poses(self.bodies)
            out.body_poses.publish()
        for i, (_, _, force, _) in enumerate(self.handles):
            engine.handle_force(i, force.value)
            force.publish()
        if (inputs.operator_time.seq or self.scene_targets) and not self.ended:
            if self.started_ns is None and not inputs.operator_time.seq:  # no operator: the run is the whole run
                self.started_ns = self.clock.now_ns()
            # a collision ends the run (a crash), unless the scene is judged by targets of its own: then it is counted
            touching = clearance <= 0.0
            self.judge(clearance, touching and (self.params.judge or not self.scene_targets))
            i = self.recorder.n - 1
            wrench = self.wrench
            self.contact[i] = math.sqrt(wrench[0] * wrench[0] + wrench[1] * wrench[1])
            if self.bodies is not None:
                self.body_track[i] = self.bodies

    def _located(self, error: RuntimeError) -> RuntimeError:
        """A scene's explosion said once, where the scene declares what exploded, and `finished` raised (a
        running failure alone does not end a run); anything else as it is."""
        from hapticop.sim.engine import SceneError

        if not isinstance(error, SceneError):
            return error
        where = self.loaded.where(error.body, f"activities.{self.name}.params.scene")
        self.ended = "the simulation exploded"
        self.flags["finished"] = True  # nothing simulated is real any more: the composition ends the run on it
        return SceneError(f"{where}: {error}", error.body)

    def _place_handles(self) -> None:
        """Each handle where its device last said, moving at its velocity; a position that is not finite or
        beyond 10 m is not taken (the handle stays where it was)."""
        for i, (position, velocity, _, last) in enumerate(self.handles):
            if position.seq:
                p = position.value
                x, y, z = float(p[0]), float(p[1]), float(p[2])
                if abs(x) < 10.0 and abs(y) < 10.0 and abs(z) < 10.0:  # also false for NaN
                    last[0], last[1], last[2] = x, y, z
            v = velocity.value
            moving = velocity.valid and abs(float(v[0])) + abs(float(v[1])) + abs(float(v[2])) < 100.0
            self.engine.place_handle(i, last, v if moving else None)

    def clean(self) -> None:
        self._hallway_clean()
        if self.scene_targets and self.recorder.n >= 2:
            self._judge_targets()

    def prepare(self, pose: np.ndarray) -> None:
        """The judge's state; `pose` is the output the robot's pose goes to."""
        from hapticop.sim.recording import TrajectoryRecorder

        p = self.params
        self.recorder = TrajectoryRecorder(int(p.time_limit_s * 1000) + 1000,
                                           meta={"hallway": self.hallway.name if self.hallway else "scene"})
        self.pose = pose
        self.started_ns: int | None = None  # when the operator started driving, on the system's clock
        self.ended = ""
        self.still_since: float | None = None
        self.velocity = np.zeros(2)  # (v, omega): the recorder's unicycle view of a twist
        self.command = np.zeros(2)
        self.executed = np.zeros(2)
        self.nothing = np.zeros(3)
        self.variant = "unknown"  # the operator's, once it has said (clean)
        # What only some compositions measure, its extreme while driving kept for metrics.json (infinite: never
        # measured): (key, input, whether the lowest is kept, else the highest)
        inputs = self.inputs
        self.watched = (("tank_level_min_j", inputs.tank_level, True), ("round_trip_max_s", inputs.round_trip, False),
                        ("link_jitter_max_s", inputs.link_jitter, False), ("link_loss_max", inputs.link_loss, False))
        self.extremes = {key: math.inf if lowest else -math.inf for key, _, lowest in self.watched}


    def judge(self, clearance: float, crashed: bool) -> None:
        """Record this cycle once the operator drives, and end the run when its time has come."""
        inputs = self.inputs
        driven = inputs.operator_time
        now = self.clock.now_ns()
        if self.started_ns is None:  # the recording's time 0: when the operator started, on the system's clock
            self.started_ns = driven.stamp_ns - round(float(driven.value) * 1e9)
            self.recorder.meta["operator_start_ns"] = self.started_ns
        t = (now - self.started_ns) / 1e9
        vx, vy, wz = inputs.robot_twist.value.tolist()  # floats: numpy scalars are slow to compare
        self.velocity[0], self.velocity[1] = vx, wz
        setpoint = inputs.velocity_setpoint.value
        self.command[0], self.command[1] = setpoint[0], setpoint[2]
        executed = inputs.executed_setpoint
        if executed.seq:
            self.executed[0], self.executed[1] = executed.value[0], executed.value[2]
        force = inputs.environment_force
        extremes = self.extremes
        for key, port, lowest in self.watched:
            if port.seq:
                value = float(port.value)
                if value < extremes[key] if lowest else value > extremes[key]:
                    extremes[key] = value
        self.recorder.append(t, self.pose, robot_velocity=self.velocity, cmd=self.command,
                             cmd_exec=self.executed if executed.seq else None,
                             handle_position=inputs.handle_position.value, handle_velocity=inputs.handle_velocity.value,
                             force_env=force.value if force.valid else self.nothing, force_hand=inputs.hand_force.value,
                             force_device=inputs.device_force.value, clearance=clearance,
                             front_clearance=self.front_clearance if self.front is not None else None,
                             side_clearance=self.side_clearance if self.front is not None else None)
        moving = abs(vx) >= STILL_MPS or abs(vy) >= STILL_MPS
        self.still_since = None if moving else (t if self.still_since is None else self.still_since)
        still = self.still_since is not None and t - self.still_since >= STILL_S
        if crashed:
            self.ended = "crash"
        elif inputs.operator_done.value and still:  # the judge's rule: stopped, and still for a while
            self.ended = "operator done"
        elif t >= self.params.time_limit_s:
            self.ended = "time limit"
        if self.ended:  # its time is told once, from the metrics, when the world cleans
            self.log.always("run judged over: %s", self.ended)
            self.flags["finished"] = True


    def _hallway_clean(self) -> None:
        from hapticop.sim.metrics import compute_metrics, metrics_json
        from hapticop.sim.world_share import find_operator, withdraw_world

        withdraw_world(self.run_dir, self.name)
        if self.recorder.n < 2:
            return
        operator = (find_operator(self.run_dir, self.params.operator) if self.params.operator else None) or {}
        self.variant = str(operator.get("variant", self.variant))
        self.recorder.meta.update(operator=self.variant, variation=operator.get("variation"))
        self.recorder.save(self.run_dir / "trajectory.npz")
        if not self.params.judge:
            self.log.info("not a hallway run: trajectory kept, nothing judged")
            return
        metrics = compute_metrics(self.recorder, self.hallway, v_cruise_mps=_cruise_speed(operator))
        extra = {key: value for key, value in self.extremes.items() if math.isfinite(value)}
        (self.run_dir / "metrics.json").write_text(metrics_json(metrics, extra or None))
        self.log.always("run ended at %.3f s after the operator started: %s", end_time_s(metrics, self.recorder),
                        metrics.ended_by)
        if self.params.plot:
            try:
                from hapticop.sim.plot import plot_run

                plot_run(self.recorder, self.hallway, self.run_dir / "run.png",
                         title=f"{self.hallway.name}, {self.variant} operator")
            except RuntimeError as error:  # matplotlib missing: the numbers are still there
                self.log.warning("no picture of the run: %s", error)
        self._results(metrics)


    def _results(self, m) -> None:
        """The rows `hapticop compose` prints at the end (results.json: any block may leave one)."""
        from hapticop.sim.targets import judged_rows

        results = {"title": f"hallway {self.hallway.name}, {self.variant} operator",
                   "rows": judged_rows(m, self.hallway, self.variant, self.targets, end_time_s(m, self.recorder)),
                   "picture": "run.png" if (self.run_dir / "run.png").exists() else None}
        (self.run_dir / "results.json").write_text(json.dumps(results, indent=2))

    def _plot_scene(self) -> str | None:
        """run.png: the path among the scene's static geometry (drawn from the compiled scene)."""
        if not self.params.plot:
            return None
        from hapticop.devices.ropod.body import Footprint
        from hapticop.sim.plot import plot_run, scene_outlines

        r = self.scene.robot
        try:
            plot_run(self.recorder, None, self.run_dir / "run.png", walls=scene_outlines(self.engine),
                     footprint=Footprint(length_m=r.length_m, width_m=r.width_m), title=f"scene of {self.name}")
        except RuntimeError as error:  # matplotlib missing: the numbers are still there
            self.log.warning("no picture of the run: %s", error)
            return None
        return "run.png"

    def _judge_targets(self) -> None:
        """judge.json (the generic metrics and each target's verdict) and the rows `hapticop compose` prints."""
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
        rows = judge(run, self.scene_targets, metrics, self.variant)
        ok = all(row["ok"] for row in rows)
        (self.run_dir / "judge.json").write_text(json.dumps(json_plain({"metrics": metrics, "targets": rows, "ok": ok}),
                                                            indent=2))
        self.log.info("targets %s (%d of %d met)", "met" if ok else "missed", sum(r["ok"] for r in rows), len(rows))
        results = self.run_dir / "results.json"
        if self.params.judge and results.exists():  # the hallway's rows first, the scene's targets after
            table = json.loads(results.read_text())
            table["rows"] += rows
        else:
            table = {"title": f"scene {self.name}", "rows": metric_rows(metrics) + rows,
                     "picture": self._plot_scene()}
        results.write_text(json.dumps(json_plain(table), indent=2))


def _all_targets(params: SceneWorldParams, scene: Scene) -> tuple[Target, ...]:
    """The targets the scene declares (its file's, resolved when loaded), unless the world is not to judge the
    run by them (`judge: false`), and the world's own."""
    declared = scene.targets if params.judge and isinstance(scene.targets, tuple) else ()
    return declared + tuple(params.targets)


def _generic(params: SceneWorldParams, scene: Scene, targets: tuple[Target, ...]) -> tuple[Target, ...]:
    """The targets the generic judge gives rows (judge.json): all but the bounds on the hallway's metrics of a
    judged hallway run, which its table shows."""
    if not (params.judge and scene.hallway is not None):
        return targets
    from hapticop.sim.targets import hallway_metric

    return tuple(t for t in targets if t.metric is None or not hallway_metric(t.metric.name))


def _scene_targets(params: SceneWorldParams) -> tuple[Target, ...]:
    """`_generic` of the params' scene, when it can be read (validation says why not)."""
    if isinstance(params.scene, Scene) and not isinstance(params.scene.targets, str):
        scene = params.scene
    else:
        loaded, _ = _loaded(params)
        scene = loaded.scene if loaded is not None and loaded.scene is not None else Scene()
    return _generic(params, scene, _all_targets(params, scene))


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
        bound = target.metric
        if bound is not None and bound.relative_to and (loaded.scene is None or loaded.scene.hallway is None):
            found.append(Diagnostic("scene-target", f"the bound on {bound.name} is relative to {bound.relative_to}, "
                                    "a distance of the scene's hallway task, which the scene has not",
                                    ("params", "targets", i, "metric", "relative_to"),
                                    hint="absolute bounds, or a 'hallway:' task in the scene"))
        push = target.push_body
        if push is not None and body_index(aliases, push.body) is None:
            known = ", ".join(a[0] for a in aliases) or "none"
            found.append(Diagnostic("scene-target", f"push_body names {push.body!r}, which is no movable body of "
                                    f"the scene", ("params", "targets", i, "push_body", "body"),
                                    expected=f"one of: {known}"))
    return found


def end_time_s(metrics, recorder) -> float:
    """The run's one end time, on the recording's clock: when the robot came to rest for good (the
    completion time), or the last moment recorded when it crashed or ran out of time."""
    if metrics.completion_time_s == metrics.completion_time_s:  # not NaN: it stopped
        return float(metrics.completion_time_s)
    return float(recorder.t[recorder.n - 1] - recorder.t[0])


def _cruise_speed(operator: dict) -> float | None:
    """The cruise speed of the operator the run had (T_ref's speed), or None if it did not say."""
    from hapticop.sim.operator import BlindOperator

    variant = operator.get("variant")
    if not variant:
        return None
    return BlindOperator.variant(str(variant), seed=operator.get("variation")).profile.cruise_speed()


def place(start: tuple[float, float, float], moved: np.ndarray, out: np.ndarray) -> np.ndarray:
    """The robot's pose in the hallway: its start pose composed with how far it has moved
    (`moved` = [x, y, theta] from where it started, in the start frame), into `out`."""
    sx, sy, st = start
    rx, ry, rt = float(moved[0]), float(moved[1]), float(moved[2])
    c, s = math.cos(st), math.sin(st)
    out[0] = sx + c * rx - s * ry
    out[1] = sy + s * rx + c * ry
    out[2] = st + rt
    return out
