"""Shared control on the robot: the operator's velocity command through a safety filter on the robot's scan.

The filter (``hapticop.haptics.safety_filter``, S2) keeps the robot off whatever its own LIDAR sees;
the block also publishes what it took away (executed minus commanded), so the haptic side can
render the correction as a force and the operator feels the robot disagree. Without a fresh scan
or command nothing is known to be safe: the robot is commanded to stand still.
"""

from __future__ import annotations

import numpy as np
from pydantic import Field

from hapticop.blocks.base import Block
from hapticop.blocks.interface import Interface, Params, Port, RateRange
from hapticop.haptics.safety_filter import SafetyFilter, SafetyFilterParams


class SharedControlParams(Params):
    filter: SafetyFilterParams = Field(default_factory=SafetyFilterParams)
    scan_points: int = Field(811, ge=2, le=10_000, description="points per scan (the ranges and angles ports)")


class SharedControl(Block):
    Params = SharedControlParams
    running_params = frozenset({"filter"})  # margins and gains retune between two cycles

    @classmethod
    def interface(cls, params: SharedControlParams) -> Interface:
        n = (params.scan_points,)
        return Interface(
            inputs={
                "command": Port("float64", (3,), "m/s, m/s, rad/s", "the operator's twist [vx, vy, wz]"),
                "ranges": Port("float32", n, "m", "the robot's own scan"),
                "angles": Port("float32", n, "rad", "beam directions in the robot frame"),
            },
            outputs={
                "velocity_setpoint": Port("float64", (3,), "m/s, m/s, rad/s", "the twist executed"),
                "correction": Port("float64", (3,), "m/s, m/s, rad/s", "executed minus commanded twist"),
            },
            rate=RateRange(100.0, 2000.0, "a command filtered far slower than the platform loop lags it"),
        )

    def configure_capabilities(self) -> None:
        self._build()

    def retune(self, changed: frozenset[str]) -> None:
        self.filter.params = self.params.filter

    def compute(self) -> None:
        command, ranges = self.inputs.command, self.inputs.ranges
        out, correction = self.outputs.velocity_setpoint, self.outputs.correction
        if command.valid and ranges.valid:
            if ranges.meta[0] != self.scan_seq:
                self.scan_seq = int(ranges.meta[0])
                self.filter.update_scan(ranges.value)
            self.filter.filter(command.value, out.value, ranges.age_ns() / 1e9)
            np.subtract(out.value, command.value, out=correction.value)
        else:  # nothing known to be safe
            out.value[:] = 0.0
            correction.value[:] = 0.0
            if command.valid:
                np.subtract(out.value, command.value, out=correction.value)
            self.filter.executed[:] = 0.0
        out.publish()
        correction.publish()

    def pausing(self) -> None:
        self.clean()

    def clean(self) -> None:
        for port in (self.outputs.velocity_setpoint, self.outputs.correction):
            port.value[:] = 0.0
            port.publish()

    def _build(self) -> None:
        angles = self.inputs.angles
        p = self.params
        self.filter = SafetyFilter(angles.value if angles.valid
                                   else np.linspace(-0.75 * np.pi, 0.75 * np.pi, p.scan_points), p.filter)
        self.scan_seq = 0
