"""A segment of emulated slaves: one EtherCAT frame in, the same frame out, processed.

EtherCAT frames pass every slave in order; each reads and writes the datagrams addressed
to it on the fly and raises their working counters. This walks the datagram chain of one
frame (EtherType 0x88A4, type 1 = datagrams) through the slaves it reaches, in bus order.
The wiring follows from each slave's open ports, as a master reads it from the DL status: a
slave's first port faces the master, its others lead on, in the processing order 3, 1, 2 (so a
junction's branch comes before the rest of the line). A frame reaches a slave only if every
slave between it and the master has power and no cable on the way is cut: a powered-off
slave, or a cut cable, takes everything wired behind it off the segment, as the port before
it closes its loop. Auto-increment addressing counts positions among the slaves it reaches.
An access the ESC refuses (a full or empty mailbox) does not count. ARMW/FRMW (the system-time
distribution a DC master appends to its cyclic frame): the addressed slave reads, every other
one writes what it read.
"""

from __future__ import annotations

import struct
from collections.abc import Sequence

from hapticop.devices.ethercat.emulator.clocks import SegmentTiming
from hapticop.devices.ethercat.emulator.esc import Esc

__all__ = ["Segment", "ETHERTYPE", "COMMANDS", "parse_datagrams", "upstream_of"]

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


def upstream_of(slaves: Sequence[Esc]) -> list[int | None]:
    """Each slave's neighbour towards the master (None: the master), from the slaves' open ports:
    a slave takes the nearest slave before it in bus order that still has a free outgoing port."""
    upstream: list[int | None] = []
    free: list[list[int]] = []  # [position, outgoing ports not yet wired] of slaves with some
    for position, slave in enumerate(slaves):
        while free and free[-1][1] == 0:
            free.pop()
        if free:
            free[-1][1] -= 1
        upstream.append(free[-1][0] if free else None)
        if len(slave.ports) > 1:
            free.append([position, len(slave.ports) - 1])
    return upstream


class Segment:
    """Slaves in bus order; `process(payload, now_ns)` handles one frame's EtherCAT payload in place.
    `cut` holds the positions whose incoming cable is cut."""

    def __init__(self, slaves: Sequence[Esc]):
        self.slaves = list(slaves)
        self.upstream = upstream_of(self.slaves)
        self.cut: set[int] = set()
        self.frames = 0
        self.timing = SegmentTiming()

    def reached(self) -> list[bool]:
        """Whether a frame reaches each slave: it has power, its cable is whole, and so is the way there."""
        reached: list[bool] = []
        for position, slave in enumerate(self.slaves):
            up = self.upstream[position]
            reached.append(slave.present and position not in self.cut and (up is None or reached[up]))
        return reached

    def behind(self, position: int) -> list[int]:
        """The positions wired behind `position` (cut off with it)."""
        found: set[int] = set()
        for p, up in enumerate(self.upstream):
            if up == position or up in found:
                found.add(p)
        return sorted(found)

    def process(self, payload: memoryview, now_ns: int) -> bool:
        """Process an EtherCAT payload (after the EtherType); False if it is not one."""
        handled = False
        slaves = [s for s, reached in zip(self.slaves, self.reached()) if reached]
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
