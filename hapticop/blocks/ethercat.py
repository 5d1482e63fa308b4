"""The EtherCAT master and its watchdog, for the ropod's segment of smart wheels.

The master exchanges the raw process-data images (168 bytes in, 36 bytes out per wheel,
packed little endian) every cycle; what the bytes mean is the business of the block that
reads them. It sends in its flush and receives in the next compute, over one link
(hapticop.devices.ethercat.link): driver `pysoem` is the real master (SOEM), which brings the
segment up to OP against the expected slaves and exchanges real frames with the ropod or
the emulated segment (hapticop.devices.ethercat.emulator); driver `sim` exchanges the images
with the activity that simulates the wheels. The watchdog watches slave states and working
counters, raises flags, and with pysoem runs SOEM's recovery of slaves that left OP on the
master of its own process.
"""

from __future__ import annotations

from typing import Literal

import numpy as np
from pydantic import Field

from hapticop.blocks.base import Block
from hapticop.blocks.interface import DeviceParams, Interface, Params, Port, RateRange
from hapticop.devices.ethercat.link import DatagramSegment, SegmentLink
from hapticop.devices.ropod.pdo import RXPDO_BYTES, RXPDO_ENTRY_BITS, TXPDO_BYTES, TXPDO_ENTRY_BITS

SMARTWHEEL_INPUT_BYTES = TXPDO_BYTES
SMARTWHEEL_OUTPUT_BYTES = RXPDO_BYTES
# What the master checks a smart wheel against: its process data (bytes, and entry sizes over
# CoE) and that it runs on SYNC0.
SMARTWHEEL_LAYOUT = (RXPDO_BYTES, TXPDO_BYTES, RXPDO_ENTRY_BITS, TXPDO_ENTRY_BITS, True)

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


class EthercatMasterParams(DeviceParams):
    simulated_by = "a ropod_plant"
    driver: Literal["pysoem", "sim"] = Field("pysoem", description="'pysoem': the SOEM master on `interface`; "
                                              "'sim': the segment the `simulator` activity simulates")
    interface: str = Field("hapticop-ecat0", description="network interface of the segment (pysoem driver)")
    slaves: dict[str, SlaveSpec] = Field(
        default_factory=_ropod_segment, description="expected slaves in bus order"
    )
    receive_timeout_us: int = Field(2000, ge=100, le=100_000, description="how long a cycle waits for its frame")
    frame_timeout_us: int = Field(2000, ge=100, le=100_000, description="how long a configuration datagram "
                                  "may take at bring-up and recovery (SOEM's EC_TIMEOUTRET)")
    mailbox_timeout_us: int = Field(700_000, ge=1000, le=30_000_000, description="how long a slave may take to "
                                    "answer a CoE mailbox request at bring-up (SOEM's EC_TIMEOUTRXM)")
    start_timeout_s: float = Field(5.0, gt=0, description="bring-up to OP and the wheels' encoders ready, at most")


    @property
    def wheels(self) -> int:
        return sum(1 for s in self.slaves.values() if s.wheel is not None)


