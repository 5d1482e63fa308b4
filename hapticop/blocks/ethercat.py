"""The EtherCAT master and its watchdog, for the ropod's segment of smart wheels.

The master exchanges the raw process-data images (168 bytes in, 36 bytes out per wheel,
packed little endian) every cycle; what the bytes mean is the business of the block that
reads them. The watchdog watches slave states and working counters and raises flags.
"""

from __future__ import annotations

from typing import Literal

from pydantic import Field

from hapticop.blocks.base import Block
from hapticop.blocks.interface import Interface, Params, Port, RateRange

SMARTWHEEL_INPUT_BYTES = 168
SMARTWHEEL_OUTPUT_BYTES = 36

EK1100 = 0x044C2C52
EK1122 = 0x04622C52
SWMC = 0x01705011


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
    driver: Literal["sim", "pysoem"] = Field("sim", description="'sim': an emulated ropod segment")
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


class EthercatWatchdogParams(Params):
    slaves: int = Field(7, ge=1, description="slaves on the segment, as the master sees them")
    expected_working_counter: int = Field(12, ge=1, description="working counter of a healthy exchange")
    lost_after_cycles: int = Field(10, ge=1, description="missed exchanges before a slave counts as lost")


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
