"""The scan rendered beside the haptic loop: filtered once per scan, where the scan arrives.

Run on the LIDAR's thread, after the LIDAR: each new scan is filtered and its points placed in
the robot frame (``hapticop.haptics.scan_field``), and the fixed ``(4, scan_points)`` result goes
to the haptic controller's ``scan_field`` input, whose 1 kHz step then only chooses and evaluates
points (docs/haptics.md). The filter's parameters are declared here, once.
"""

from __future__ import annotations

import numpy as np
from pydantic import Field

from hapticop.blocks.base import Block
from hapticop.blocks.interface import Interface, Params, Port
from hapticop.haptics.scan_field import ROWS, ScanField
from hapticop.haptics.scan_filter import MovingAverageParams, ScanFilterParams


class ScanFieldParams(Params):
    scan_filter: ScanFilterParams = Field(
        default_factory=MovingAverageParams, discriminator="kind",
        description="the per-beam filter of each scan: 'kind' moving_average or moving_median")
    scan_points: int = Field(811, ge=2, le=10_000, description="points per scan (the ranges and angles ports)")


class ScanFieldBlock(Block):
    """Filter each new scan and publish its points in the robot frame, once per scan."""

    Params = ScanFieldParams
    running_params = frozenset({"scan_filter"})  # the next scan is rendered with the new filter

    @classmethod
    def interface(cls, params: ScanFieldParams) -> Interface:
        n = (params.scan_points,)
        return Interface(
            inputs={"ranges": Port("float32", n, "m", "range per beam; NaN where invalid"),
                    "angles": Port("float32", n, "rad", "beam angle in the robot frame")},
            outputs={"field": Port("float64", (ROWS, params.scan_points), "m, rad, m, m",
                                   "rows: filtered range (NaN: nothing seen), angle, robot-frame x and y; "
                                   "a filter that shortens the scan pads the last columns with beams "
                                   "that see nothing")})

    def create(self) -> None:
        self.renderer: ScanField | None = None
        self.angle_bytes = b""  # the angles the renderer was built for
        self.scan_seq = 0

    def retune(self, changed: frozenset[str]) -> None:
        self.renderer = None  # rebuilt on the next scan, with the new filter

    def compute(self) -> None:
        ranges, angles = self.inputs.ranges, self.inputs.angles
        if ranges.seq == self.scan_seq or not angles.valid:
            return
        self.scan_seq = ranges.seq
        renderer = self.renderer
        # The angles' bytes, compared in one call: the LIDAR's process is woken 15 times a second, and
        # there each numpy call starts cold (array_equal makes several). Same bits, same renderer.
        if renderer is None or angles.value.tobytes() != self.angle_bytes:
            renderer = self.renderer = ScanField(self.params.scan_filter, angles.value)
            self.angle_bytes = angles.value.tobytes()
        out = self.outputs.field
        np.copyto(out.value, renderer.apply(ranges.value))
        out.stamp_ns = ranges.stamp_ns  # the scan's time, not the rendering's: its age is the scan's
        out.publish()
