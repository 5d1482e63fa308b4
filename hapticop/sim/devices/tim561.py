"""The simulated TiM561: CoLa A on a loopback port (an in-memory stream under the virtual clock), scanning the
simulated hallway from where the robot is.

It serves the LIDAR block as the scanner would (hapticop.devices.sick.simulator serves the
device model over TCP) at an address it publishes in the run directory. The walls come from
the world it names, the robot's pose in the hallway from a stream of that world. It is
stepped in its compute: each step answers the client and sends the scans that are due,
ray-cast at the moment they leave. Under the virtual clock a thread of the same rate just
before the LIDAR's reproduces every run; in real time its thread belongs outside the
real-time loops' processes (a scan costs a ray cast and an 811-value telegram, about 0.6 ms
of Python).
"""

from __future__ import annotations

from typing import Literal

import numpy as np
from pydantic import Field

from hapticop.blocks.base import Block
from hapticop.blocks.interface import Interface, Params, Port, RateRange


class Tim561SimulatorParams(Params):
    world: str = Field(description="the world activity whose hallway it scans")
    bodies: int = Field(0, ge=0, description="movable bodies in the world's scene it sees move (the rows of "
                        "scene_world's body_poses); 0: it sees them where they started")
    scan_rate_hz: float = Field(15.0, gt=0, le=100, description="the TiM561 scans at 15 Hz")
    sim_fault: Literal["none", "unplugged", "stall", "garbage"] = Field(
        "none", description="a fault of the simulated scanner, for fault scenarios (set it by a patch): "
        "'unplugged' drops the connection and refuses new ones, 'stall' keeps it open but sends no scans, "
        "'garbage' sends noise between telegrams")


class Tim561Simulator(Block):
    Params = Tim561SimulatorParams
    simulator = True
    provides = frozenset({"tim561"})
    needs = {"world": "hallway"}
    running_params = frozenset({"sim_fault"})

    @classmethod
    def interface(cls, params: Tim561SimulatorParams) -> Interface:
        inputs = {"pose_in_hallway": Port("float64", (3,), "m, m, rad", "where the robot is in its world")}
        if params.bodies:
            inputs["body_poses"] = Port("float64", (params.bodies, 3), "m, m, rad", "where the scene's movable "
                                        "bodies are (scene_world's body_poses)")
        return Interface(
            inputs=inputs,
            rate=RateRange(params.scan_rate_hz, 1000.0, "it sends each scan at the first step after it is due"),
        )

    def create(self) -> None:
        self.device = None
        self.fault = "none"
        self.waiting_logged = False

    def configure_resources(self) -> bool:
        """Open the scanner once the world has published its hallway or scene, and say where it listens."""
        import socket

        from hapticop.devices.link import publish_address
        from hapticop.devices.memory_stream import MEMORY_SOCKETS
        from hapticop.devices.sick.device_model import ANGLES_RAD
        from hapticop.devices.sick.simulator import TiMSimulator
        from hapticop.sim.world_share import find_world

        world = self.params.world
        found = find_world(self.run_dir, world)
        if found is None:
            if not self.waiting_logged:
                self.log.info("waiting for the world '%s' to open its hallway", world)
                self.waiting_logged = True
            return False
        if self.device is not None:  # configured again (a patch): a new scanner, without faults
            self.device.close()
        self.angles = np.asarray(ANGLES_RAD, dtype=float)
        self.ranges = np.zeros(len(self.angles))
        self.start_pose = np.asarray(found.start, dtype=float)
        from hapticop.sim.engine import Engine

        self.engine = Engine(found.xml, world)  # the scene: MuJoCo casts the rays
        self.limits = (found.min_range_m, found.max_range_m, found.yaw_rad)
        # Under the virtual clock the LIDAR block runs in this thread too: the same CoLa A bytes through
        # in-memory streams (the block looks for the address there as well), no socket.
        sockets = MEMORY_SOCKETS if self.clock.virtual else socket.socket
        self.device = TiMSimulator("127.0.0.1", 0, ranges_m=self._scan, noise_std_m=found.noise_sigma_m,
                                   rng=self.rng, clock_ns=self.clock.now_ns, scan_rate_hz=self.params.scan_rate_hz,
                                   sockets=sockets)
        self.fault = "none"
        # The first step sets the scans' schedule. A thread at the scan rate may wake later for
        # that step than for the next ones; stepping half a period ahead of the clock sends each
        # scan at the step nearest its time instead of a whole period late.
        self.ahead_ns = round(0.5e9 / self.params.scan_rate_hz)
        publish_address(self.run_dir, self.name, self.device.host, self.device.port)
        self.log.info("TiM561 in the world of '%s' on %s:%d", world, self.device.host, self.device.port)
        return True

    def _scan(self, _now_ns: int) -> np.ndarray:
        """The ranges of the scan leaving now: the world ray-cast from where the robot is."""
        where = self.inputs.pose_in_hallway
        pose = where.value if where.seq > 0 else self.start_pose  # at its start until the world says
        if self.params.bodies and self.inputs.body_poses.seq > 0:
            self.engine.place_bodies(self.inputs.body_poses.value)
        self.engine.place_robot(pose)
        low, high, yaw = self.limits
        self.engine.scan(self.angles, self.ranges, low, high, yaw)
        np.nan_to_num(self.ranges, copy=False, nan=0.0)  # no echo: the TiM reports 0
        return self.ranges

    def compute(self) -> None:
        fault = self.params.sim_fault
        if fault != self.fault:
            self._switch(fault)
        if fault == "garbage":
            self.device.inject_garbage()  # noise before every telegram, as long as it lasts
        self.device.step(self.clock.now_ns() + self.ahead_ns)

    def _switch(self, fault: str) -> None:
        self.device.set_fault(fault)
        if fault == "none":
            self.log.info("simulated scanner fault cleared")
        else:
            self.log.warning("simulated scanner fault: %s", fault)
        self.fault = fault

    def wakeup_fds(self) -> tuple[int, ...]:
        """The listening socket and the client's: a `wake: data` thread answers a command at once."""
        return self.device.filenos() if self.device is not None else ()

    def clean(self) -> None:
        from hapticop.devices.link import withdraw_address

        if self.device is not None:
            withdraw_address(self.run_dir, self.name)
            self.device.close()
            self.device = None
