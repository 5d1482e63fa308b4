"""The SICK TiM5xx LIDAR over CoLa A: ranges and angles of each 15 Hz scan.

The scan size is a parameter (811 points over 270 degrees on a TiM561), so the port
shapes follow it.
"""

from __future__ import annotations

from typing import Literal

import numpy as np
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
    scene: str = Field("hallway", description="the simulated world to scan (sim driver)")
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
    sim_fault: Literal["none", "unplugged", "stall", "garbage"] = Field(
        "none", description="sim driver: a fault of the simulated scanner, for fault scenarios (set it by a patch): "
        "'unplugged' drops the connection and refuses new ones, 'stall' keeps it open but sends no scans, "
        "'garbage' sends noise between telegrams")


class Lidar(Block):
    Params = LidarParams
    running_params = frozenset({"sim_fault"})
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

    # -- life cycle -------------------------------------------------------------------------
    def configure_resources(self) -> bool:
        """Connect a CoLa A client; with the sim driver, first start a TiM561 simulator on loopback."""
        from hapticop.devices.sick.client import ColaClient

        p = self.params
        host, port = p.host, p.port
        if p.driver == "sim":
            if getattr(self, "scanner", None) is None:
                self.scanner = self._simulator()
                if self.scanner is None:
                    return False  # the world activity has not opened the simulated world yet
            if not self.clock.virtual and not self.scanner.ready():
                return False  # its process is starting
            host, port = "127.0.0.1", self.scanner.port
        else:
            self.scanner = None
        from hapticop.devices.sick.cola import OutputRange, startup_sequence

        # The SICK frame counts from the sensor's right side: robot-frame -135 deg is SICK -45 deg.
        output_range = OutputRange(start=round((p.angle_min_deg + 90.0) * 10_000),
                                   stop=round((p.angle_max_deg + 90.0) * 10_000))
        self.client = ColaClient(host, port, backoff=p.reconnect_backoff_s, clock_ns=self.clock.now_ns,
                                 points=p.points, min_range_m=p.min_range_m,
                                 startup=startup_sequence(output_range=output_range))
        self.ranges = np.zeros(p.points, dtype=np.float32)
        self.angles = np.zeros(p.points, dtype=np.float32)
        self.yaw = np.radians(p.mount.yaw_deg)
        self.connected = False
        self.fault = "none"
        return True

    def _simulator(self):
        """The simulated scanner: stepped here under the virtual clock, a process of its own in
        real time (hapticop.sim.scanner_process says why); None until the world is open."""
        from hapticop.sim.scanner_process import ScannerProcess, scan_of
        from hapticop.sim.scene import find_scene, find_shared_scene

        if not self.clock.virtual:  # this thread may run in a child process of the world's
            scene = find_shared_scene(self.params.scene)
            if scene is None:
                return None
            seed = int(self.rng.integers(1 << 31))
            return ScannerProcess(scene.shared_pose.name, self.params.scan_rate_hz, seed)
        from hapticop.devices.sick.simulator import TiMSimulator

        scene = find_scene(self.params.scene)
        if scene is None:
            return None
        return TiMSimulator("127.0.0.1", 0, ranges_m=scan_of(scene.world, scene.geometry, scene.pose),
                            noise_std_m=scene.geometry.lidar.noise_sigma_m, rng=self.rng,
                            clock_ns=self.clock.now_ns, scan_rate_hz=self.params.scan_rate_hz)

    def compute(self) -> None:
        now = self.clock.now_ns()
        if self.scanner is not None:
            if self.params.sim_fault != self.fault:
                self._inject(self.params.sim_fault)
            if self.clock.virtual:
                if self.fault == "garbage":
                    self.scanner.inject_garbage()
                with self.context.simulation:
                    self.scanner.step(now)
        if self.client.poll(now) and self.client.latest_scan(self.ranges, self.angles):
            out = self.outputs
            np.copyto(out.ranges.value, self.ranges)
            np.add(self.angles, self.yaw, out=out.angles.value)  # sensor frame to robot frame
            out.ranges.origin_ns = out.angles.origin_ns = self.client.scan_host_ns  # when its last byte was read
            out.ranges.publish()
            out.angles.publish()
            self.flags["new_scan"] = True
        connected = self.client.scans > 0 and self.client.state.name == "STREAMING"
        if connected != self.connected:
            (self.log.info if connected else self.log.warning)(
                "LIDAR %s%s", "streaming" if connected else "not streaming",
                "" if connected else f" ({self.client.last_error or 'starting'})")
            self.connected = connected

    def wakeup_fds(self) -> tuple[int, ...]:
        """The scanner's socket: a `wake: data` thread parses a telegram as its last byte arrives."""
        fd = self.client.fileno()
        return (fd,) if fd >= 0 else ()

    def _inject(self, fault: str) -> None:
        """Switch the simulated scanner's fault (a patch changed `sim_fault`)."""
        scanner = self.scanner
        if not self.clock.virtual:
            scanner.fault(fault)  # the process keeps it up (garbage: between its telegrams)
        else:
            scanner.set_fault(fault)
        if fault == "none":
            self.log.info("simulated scanner fault cleared")
        else:
            self.log.warning("simulated scanner fault: %s", fault)
        self.fault = fault

    def clean(self) -> None:
        if getattr(self, "client", None) is not None:
            self.client.close()
        if getattr(self, "scanner", None) is not None:
            if self.clock.virtual:
                self.scanner.close()
            else:
                self.scanner.stop()
            self.scanner = None
