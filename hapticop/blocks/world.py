"""The simulated hallway: the world the simulated devices share, and the judge of the run.

It opens the scene the simulated ropod, LIDAR and Falcon (with its blind operator) work
in, records the run (robot pose and velocity, handle, forces, clearance) and raises
`finished` when the operator is done, the robot crashes, or time is up, so the mediator can
end the run. When it is cleaned it leaves the trajectory, the metrics of
hallway-experiment.md section 5 and a picture of the run in the run directory.
"""

from __future__ import annotations

import json
from dataclasses import asdict
from typing import Literal

import numpy as np
from pydantic import Field

from hapticop.blocks.base import Block
from hapticop.sim.scene import place
from hapticop.blocks.interface import Params, Port


class HallwayWorldParams(Params):
    hallway: Literal["H1", "H2", "H3", "H4", "H5", "H6"] = Field("H1", description="hallway of hallway-experiment.md §2")
    operator: Literal["cautious", "nominal", "aggressive", "tremor", "hands_off"] = "nominal"
    variation: int | None = Field(None, ge=0, description="seed of a varied operator; none: the exact profile")
    scene: str = Field("hallway", description="name the simulated devices find this world by")
    time_limit_s: float = Field(90.0, gt=0, description="the run ends here at the latest")
    plot: bool = Field(True, description="draw the run to run.png (needs matplotlib)")


