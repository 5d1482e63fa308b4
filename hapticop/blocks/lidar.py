"""The SICK TiM5xx LIDAR over CoLa A: ranges and angles of each 15 Hz scan.

The scan size is a parameter (811 points over 270 degrees on a TiM561), so the port
shapes follow it.
"""

from __future__ import annotations

from typing import Literal

from pydantic import Field

from hapticop.blocks.base import Block
from hapticop.blocks.interface import Interface, Params, Port, RateRange


class MountPose(Params):
    """Where the scanner sits in the robot frame (x forward, y left)."""

    x_m: float = 0.0
    y_m: float = 0.0
    yaw_deg: float = 0.0


class LidarParams(Params):
    driver: Literal["sim", "tcp"] = Field("sim", description="'sim': a CoLa A server on loopback")
    host: str = Field("127.0.0.1", description="scanner address (the TiM's factory default is 192.168.0.1)")
    port: int = Field(2112, ge=0, le=65535, description="CoLa port; 0 lets the simulator pick a free one")
    points: int = Field(811, ge=2, le=10_000, description="points per scan")
    scan_rate_hz: float = Field(15.0, gt=0, le=100)
    angle_min_deg: float = -135.0
    angle_max_deg: float = 135.0
    min_range_m: float = Field(0.05, ge=0, description="closer values are invalid")
    max_range_m: float = Field(10.0, gt=0)
    reconnect_backoff_s: tuple[float, float] = Field((0.1, 2.0), description="first and longest retry delay")
    mount: MountPose = Field(default_factory=MountPose)


class Lidar(Block):
    Params = LidarParams
    flags_written = {"new_scan": "a complete scan was written to the ranges and angles ports"}

    @classmethod
    def interface(cls, params: LidarParams) -> Interface:
        n = (params.points,)
        return Interface(
            outputs={
                "ranges": Port("float32", n, "m", "range per beam; NaN where invalid"),
                "angles": Port("float32", n, "rad", "beam angle in the robot frame"),
            },
            flags_written=dict(cls.flags_written),
            rate=RateRange(params.scan_rate_hz, 1000.0, "the thread must poll at least as fast as the scanner scans"),
        )
