"""A segment of emulated slaves: one EtherCAT frame in, the same frame out, processed.

EtherCAT frames pass every slave in order; each reads and writes the datagrams addressed
to it on the fly and raises their working counters. This walks the datagram chain of one
frame (EtherType 0x88A4, type 1 = datagrams) through the present slaves in bus order.
Auto-increment addressing counts positions among the slaves that are there, as on a wire
where a powered-off slave's port is closed. An access the ESC refuses (a full or empty
mailbox) does not count. ARMW/FRMW (the system-time distribution a DC master appends to
its cyclic frame): the addressed slave reads, every other one writes what it read.
"""

from __future__ import annotations

import struct
from collections.abc import Sequence

from hapticop.devices.ethercat.emulator.clocks import SegmentTiming
from hapticop.devices.ethercat.emulator.esc import Esc

__all__ = ["Segment", "ETHERTYPE", "COMMANDS", "parse_datagrams"]

ETHERTYPE = 0x88A4
NOP, APRD, APWR, APRW, FPRD, FPWR, FPRW, BRD, BWR, BRW, LRD, LWR, LRW, ARMW, FRMW = range(15)
COMMANDS = {NOP: "NOP", APRD: "APRD", APWR: "APWR", APRW: "APRW", FPRD: "FPRD", FPWR: "FPWR", FPRW: "FPRW",
            BRD: "BRD", BWR: "BWR", BRW: "BRW", LRD: "LRD", LWR: "LWR", LRW: "LRW", ARMW: "ARMW", FRMW: "FRMW"}
_HEADER = 10  # cmd, idx, address (4), length/flags (2), irq (2)


def parse_datagrams(payload: memoryview):
    """(offset of header, cmd, index, address, data length) of each datagram of an EtherCAT payload."""
    (word,) = struct.unpack_from("<H", payload, 0)
    total, kind = word & 0x07FF, word >> 12
    if kind != 1 or total + 2 > len(payload):
        return
    at = 2
    while at + _HEADER + 2 <= 2 + total:
        cmd, index, address, flags = struct.unpack_from("<BBIH", payload, at)
        length = flags & 0x07FF
        if at + _HEADER + length + 2 > 2 + total:
            return
        yield at, cmd, index, address, length
        if not flags & 0x8000:
            return
        at += _HEADER + length + 2


class Segment:
    """Slaves in bus order; `process(payload, now_ns)` handles one frame's EtherCAT payload in place."""

    def __init__(self, slaves: Sequence[Esc]):
        self.slaves = list(slaves)
        self.frames = 0
        self.timing = SegmentTiming()

    def present(self) -> list[Esc]:
        return [s for s in self.slaves if s.present]

    def process(self, payload: memoryview, now_ns: int) -> bool:
        """Process an EtherCAT payload (after the EtherType); False if it is not one."""
        handled = False
        slaves = self.present()
        self.timing.frame_arrives(slaves, now_ns)
        for at, cmd, _, address, length in parse_datagrams(payload):
            handled = True
            data = payload[at + _HEADER:at + _HEADER + length]
            wkc_at = at + _HEADER + length
            wkc = struct.unpack_from("<H", payload, wkc_at)[0]
            adp, ado = address & 0xFFFF, address >> 16
            if cmd in (LRD, LWR, LRW):
                reads, writes = cmd != LWR, cmd != LRD
                for s in slaves:
                    wkc += s.logical(address, data, reads, writes, now_ns)
            else:
                for s in slaves:
                    wkc += self._physical(s, cmd, adp, ado, data, now_ns)
                    if cmd in (APRD, APWR, APRW, ARMW, BRD, BWR, BRW):
                        adp = (adp + 1) & 0xFFFF
                struct.pack_into("<H", payload, at + 2, adp)
            struct.pack_into("<H", payload, wkc_at, wkc & 0xFFFF)
        if handled:
            self.frames += 1
        return handled

    @staticmethod
    def _physical(s: Esc, cmd: int, adp: int, ado: int, data: memoryview, now_ns: int) -> int:
        if cmd in (BRD, BWR, BRW):
            if cmd == BRD:
                return int(s.read(ado, data, combine=True))
            if cmd == BWR:
                return int(s.write(ado, data, now_ns))
            return int(s.read(ado, data, combine=True)) + 2 * int(s.write(ado, data, now_ns))
        if cmd in (APRD, APWR, APRW, ARMW):
            addressed = adp == 0
        elif cmd in (FPRD, FPWR, FPRW, FRMW):
            addressed = adp == s.station
        else:
            return 0
        if cmd in (ARMW, FRMW):  # the addressed slave reads, every other one writes
            return int(s.read(ado, data) if addressed else s.write(ado, data, now_ns))
        if not addressed:
            return 0
        if cmd in (APRD, FPRD):
            return int(s.read(ado, data))
        if cmd in (APWR, FPWR):
            return int(s.write(ado, data, now_ns))
        incoming = bytes(data)
        return int(s.read(ado, data)) + 2 * int(s.write(ado, memoryview(incoming), now_ns))