class HallwayWorld(Block):
    Params = HallwayWorldParams
    simulator = True  # everything it does is the simulation
    provides = frozenset({"hallway"})
    inputs = {
        "robot_pose": Port("float64", (3,), "m, m, rad", "the simulated robot's pose from its start", required=False),
        "robot_twist": Port("float64", (3,), "m/s, m/s, rad/s", "the simulated robot's twist", required=False),
        "environment_force": Port("float64", (3,), "N", "the obstacle force on the handle", required=False),
        "velocity_setpoint": Port("float64", (3,), "m/s, m/s, rad/s", "the commanded twist", required=False),
    }
    outputs = {
        "pose_in_hallway": Port("float64", (3,), "m, m, rad", "where the robot is in the hallway, every cycle "
                                "(its start until the robot's motion arrives)"),
    }
    flags_written = {"finished": "the operator is done, the robot crashed, or time is up"}
    flags_read = {"operator_go": "the haptic loop runs: the operator may start driving"}
    awaits = frozenset({"operator_go"})

    def create(self) -> None:
        from hapticop.sim.hallway import HallwayGeometry, World
        from hapticop.sim.metrics import TrajectoryRecorder
        from hapticop.sim.operator import BlindOperator
        from hapticop.sim.scene import Scene, open_scene
        from hapticop.sim.world_share import publish_world

        p = self.params
        self.geometry = HallwayGeometry.named(p.hallway)
        publish_world(self.run_dir, self.name, self.geometry)  # for its simulators, in any process
        operator = BlindOperator.variant(p.operator, seed=p.variation, t_max_s=p.time_limit_s)
        self.scene = open_scene(Scene(p.scene, self.geometry, World.from_geometry(self.geometry), operator))
        self.recorder = TrajectoryRecorder(int(p.time_limit_s * 1000) + 1000,
                                           meta={"hallway": p.hallway, "operator": p.operator,
                                                 "variation": p.variation})
        self.ended = ""
        self.still_since: float | None = None
        self.velocity = np.zeros(2)  # (v, omega): the recorder's unicycle view of a twist
        self.command = np.zeros(2)

    def _place_robot(self) -> None:
        """The robot's pose in the hallway: its start composed with how far it has moved."""
        pose, scene = self.inputs.robot_pose, self.scene
        if pose.seq == 0:
            return
        place(self.geometry.start, pose.value, scene.pose)
        np.copyto(scene.twist, self.inputs.robot_twist.value)

    def compute(self) -> None:
        now = self.clock.now_ns()
        scene = self.scene
        self._place_robot()  # the LIDAR sees the robot where it is, even before the operator drives
        where = self.outputs.pose_in_hallway
        np.copyto(where.value, scene.pose)
        where.publish()
        if scene.operator_since_ns is None:
            if not self.flags["operator_go"]:
                return
            scene.operator_since_ns = now
            self.recorder.meta["operator_start_ns"] = now  # the recording's time 0, on the system's clock
            self.log.info("the operator starts driving")
        t = scene.operator_time(now)
        force = self.inputs.environment_force
        np.copyto(scene.environment_force, force.value if force.valid else 0.0)
        clearance, crashed = scene.world.clearance(scene.pose, self.geometry.footprint)
        if not self.ended:
            vx, vy, wz = scene.twist.tolist()  # floats: numpy scalars are slow to compare
            self.velocity[0], self.velocity[1] = vx, wz
            setpoint = self.inputs.velocity_setpoint.value
            self.command[0], self.command[1] = setpoint[0], setpoint[2]
            self.recorder.append(t, scene.pose, robot_velocity=self.velocity, cmd=self.command,
                                 handle_position=scene.handle_position, handle_velocity=scene.handle_velocity,
                                 force_env=scene.environment_force, force_hand=scene.hand_force,
                                 force_device=scene.device_force, clearance=clearance)
            g = self.geometry
            moving = abs(vx) >= g.still_speed_mps or abs(vy) >= g.still_speed_mps
            self.still_since = None if moving else (t if self.still_since is None else self.still_since)
            still = self.still_since is not None and t - self.still_since >= g.still_time_s
            if crashed:
                self.ended = "crash"
            elif scene.operator.done(t) and still:  # the judge's rule: stopped, and still for a while
                self.ended = "operator done"
            elif t >= self.params.time_limit_s:
                self.ended = "time limit"
            if self.ended:
                self.log.always("run ended at %.2f s: %s", t, self.ended)
                self.flags["finished"] = True

    def clean(self) -> None:
        from hapticop.sim.metrics import compute_metrics
        from hapticop.sim.scene import close_scene
        from hapticop.sim.world_share import withdraw_world

        close_scene(self.params.scene)
        withdraw_world(self.run_dir, self.name)
        if self.recorder.n < 2:
            return
        self.recorder.save(self.run_dir / "trajectory.npz")
        metrics = compute_metrics(self.recorder, self.geometry)
        (self.run_dir / "metrics.json").write_text(json.dumps(_plain(asdict(metrics)), indent=2))
        if self.params.plot:
            try:
                from hapticop.sim.plot import plot_run

                plot_run(self.recorder, self.geometry, self.run_dir / "run.png",
                         title=f"{self.params.hallway}, {self.params.operator} operator")
            except RuntimeError as error:  # matplotlib missing: the numbers are still there
                self.log.warning("no picture of the run: %s", error)
        self._results(metrics)


    def _results(self, m) -> None:
        """The rows `hapticop compose` prints at the end (results.json: any block may leave one)."""
        from hapticop.sim.metrics import Targets, targets_met

        g = self.geometry
        checks = targets_met(m, Targets.for_variant(self.params.operator)).checks

        def row(name, value, unit, target, check):
            return {"metric": name, "value": None if value is None or value != value else round(float(value), 3),
                    "unit": unit, "target": target, "ok": checks.get(check) if check else None}

        rows = [
            {"metric": "ended by", "value": m.ended_by, "unit": "", "target": "stopped", "ok": checks.get("completed")},
            row(f"collisions (clearance under dist3 = {g.dist3_m} m)", m.n_collisions, "", "0", "no_crash"),
            row(f"stop error against dist2 = {g.dist2_m} m (+ early)", m.e_stop_m, "m", "-0.05 to +0.10", "e_stop"),
            row(f"least side clearance (dist1 = {g.dist1_m} m)", m.side_clearance_min_m, "m",
                f">= {g.dist1_m - 0.10:.2f}", "side_clearance"),
            row("completion time", m.completion_time_s, "s", "", None),
            row("peak force", m.force_peak_n, "N", "<= 8", "force_peak"),
            row("rms force", m.force_rms_n, "N", "", None),
            row("rms force rate", m.force_rate_rms_nps, "N/s", "<= 30", "force_rate"),
        ]
        results = {"title": f"hallway {self.params.hallway}, {self.params.operator} operator",
                   "rows": rows, "picture": "run.png" if (self.run_dir / "run.png").exists() else None}
        (self.run_dir / "results.json").write_text(json.dumps(results, indent=2))


def _plain(value):
    if isinstance(value, dict):
        return {k: _plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    if isinstance(value, (np.floating, float)):
        return None if not np.isfinite(value) else float(value)
    if isinstance(value, (np.integer, int, bool, np.bool_)) and not isinstance(value, str):
        return value.item() if hasattr(value, "item") else value
    return value if isinstance(value, (str, type(None))) else str(value)
