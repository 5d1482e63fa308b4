"""The simulated hallway: where the robot is in it, and the judge of the run.

It publishes the hallway's fixed geometry for the simulators that need it (`world_share`) and,
every cycle, the robot's pose in the hallway (its start composed with the motion the robot
plant reports), which the simulated LIDAR scans from. Once the operator drives it records the
run (robot pose and velocity, handle, forces, clearance) and raises `finished` when the
operator is done and the robot still, the robot crashes, or time is up, so the mediator can
end the run. When it is cleaned it leaves the trajectory, the metrics of docs/hallway-experiment.md
section 5 and a picture of the run in the run directory.
"""

from __future__ import annotations

import json
import math
from typing import Literal

import numpy as np
from pydantic import Field

from hapticop.blocks.base import Block
from hapticop.blocks.interface import Display, Params, Port


class HallwayWorldParams(Params):
    hallway: Literal["H1", "H2", "H3", "H4", "H5", "H6"] = Field(
        "H1", description="hallway of docs/hallway-experiment.md §2")
    operator: str = Field("operator", description="the activity whose run this world judges (block blind_operator): "
                          "its variant sets the targets")
    time_limit_s: float = Field(90.0, gt=0, description="the run ends here at the latest")
    plot: bool = Field(True, description="draw the run to run.png (needs matplotlib)")
    judge: bool = Field(True, description="judge the run by the hallway experiment's targets; false for an "
                        "application that does not drive the robot down the hallway (the desk): its "
                        "trajectory is kept, but nothing is judged")


class HallwayWorld(Block):
    Params = HallwayWorldParams
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
    outputs = {"pose_in_hallway": Port("float64", (3,), "m, m, rad", "the robot's pose in the hallway (x along it, "
                                       "y to the left, theta counter-clockwise)")}
    flags_written = {"finished": "the operator is done, the robot crashed, or time is up"}

    @classmethod
    def displays(cls, params: HallwayWorldParams) -> tuple[Display, ...]:
        """The robot's frames along REP-105, from its pose in the hallway (the map)."""
        return (Display("frames", {"pose": "pose_in_hallway"}),)

    @classmethod
    def promises(cls, params: HallwayWorldParams) -> tuple[str, ...]:
        if not params.judge:  # not a hallway run: the trajectory alone
            return ("trajectory.npz",)
        return ("trajectory.npz", "metrics.json", "results.json") + (("run.png",) if params.plot else ())

    def create(self) -> None:
        from hapticop.sim.hallway import HallwayGeometry, World
        from hapticop.sim.world_share import publish_world

        self.geometry = HallwayGeometry.named(self.params.hallway)
        self.world = World.from_geometry(self.geometry)
        publish_world(self.run_dir, self.name, self.geometry)
        self.prepare(self.outputs.pose_in_hallway.value)

    def prepare(self, pose: np.ndarray) -> None:
        """The judge's state, once `geometry` is known; `pose` is the output the robot's pose goes to."""
        from hapticop.sim.recording import TrajectoryRecorder

        p = self.params
        self.recorder = TrajectoryRecorder(int(p.time_limit_s * 1000) + 1000, meta={"hallway": self.geometry.name})
        self.pose = pose
        self.pose[:] = self.geometry.start
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

    def compute(self) -> None:
        if self.inputs.robot_pose.seq:  # the robot where it is, for the LIDAR, even before the operator drives
            place(self.geometry.start, self.inputs.robot_pose.value, self.pose)
        self.outputs.pose_in_hallway.publish()
        if self.inputs.operator_time.seq and not self.ended:
            self.judge(*self.world.clearance(self.pose, self.geometry.footprint))

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
                             force_device=inputs.device_force.value, clearance=clearance)
        g = self.geometry
        moving = abs(vx) >= g.still_speed_mps or abs(vy) >= g.still_speed_mps
        self.still_since = None if moving else (t if self.still_since is None else self.still_since)
        still = self.still_since is not None and t - self.still_since >= g.still_time_s
        if crashed:
            self.ended = "crash"
        elif inputs.operator_done.value and still:  # the judge's rule: stopped, and still for a while
            self.ended = "operator done"
        elif t >= self.params.time_limit_s:
            self.ended = "time limit"
        if self.ended:  # its time is told once, from the metrics, when the world cleans
            self.log.always("run judged over: %s", self.ended)
            self.flags["finished"] = True

    def clean(self) -> None:
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
        metrics = compute_metrics(self.recorder, self.geometry, v_cruise_mps=_cruise_speed(operator))
        extra = {key: value for key, value in self.extremes.items() if math.isfinite(value)}
        (self.run_dir / "metrics.json").write_text(metrics_json(metrics, extra or None))
        self.log.always("run ended at %.3f s after the operator started: %s", end_time_s(metrics, self.recorder),
                        metrics.ended_by)
        if self.params.plot:
            try:
                from hapticop.sim.plot import plot_run

                plot_run(self.recorder, self.geometry, self.run_dir / "run.png",
                         title=f"{self.geometry.name}, {self.variant} operator")
            except RuntimeError as error:  # matplotlib missing: the numbers are still there
                self.log.warning("no picture of the run: %s", error)
        self._results(metrics)

    def _results(self, m) -> None:
        """The rows `hapticop compose` prints at the end (results.json: any block may leave one)."""
        from hapticop.sim.targets import judged_rows

        results = {"title": f"hallway {self.geometry.name}, {self.variant} operator",
                   "rows": judged_rows(m, self.geometry, self.variant, end_time_s(m, self.recorder)),
                   "picture": "run.png" if (self.run_dir / "run.png").exists() else None}
        (self.run_dir / "results.json").write_text(json.dumps(results, indent=2))


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