class EthercatMaster(Block):
    """The EtherCAT master: brings the segment to OP, then exchanges the wheels' process data each cycle."""

    Params = EthercatMasterParams
    needs = {"simulator": "ropod_wheels"}
    flags_written = {"operational": "every expected slave is in OP and exchanging process data"}

    @classmethod
    def interface(cls, params: EthercatMasterParams) -> Interface:
        wheels, slaves = params.wheels, len(params.slaves)
        return Interface(
            inputs={"wheel_commands": Port("uint8", (wheels, SMARTWHEEL_OUTPUT_BYTES), "1", "RxPDO image per wheel")},
            outputs={
                "wheel_sensors": Port("uint8", (wheels, SMARTWHEEL_INPUT_BYTES), "1", "TxPDO image per wheel"),
                "slave_states": Port("uint8", (slaves,), "1", "AL state per slave, bus order"),
                "working_counter": Port("int32", (), "1", "working counter of the last exchange"),
            },
            flags_written=dict(cls.flags_written),
            rate=RateRange(100.0, 4000.0, "smart-wheel drives expect a steady cycle near 1 kHz"),
        )

    @classmethod
    def preflight(cls, params: EthercatMasterParams, timeout_s: float) -> str | None:
        """The real master: its network interface, and the right to open it raw."""
        if params.driver != "pysoem":
            return None
        from hapticop.devices.ethercat.probe import interface_problem

        return interface_problem(params.interface)

    def create(self) -> None:
        self.link: SegmentLink | None = None

    def configure_resources(self) -> bool:
        """Bring the segment up; the wheels get disabled drives and zero setpoints until the
        controller runs."""
        if self.link is None:
            self.rx = self.inputs.wheel_commands.value
            self.rx.fill(0)
            self.in_op = np.zeros(self.outputs.slave_states.value.shape, dtype=bool)  # scratch: slaves in OP
            self.link = self._connect()
        try:
            return self.link.start(self.rx, self.outputs.wheel_sensors.value)
        except Exception:
            self.link.close(self.rx)  # a failed bring-up starts over when configured again
            self.link = None
            raise

    def _connect(self) -> SegmentLink:
        p = self.params
        if p.driver == "sim":
            from hapticop.devices.link import DatagramLink

            link = DatagramLink.host(self.run_dir, p.simulator, memory=self.clock.virtual)
            return DatagramSegment(link, p.wheels, SMARTWHEEL_INPUT_BYTES, len(p.slaves))
        from hapticop.devices.ethercat.master import ExpectedSlave, SoemLink, SoemMaster

        expected = [ExpectedSlave(name, spec.product, *SMARTWHEEL_LAYOUT) if spec.wheel is not None
                    else ExpectedSlave(name, spec.product) for name, spec in p.slaves.items()]
        wheels = [(spec.wheel, i) for i, spec in enumerate(p.slaves.values()) if spec.wheel is not None]
        master = SoemMaster(p.interface, expected, p.receive_timeout_us, p.start_timeout_s, p.frame_timeout_us,
                            cycle_ns=self.context.period_ns or 1_000_000, mailbox_timeout_us=p.mailbox_timeout_us)
        return SoemLink(master, wheels, _encoders_ready, self.clock.now_ns, self.log)

    def compute(self) -> None:
        """Read: the inputs the frame sent at the end of the last cycle brought back. Commands
        go out in `flush`."""
        out = self.outputs
        wkc = self.link.receive(out.wheel_sensors.value, out.slave_states.value)
        if wkc < 0:  # no frame came back: nothing new to say
            self.flags["operational"] = False
            return
        out.working_counter.value[...] = wkc
        out.wheel_sensors.publish()
        out.slave_states.publish()
        out.working_counter.publish()
        self.flags["operational"] = wkc == self.link.expected_wkc and _all_in_op(out.slave_states.value, self.in_op)

    def flush(self) -> None:
        """Write: the wheel commands this cycle computed, sent now."""
        self.link.send(self.rx)

    def clean(self) -> None:
        self.flags["operational"] = False
        if self.link is not None:
            self.rx.fill(0)  # drives disabled before the segment is let go
            self.link.close(self.rx)
            self.link = None


def _all_in_op(states: np.ndarray, scratch: np.ndarray) -> bool:
    """Every slave in OP, compared in place: nothing allocated, and no `all()`, which costs four times
    what counting does on arrays this small."""
    np.equal(states, AL_OP, out=scratch)
    return np.count_nonzero(scratch) == scratch.size


def _encoders_ready(sensors: np.ndarray) -> bool:
    """Every wheel reports its encoders ready (the drives may be enabled)."""
    from hapticop.devices.ropod.pdo import Stat1, txpdo_view

    status = txpdo_view(sensors)["status1"]
    return bool(np.all((status & int(Stat1.ENCODERS_OK)) == int(Stat1.ENCODERS_OK)))


