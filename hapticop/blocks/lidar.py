"""The SICK TiM5xx LIDAR over CoLa A: ranges and angles of each 15 Hz scan.

The block is a CoLa A client and nothing else: `driver: tcp` reaches the scanner at
host:port; `driver: sim` reaches a simulated one at the address its activity (`simulator`)
publishes. The scan size is a parameter (811 points over 270 degrees on a TiM561), so the
port shapes follow it.
"""

from __future__ import annotations

import math
from typing import Literal

import numpy as np
from pydantic import Field

from hapticop.blocks.base import Block
from hapticop.blocks.interface import DeviceParams, Display, Interface, Port, RateRange
from hapticop.devices.ropod.body import Body

ROPOD_BODY = Body()


class LidarParams(DeviceParams):
    simulated_by = "a tim561_simulator"
    driver: Literal["tcp", "sim"] = Field("tcp", description="'tcp': the scanner at host:port; 'sim': the "
                                          "simulated scanner the `simulator` activity serves")
    host: str = Field("127.0.0.1", description="scanner address (the TiM's factory default is 192.168.0.1)")
    port: int = Field(2112, ge=1, le=65535, description="CoLa A port of the scanner")
    points: int = Field(811, ge=2, le=10_000, description="points per scan")
    scan_rate_hz: float = Field(15.0, gt=0, le=100, description="the scanner's scan rate")
    angle_min_deg: float = Field(-135.0, description="the first beam's angle, the sensor's frame (0 ahead)")
    angle_max_deg: float = Field(135.0, description="the last beam's angle")
    min_range_m: float = Field(0.05, ge=0, description="closer values are invalid")
    max_range_m: float = Field(10.0, gt=0, description="the farthest range the scanner reports")
    reconnect_backoff_s: tuple[float, float] = Field((0.1, 2.0), description="first and longest retry delay")
    yaw_deg: float = Field(
        math.degrees(ROPOD_BODY.lidar.yaw_rad), description="the scanner's heading on the robot: beam angles are "
        "turned by it into the robot frame (where it sits is the robot body's, hapticop.devices.ropod.body)")



class Lidar(Block):
    Params = LidarParams
    needs = {"simulator": "tim561"}
    flags_written = {"new_scan": "a complete scan was written to the ranges and angles ports"}

    @classmethod
    def displays(cls, params: LidarParams) -> tuple[Display, ...]:
        """The scan in the scanner's own frame (`laser`), and where that frame sits on the robot."""
        yaw = math.radians(params.yaw_deg)
        mount = ROPOD_BODY.lidar
        return (Display("laser_scan", {"ranges": "ranges", "angles": "angles"},
                        {"yaw_rad": yaw, "mount": (mount.x_m, mount.y_m, yaw)}),)

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

    @classmethod
    def preflight(cls, params: LidarParams, timeout_s: float) -> str | None:
        """A real scanner: something answers CoLa A at host:port within the bound."""
        if params.driver != "tcp":
            return None
        from hapticop.devices.sick.probe import ProbeError, probe_lidar

        try:
            probe_lidar(params.host, params.port, timeout_s)
        except ProbeError as error:
            return f"no LIDAR answering: {error}"
        return None

    # -- life cycle -------------------------------------------------------------------------
    def create(self) -> None:
        self.client = None
        self.connected = False

    def configure_resources(self) -> bool:
        """A CoLa A client for the scanner at host:port, or where the simulator says it listens."""
        import socket

        from hapticop.devices.link import published_address
        from hapticop.devices.memory_stream import MEMORY_SOCKETS
        from hapticop.devices.sick.client import ColaClient
        from hapticop.devices.sick.commands import OutputRange, startup_sequence

        p = self.params
        address = (p.host, p.port) if p.driver == "tcp" else published_address(self.run_dir, p.simulator)
        if address is None:
            return False  # the simulated scanner is not listening yet
        if self.client is not None:  # configured again (a patch): a new connection
            self.client.close()
        # The SICK frame counts from the sensor's right side: robot-frame -135 deg is SICK -45 deg.
        output_range = OutputRange(start=round((p.angle_min_deg + 90.0) * 10_000),
                                   stop=round((p.angle_max_deg + 90.0) * 10_000))
        self.client = ColaClient(*address, backoff=p.reconnect_backoff_s, clock_ns=self.clock.now_ns,
                                 points=p.points, min_range_m=p.min_range_m,
                                 startup=startup_sequence(output_range=output_range),
                                 # a simulator under the virtual clock serves in this thread, in memory
                                 sockets=MEMORY_SOCKETS if p.driver == "sim" and self.clock.virtual else socket.socket)
        self.yaw = np.radians(p.yaw_deg)
        self.connected = False
        return True

    def compute(self) -> None:
        client = self.client
        out = self.outputs
        if client.poll(self.clock.now_ns()) and client.latest_scan(out.ranges.value, out.angles.value):
            np.add(out.angles.value, self.yaw, out=out.angles.value)  # sensor frame to robot frame
            out.ranges.origin_ns = out.angles.origin_ns = client.scan_host_ns  # when its last byte was read
            out.ranges.publish()
            out.angles.publish()
            self.flags["new_scan"] = True
        connected = client.scans > 0 and client.state.name == "STREAMING"
        if connected != self.connected:
            (self.log.info if connected else self.log.warning)(
                "LIDAR %s%s", "streaming" if connected else "not streaming",
                "" if connected else f" ({client.last_error or 'starting'})")
            self.connected = connected

    def wakeup_fds(self) -> tuple[int, ...]:
        """The scanner's socket: a `wake: data` thread parses a telegram as its last byte arrives."""
        fd = self.client.fileno() if self.client is not None else -1
        return (fd,) if fd >= 0 else ()

    def clean(self) -> None:
        if self.client is not None:
            self.client.close()
            self.client = None
