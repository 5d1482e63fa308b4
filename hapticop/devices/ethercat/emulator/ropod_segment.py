"""The ropod's EtherCAT segment: an EK1100 coupler, two EK1122 junctions, four smart wheels.

Bus order is the one ropod's own masters expect (EK1100, EK1122, SWMC, SWMC, EK1122,
SWMC, SWMC): each junction's first RJ45 port (processed before its E-bus port) carries a
chain of two wheels. A smart wheel (SWMC, product 0x01705011) has, like the real one, a
CoE mailbox on SM0/SM1 and distributed clocks: its 36 bytes of commands (SM2) and 168
bytes of sensors (SM3), packed little endian as in hapticop.devices.ropod.pdo, are
described by its PDO mapping and assignment objects (and by the SII's PDO categories), and
its firmware runs on SYNC0, so it refuses SAFE-OP until SYNC0 is configured. All four
wheels are one simulated ropod (hapticop.devices.ropod.plant): a wheel drives only while its
slave is in OP and its watchdog has not fired, as the drive firmware does; otherwise its row
of commands is zero. A wheel whose SYNC0 runs takes its commands and publishes its sensors
on SYNC0 pulses only, holding both in between.
"""

from __future__ import annotations

import numpy as np

from hapticop.devices.ethercat.emulator.esc import Esc
from hapticop.devices.ethercat.emulator.segment import Segment
from hapticop.devices.ethercat.emulator.sii import (
    FMMU_INPUTS,
    FMMU_OUTPUTS,
    SM_INPUTS,
    SM_MAILBOX_IN,
    SM_MAILBOX_OUT,
    SM_OUTPUTS,
    MailboxSpec,
    Pdo,
    PdoEntry,
    SlaveIdentity,
    SyncManagerSpec,
)
from hapticop.devices.ropod.pdo import RXPDO_BYTES, RXPDO_DTYPE, TXPDO_BYTES, TXPDO_DTYPE, new_rx_image, new_tx_image
from hapticop.devices.ropod.plant import PlantParams, RopodPlant

__all__ = ["EK1100", "EK1122", "SWMC", "BECKHOFF", "RopodSegment", "smart_wheel_identity"]

BECKHOFF = 0x00000002
EK1100, EK1122, SWMC = 0x044C2C52, 0x04622C52, 0x01705011
SWMC_VENDOR = 0x00000000  # not published: masters match the smart wheels on product code only
MAILBOX_OUT_AT, MAILBOX_IN_AT, MAILBOX_BYTES = 0x1000, 0x1080, 128
OUTPUTS_AT, INPUTS_AT = 0x1100, 0x1180
PLAIN_OUTPUTS_AT, PLAIN_INPUTS_AT = 0x1000, 0x1100  # the wheel without a mailbox: process data on SM0/SM1
_TYPES = {"<u2": 0x0006, "<u8": 0x001B, "<f4": 0x0008}  # CoE data types UINT16, UINT64, REAL32


def _entries(dtype: np.dtype, index: int) -> tuple[PdoEntry, ...]:
    return tuple(PdoEntry(index, sub + 1, dtype.fields[name][0].itemsize * 8, _TYPES[dtype.fields[name][0].str])
                 for sub, name in enumerate(dtype.names))


