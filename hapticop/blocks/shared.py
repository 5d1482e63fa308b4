"""Shared control on the robot: the operator's velocity command through a safety filter on the robot's scan.

The filter (``hapticop.haptics.safety_filter``, S2) keeps the robot off whatever its own LIDAR sees;
the block also publishes what it took away (executed minus commanded), so the haptic side can
render the correction as a force and the operator feels the robot disagree. Without a fresh scan
or command nothing is known to be safe: the robot is commanded to stand still. Each scan passes a
per-beam filter first (a 5-beam median by default): the barrier has one constraint per point, so a
single phantom return would otherwise stop the robot (docs/hallway-experiment.md §10.2).
"""

from __future__ import annotations

import numpy as np
from pydantic import Field

from hapticop.blocks.base import Block
from hapticop.blocks.interface import Interface, Params, Port, RateRange
from hapticop.haptics.safety_filter import SafetyFilter, SafetyFilterParams
from hapticop.haptics.scan_filter import MovingMedianParams, make_scan_filter


class SharedControlParams(Params):
    filter: SafetyFilterParams = Field(default_factory=SafetyFilterParams)
    scan_filter: MovingMedianParams = Field(
        default_factory=MovingMedianParams,
        description="the running median each scan passes before the barrier: a return counts only where most of "
        "its neighbours agree (window 1: every beam counts)")
    scan_points: int = Field(811, ge=2, le=10_000, description="points per scan (the ranges and angles ports)")


class SharedControl(Block):
    Params = SharedControlParams
    running_params = frozenset({"filter", "scan_filter"})  # both retune between two cycles

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
        if "scan_filter" in changed:
            self._build()
        self.filter.params = self.params.filter

    def compute(self) -> None:
        command, ranges = self.inputs.command, self.inputs.ranges
        out, correction = self.outputs.velocity_setpoint, self.outputs.correction
        if command.valid and ranges.valid:
            if ranges.meta[0] != self.scan_seq:
                self.scan_seq = int(ranges.meta[0])
                self.filter.update_scan(self.scan_filter.apply(ranges.value))
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
        self.scan_filter = make_scan_filter(p.scan_filter)
        filtered_angles = self.scan_filter.configure(angles.value if angles.valid
                                                     else np.linspace(-0.75 * np.pi, 0.75 * np.pi, p.scan_points))
        self.filter = SafetyFilter(filtered_angles, p.filter)
        self.scan_seq = 0
