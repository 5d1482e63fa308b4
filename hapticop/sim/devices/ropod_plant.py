"""The simulated ropod behind its smart wheels: it answers the EtherCAT master's process data.

Each step takes the newest wheel commands the master sent (the RxPDO images, over a
`DatagramLink`), moves the robot under them for the time since the last step
(hapticop.devices.ropod.plant), and answers with what the segment would: the wheels' sensors
(TxPDO images), every slave in OP and a full working counter. It publishes where the robot
truly is, from where it started, for the simulated world; a controller never sees that.
In the master's thread just before it, a command sent in one cycle's flush moves the robot
in the next cycle, whose compute reads the sensors: the order of a real exchange. In a scene
(scene_world) the contacts' wrench on the robot comes back as an external force on the platform.
"""

from __future__ import annotations

import numpy as np
from pydantic import Field

from hapticop.blocks.base import Block
from hapticop.blocks.interface import Params, Port, RateRange

_MAX_STEP_NS = 5_000_000  # a late cycle is not a leap in time


class RopodPlantSimulatorParams(Params):
    slaves: int = Field(7, ge=4, description="slaves the simulated segment reports, all in OP (the ropod's: "
                        "a coupler, two junctions and the four wheels)")


class RopodPlantSimulator(Block):
    Params = RopodPlantSimulatorParams
    simulator = True
    provides = frozenset({"ropod_wheels"})
    outputs = {
        "robot_pose": Port("float64", (3,), "m, m, rad", "pose from where it started [x, y, theta]"),
        "robot_twist": Port("float64", (3,), "m/s, m/s, rad/s", "true twist [vx, vy, wz]"),
    }
    inputs = {
        "contact_wrench": Port("float64", (3,), "N, N, N m", "what the world's contacts push the robot with, in its "
                               "frame (scene_world): pushing a box slows it, a wall stops it", required=False),
    }
    rate = RateRange(100.0, 4000.0, "the drives' model steps at the master's cycle")

    def create(self) -> None:
        self.link = None

    def configure_resources(self) -> None:
        from hapticop.devices.ethercat.link import SegmentReply
        from hapticop.devices.ethercat.master import AL_OP
        from hapticop.devices.link import DatagramLink
        from hapticop.devices.ropod.pdo import RXPDO_BYTES, TXPDO_BYTES
        from hapticop.devices.ropod.plant import PlantParams, RopodPlant

        self.plant = RopodPlant(PlantParams(), rng=self.rng)  # its pose counts from where it starts
        wheels = self.plant.units
        self.commands = np.zeros((wheels, RXPDO_BYTES), np.uint8)  # drives disabled until the master says
        self.frame = np.zeros_like(self.commands)
        self.reply = SegmentReply(wheels, TXPDO_BYTES, self.params.slaves)
        self.reply.states[:] = AL_OP
        self.reply.working_counter[0] = 3 * wheels  # each wheel's process data counts 3; the junctions none
        self.plant.write_sensors(self.reply.inputs)
        self.link = DatagramLink.device(self.run_dir, self.name, memory=self.clock.virtual)
        self.last_ns = self.clock.now_ns()

    def compute(self) -> None:
        link, frame = self.link, self.frame
        while (n := link.receive_into(frame)) > 0:  # the newest frame's commands hold
            if n != frame.nbytes:
                raise ValueError(f"the master sent {n} bytes of wheel commands, the plant takes {frame.nbytes}")
            np.copyto(self.commands, frame)
        now = self.clock.now_ns()
        dt = min(max(now - self.last_ns, 0), _MAX_STEP_NS) / 1e9
        self.last_ns = now
        contact = self.inputs.contact_wrench
        if contact.seq:
            external, wrench = self.plant.external, contact.value
            external[0], external[1], external[2] = float(wrench[0]), float(wrench[1]), float(wrench[2])
        if dt > 0:
            self.plant.step(self.commands, dt, self.reply.inputs)
        link.send(self.reply.buffer)
        out = self.outputs
        np.copyto(out.robot_pose.value, self.plant.pose)
        np.copyto(out.robot_twist.value, self.plant.twist)
        out.robot_pose.publish()
        out.robot_twist.publish()

    def clean(self) -> None:
        if self.link is not None:
            self.link.close()
            self.link = None
