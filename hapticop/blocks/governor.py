"""The speed governor on its own, for the robot's side: the command limited by the robot's own scan.

In the hallway the haptic controller governs its own setpoints; when the operator is across a
network the governor must run where the robot is, on the undelayed scan, so that collisions do not
depend on the link (docs/teleop.md). A command that is stale (its stream's max_age passed: the link
is lost) is no command: the robot is told to stand still, and so is a command not finite or outside the
command port's range (`hapticop.blocks.bounds`) until the next good one.
"""

from __future__ import annotations

import numpy as np
from pydantic import Field

from hapticop.blocks.base import Block
from hapticop.blocks.bounds import Bounds
from hapticop.blocks.interface import Interface, Params, Port
from hapticop.haptics.geometry import BeamGeometry
from hapticop.haptics.governor import BlindPolicy, GovernorParams, govern_cycle, govern_scan, limit_blind_by
from hapticop.haptics.scan_filter import MovingAverageParams, ScanFilterParams, make_scan_filter

COMMAND_RANGE = (-10.0, 10.0)  # m/s and rad/s: beyond any platform; the robot's own limits are tighter


class SpeedGovernorParams(Params):
    governor: GovernorParams = Field(default_factory=GovernorParams)
    blind: BlindPolicy = Field(default_factory=BlindPolicy)
    scan_filter: ScanFilterParams = Field(
        default_factory=MovingAverageParams, discriminator="kind",
        description="the per-beam filter of each scan: 'kind' moving_average or moving_median")
    scan_points: int = Field(811, ge=2, le=10_000, description="points per scan (the ranges and angles ports)")


class SpeedGovernor(Block):
    """S1 on the robot: the commanded twist scaled towards zero so the robot stops before obstacles."""

    Params = SpeedGovernorParams
    flags_written = {"blind": "the scan is stale: the blind policy limits the robot"}
    running_params = frozenset({"governor", "blind"})

    @classmethod
    def interface(cls, params: SpeedGovernorParams) -> Interface:
        n = (params.scan_points,)
        twist = "m/s, m/s, rad/s"
        return Interface(
            inputs={"command": Port("float64", (3,), twist, "the twist [vx, vy, wz] asked for", range=COMMAND_RANGE),
                    "ranges": Port("float32", n, "m"),
                    "angles": Port("float32", n, "rad")},
            outputs={"twist": Port("float64", (3,), twist, "the twist allowed")},
            flags_written=dict(cls.flags_written))

    def create(self) -> None:
        self.scan_seq = -1
        self.stop_gap_m = 0.0
        self.blind = False
        self.command_seq = -1
        self.command_good = False

    def configure_resources(self) -> bool:
        """Wait for the scan's angles: the governor's geometry hangs on them."""
        if not self.inputs.angles.valid:
            self.context.waiting_for("the scan's angles")
            return False
        self.context.waiting_for(None)
        p = self.params
        self.filter = make_scan_filter(p.scan_filter)
        self.beams = BeamGeometry(self.filter.configure(self.inputs.angles.value))
        self.scan_seq = -1
        self.bounds = Bounds(self.interface(p).inputs["command"], f"{self.name}.command")
        return True

    def compute(self) -> None:
        inputs, out = self.inputs, self.outputs.twist.value
        ranges = inputs.ranges
        if ranges.seq != self.scan_seq:
            self.scan_seq = ranges.seq
            self.stop_gap_m = govern_scan(self.filter.apply(ranges.value), self.beams, self.params.governor)
        command = inputs.command
        if command.seq != self.command_seq:  # each new sample checked once: a bad one is no command
            self.command_seq = command.seq
            self.command_good = self.bounds.admits(command.value)
            self.bounds.said(self.log, self.command_good)
        if command.valid and self.command_good:
            np.copyto(out, command.value)
        else:
            out.fill(0.0)
        blind = not ranges.valid
        if blind != self.blind:
            self.blind = self.flags["blind"] = blind
        if blind:
            limit_blind_by(out, self.params.blind)
        else:
            govern_cycle(out, self.beams, self.stop_gap_m, out, self.params.governor)
        self.outputs.twist.publish()

    def pausing(self) -> None:
        self.clean()

    def clean(self) -> None:
        self.outputs.twist.value.fill(0.0)
        self.outputs.twist.publish()