def smart_wheel_identity(mailbox: bool = True) -> SlaveIdentity:
    """The smart wheel as ropod's firmware presents it: a CoE mailbox and distributed clocks with
    SYNC0 required. `mailbox=False`: the plainer slave of the recorded SOEM bring-up trace, its
    process data on SM0/SM1 and its PDOs in the SII only."""
    if not mailbox:
        return SlaveIdentity(
            name="SWMC", vendor=SWMC_VENDOR, product=SWMC, revision=0x00000001,
            sync_managers=(SyncManagerSpec(PLAIN_OUTPUTS_AT, RXPDO_BYTES, 0x64, SM_OUTPUTS),
                           SyncManagerSpec(PLAIN_INPUTS_AT, TXPDO_BYTES, 0x20, SM_INPUTS)),
            fmmus=(FMMU_OUTPUTS, FMMU_INPUTS),
            rx_pdos=(Pdo(0x1600, 0, _entries(RXPDO_DTYPE, 0x7000)),),
            tx_pdos=(Pdo(0x1A00, 1, _entries(TXPDO_DTYPE, 0x6000)),),
            ebus_current_ma=0,
        )
    return SlaveIdentity(
        name="SWMC", vendor=SWMC_VENDOR, product=SWMC, revision=0x00000001,
        sync_managers=(SyncManagerSpec(MAILBOX_OUT_AT, MAILBOX_BYTES, 0x26, SM_MAILBOX_OUT),  # mailbox, write
                       SyncManagerSpec(MAILBOX_IN_AT, MAILBOX_BYTES, 0x22, SM_MAILBOX_IN),  # mailbox, read
                       SyncManagerSpec(OUTPUTS_AT, RXPDO_BYTES, 0x64, SM_OUTPUTS),  # 3-buffer, write, watchdog
                       SyncManagerSpec(INPUTS_AT, TXPDO_BYTES, 0x20, SM_INPUTS)),
        fmmus=(FMMU_OUTPUTS, FMMU_INPUTS),
        rx_pdos=(Pdo(0x1600, 2, _entries(RXPDO_DTYPE, 0x7000)),),
        tx_pdos=(Pdo(0x1A00, 3, _entries(TXPDO_DTYPE, 0x6000)),),
        ebus_current_ma=0,
        mailbox=MailboxSpec(MAILBOX_OUT_AT, MAILBOX_BYTES, MAILBOX_IN_AT, MAILBOX_BYTES),
        distributed_clocks=True,
        requires_sync0=True,
    )


def _coupler() -> SlaveIdentity:
    return SlaveIdentity(name="EK1100", vendor=BECKHOFF, product=EK1100, revision=0x00110000,
                         strings=("EtherCAT Coupler (2A E-Bus)",), ebus_current_ma=-2000)


def _junction() -> SlaveIdentity:
    return SlaveIdentity(name="EK1122", vendor=BECKHOFF, product=EK1122, revision=0x00110000,
                         strings=("2 port EtherCAT junction",), ebus_current_ma=220)


class RopodSegment:
    """The seven slaves and the robot behind the four wheels. `step(now_ns)` runs the physics."""

    max_step_s = 0.005  # a late step is not a leap in time

    def __init__(self, plant: PlantParams = PlantParams(), rng: np.random.Generator | None = None,
                 wheel: SlaveIdentity | None = None):
        wheel = wheel or smart_wheel_identity()
        self.wheels = [Esc(wheel, ports=(0, 1)), Esc(wheel, ports=(0,)), Esc(wheel, ports=(0, 1)),
                       Esc(wheel, ports=(0,))]
        self.slaves = [Esc(_coupler(), ports=(0, 1)), Esc(_junction(), ports=(0, 1, 3)), self.wheels[0], self.wheels[1],
                       Esc(_junction(), ports=(0, 3)), self.wheels[2], self.wheels[3]]
        self.segment = Segment(self.slaves)
        self.plant = RopodPlant(plant, rng=rng)
        self.rx = new_rx_image(len(self.wheels))
        self.sampled = [True] * len(self.wheels)  # which wheels' firmware ran this step (a SYNC0 pulse came)
        self.tx = new_tx_image(len(self.wheels))
        self.plant.write_sensors(self.tx)
        self._publish_sensors()
        self.last_step_ns: int | None = None

    def tick(self, now_ns: int) -> None:
        for slave in self.slaves:
            if slave.present:
                slave.tick(now_ns)

    def step(self, now_ns: int) -> None:
        """Advance the robot to now with the commands of the wheels that are live."""
        if self.last_step_ns is None:
            self.last_step_ns = now_ns
            return
        dt = min(max(now_ns - self.last_step_ns, 0) / 1e9, self.max_step_s)
        self.last_step_ns = now_ns
        live = False
        sampled = self.sampled
        for i, wheel in enumerate(self.wheels):
            clock = wheel.clock
            sampled[i] = clock is None or not clock.sync0_running or clock.sync0_pulses(now_ns) > 0
            buffer = wheel.output_buffer() if wheel.outputs_live else None
            if buffer is None:
                self.rx[i] = 0  # drive disabled: the firmware's safe state
            elif sampled[i]:
                self.rx[i] = np.frombuffer(buffer, np.uint8)
            live = live or buffer is not None
        if not live and not self.plant.twist.any():
            return  # at rest with every drive off, the robot stays at rest: nothing to integrate
        if dt > 0:
            self.plant.step(self.rx, dt, self.tx)
        self._publish_sensors(sampled)

    def _publish_sensors(self, which=None) -> None:
        for i, wheel in enumerate(self.wheels):
            if which is None or which[i]:
                wheel.write_inputs(self.tx[i].data)