class EthercatWatchdogParams(Params):
    slaves: int = Field(7, ge=1, description="slaves on the segment, as the master sees them")
    expected_working_counter: int = Field(12, ge=1, description="working counter of a healthy exchange")
    lost_after_cycles: int = Field(10, ge=1, description="cycles without new process data, or with a short working "
                                   "counter, before it counts as a fault (one late frame is not a lost wheel)")
    interface: str | None = Field(
        None, description="with the pysoem driver: the master's interface; the watchdog then runs SOEM's slave "
        "check and recovery on that master, which must be open in this process (deploy both threads as 'thread')")
    state_poll_ms: float = Field(10.0, gt=0, description="read the AL states this often even while the working "
                                 "counter is healthy (an AL error in SAFE-OP keeps it full)")
    retry_lost_ms: float = Field(100.0, gt=0, description="how often to try to recover a lost slave (each try "
                                 "holds pysoem's GIL through its timeouts)")
    silent_segment_ms: float = Field(500.0, ge=0, description="a state read in which no slave answers is believed "
                                     "(every slave gone) only once the reads stay silent this long: a lost or late "
                                     "frame is not a segment gone (the fault is raised meanwhile all the same)")
    fault_hold_ms: float = Field(200.0, ge=0, description="a raised slave_fault stays raised at least this long "
                                 "after the segment is healthy again: every loop that must hold the robot sees it, "
                                 "and a flapping wheel does not jerk the robot back into motion")


class EthercatWatchdog(Block):
    """Watches every slave's AL state and the working counter; raises `slave_fault` when one is lost."""

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
        self.short_cycles = 0
        self.healthy = False
        self.check = None
        self.last_poll_ns = 0
        self.fault_until_ns = 0

    def configure_resources(self) -> None:
        """What the cycle compares against, from the parameters (again after a live change)."""
        p = self.params
        self.in_op = np.zeros(p.slaves, dtype=bool)  # scratch: which slaves are in OP this cycle
        self.expected_wkc, self.lost_after = p.expected_working_counter, p.lost_after_cycles

    def _recover(self) -> bool:
        """SOEM's check on the master of this process: True while every slave is in OP."""
        from hapticop.devices.ethercat.master import find_master

        master = find_master(self.params.interface)
        if master is None or not master.up:
            self.check = None
            return False
        if self.check is None or self.check.master is not master:
            from hapticop.devices.ethercat.recovery import SlaveCheck

            self.check = SlaveCheck(master, self.log.warning, self.params.retry_lost_ms, self.params.silent_segment_ms)
        now = self.clock.now_ns()
        if self.check.needed() or now - self.last_poll_ns >= self.params.state_poll_ms * 1e6:
            self.last_poll_ns = now
            self.check.check(on_fault=self._fault_now)
        return not self.check.pending

    def _fault_now(self) -> None:
        """A slave is below OP: say so before the recovery steps block this thread."""
        self.flags["slave_fault"] = True
        self.flags["all_operational"] = False

    def compute(self) -> None:
        states, counter, lost_after = self.inputs.slave_states, self.inputs.working_counter, self.lost_after
        stale = self.stale_cycles = 0 if states.fresh else self.stale_cycles + 1
        in_op = self._recover() if self.params.interface else True
        short = self.short_cycles = self.short_cycles + 1 if int(counter.value) != self.expected_wkc else 0
        seen = states.seq > 0
        healthy = (in_op and seen and stale < lost_after and short < lost_after
                   and _all_in_op(states.value, self.in_op))
        if healthy != self.healthy:
            if healthy:
                self.log.info("all %d slaves operational", self.params.slaves)
            else:
                self.log.warning("slave fault: states %s, working counter %d (%d cycles short), "
                                 "%d cycles without process data", states.value.tolist(), int(counter.value),
                                 short, stale)
            self.healthy = healthy
        flags = self.flags
        flags["all_operational"] = healthy
        now, fault = self.clock.now_ns(), not healthy and seen
        if fault:
            self.fault_until_ns = now + int(self.params.fault_hold_ms * 1e6)
        flags["slave_fault"] = fault or now < self.fault_until_ns
