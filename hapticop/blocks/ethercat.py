"""The EtherCAT master and its watchdog, for the ropod's segment of smart wheels.

The master exchanges the raw process-data images (168 bytes in, 36 bytes out per wheel,
packed little endian) every cycle; what the bytes mean is the business of the block that
reads them. Driver `sim` exchanges them with a simulated ropod and publishes where that
robot truly is, for the simulated world. The watchdog watches slave states and working counters and raises flags.
"""

from __future__ import annotations

from typing import Literal

import numpy as np
from pydantic import Field

from hapticop.blocks.base import Block
from hapticop.blocks.interface import Interface, Params, Port, RateRange
from hapticop.devices.ropod.pdo import RXPDO_BYTES, TXPDO_BYTES

SMARTWHEEL_INPUT_BYTES = TXPDO_BYTES
SMARTWHEEL_OUTPUT_BYTES = RXPDO_BYTES

EK1100 = 0x044C2C52
EK1122 = 0x04622C52
SWMC = 0x01705011

AL_OP = 8  # EtherCAT application-layer state OPERATIONAL


class SlaveSpec(Params):
    product: int = Field(description="EtherCAT product code, checked at bring-up")
    wheel: int | None = Field(None, ge=0, description="index of the smart wheel this slave is, if one")


def _ropod_segment() -> dict[str, SlaveSpec]:
    return {
        "ek1100": SlaveSpec(product=EK1100),
        "ek1122_front": SlaveSpec(product=EK1122),
        "wheel_1": SlaveSpec(product=SWMC, wheel=0),
        "wheel_2": SlaveSpec(product=SWMC, wheel=1),
        "ek1122_rear": SlaveSpec(product=EK1122),
        "wheel_3": SlaveSpec(product=SWMC, wheel=2),
        "wheel_4": SlaveSpec(product=SWMC, wheel=3),
    }


class EthercatMasterParams(Params):
    driver: Literal["sim", "pysoem"] = Field("sim", description="'sim': a simulated ropod in the shared world")
    interface: str = Field("hapticop-ecat0", description="network interface of the segment (pysoem driver)")
    slaves: dict[str, SlaveSpec] = Field(
        default_factory=_ropod_segment, description="expected slaves in bus order"
    )

    @property
    def wheels(self) -> int:
        return sum(1 for s in self.slaves.values() if s.wheel is not None)


class EthercatMaster(Block):
    Params = EthercatMasterParams
    flags_written = {"operational": "every expected slave is in OP and exchanging process data"}

    @classmethod
    def interface(cls, params: EthercatMasterParams) -> Interface:
        wheels, slaves = params.wheels, len(params.slaves)
        outputs = {
            "wheel_sensors": Port("uint8", (wheels, SMARTWHEEL_INPUT_BYTES), "1", "TxPDO image per wheel"),
            "slave_states": Port("uint8", (slaves,), "1", "AL state per slave, bus order"),
            "working_counter": Port("int32", (), "1", "working counter of the last exchange"),
        }
        if params.driver == "sim":  # the simulated robot's true motion, for the simulated world
            outputs["robot_pose"] = Port("float64", (3,), "m, m, rad", "pose from where it started [x, y, theta]")
            outputs["robot_twist"] = Port("float64", (3,), "m/s, m/s, rad/s", "true twist [vx, vy, wz]")
        return Interface(
            inputs={"wheel_commands": Port("uint8", (wheels, SMARTWHEEL_OUTPUT_BYTES), "1", "RxPDO image per wheel")},
            outputs=outputs,
            flags_written=dict(cls.flags_written),
            rate=RateRange(100.0, 4000.0, "smart-wheel drives expect a steady cycle near 1 kHz"),
        )

    def configure_resources(self) -> None:
        if self.params.driver == "pysoem":
            raise RuntimeError("the pysoem driver is not part of this hapticop yet; use driver: sim")
        from hapticop.devices.ropod.plant import PlantParams, RopodPlant

        self.plant = RopodPlant(PlantParams(), rng=self.rng)  # its pose counts from where it starts
        self.rx = self.inputs.wheel_commands.value
        self.tx = self.outputs.wheel_sensors.value
        self.plant.write_sensors(self.tx)
        self.last_ns = self.clock.now_ns()
        self.outputs.slave_states.value[:] = AL_OP
        # Each wheel's process data counts 3 (read and write); the junctions count none.
        self.outputs.working_counter.value[...] = 3 * self.params.wheels
        return True

    def compute(self) -> None:
        now = self.clock.now_ns()
        dt = min(max(now - self.last_ns, 0), 5_000_000) / 1e9  # a late cycle is not a leap in time
        self.last_ns = now
        if dt > 0:
            self.plant.step(self.rx, dt, self.tx)
        out = self.outputs
        np.copyto(out.robot_pose.value, self.plant.pose)
        np.copyto(out.robot_twist.value, self.plant.twist)
        out.robot_pose.publish()
        out.robot_twist.publish()
        self.outputs.wheel_sensors.publish()
        self.outputs.slave_states.publish()
        self.outputs.working_counter.publish()
        self.flags["operational"] = True

    def clean(self) -> None:
        self.flags["operational"] = False


class EthercatWatchdogParams(Params):
    slaves: int = Field(7, ge=1, description="slaves on the segment, as the master sees them")
    expected_working_counter: int = Field(12, ge=1, description="working counter of a healthy exchange")
    lost_after_cycles: int = Field(10, ge=1, description="cycles without new process data before it counts as lost")


class EthercatWatchdog(Block):
    Params = EthercatWatchdogParams
    flags_written = {
        "all_operational": "every slave in OP with a healthy working counter",
        "slave_fault": "a slave left OP or stopped answering",
    }

    @classmethod
    def interface(cls, params: EthercatWatchdogParams) -> Interface:
        return Interface(
            inputs={
                "slave_states": Port("uint8", (params.slaves,), "1", "AL state per slave, bus order"),
                "working_counter": Port("int32", (), "1", "working counter of the last exchange"),
            },
            flags_written=dict(cls.flags_written),
            rate=RateRange(10.0, 4000.0),
        )

    def create(self) -> None:
        self.stale_cycles = 0
        self.healthy = False

    def compute(self) -> None:
        states, counter = self.inputs.slave_states, self.inputs.working_counter
        self.stale_cycles = 0 if states.fresh else self.stale_cycles + 1
        healthy = (states.seq > 0 and self.stale_cycles < self.params.lost_after_cycles
                   and bool(np.all(states.value == AL_OP))
                   and int(counter.value) == self.params.expected_working_counter)
        if healthy != self.healthy:
            if healthy:
                self.log.info("all %d slaves operational", self.params.slaves)
            else:
                self.log.warning("slave fault: states %s, working counter %d, %d cycles without process data",
                                 states.value.tolist(), int(counter.value), self.stale_cycles)
            self.healthy = healthy
        self.flags["all_operational"] = healthy
        self.flags["slave_fault"] = not healthy and states.seq > 0
