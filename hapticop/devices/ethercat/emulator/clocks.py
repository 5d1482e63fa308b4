"""Distributed clocks of an emulated ESC: receive times, system time, and the SYNC0 pulse.

An ESC with DC (feature bit 2 of register 0x0008) keeps a local clock in ns. A write to
0x0900 latches the local time at which that frame passed each port (0x0900-0x090F) and the
processing unit (0x0918); from these the master computes each slave's offset (0x0920, so
local + offset is the common system time at 0x0910) and its propagation delay (0x0928).
Writing the system time (the FRMW a master appends to its cyclic frame) compares it with
the local copy and leaves the difference at 0x092C. The cyclic unit (0x0980-0x09A7) makes
SYNC0 pulses from a start time (0x0990, system time) every cycle (0x09A0) once cyclic
operation and SYNC0 are activated (0x0981 bits 0 and 1); a start time already past at
activation never fires (activation status 0x0984 bit 2), as on an ET1100. The emulated
clocks all run on the emulator's monotonic clock (no drift), and a frame reaches each ESC
after the forwarding delays of the ESCs and cables before it, so receive times differ.
"""

from __future__ import annotations

import struct
from collections.abc import Sequence

__all__ = ["DistributedClock", "SegmentTiming", "port_times", "AL_CODE_INVALID_DC_SYNC", "AL_CODE_INVALID_SYNC_CYCLE",
           "REG_FEATURES", "FEATURE_DC", "REG_RECEIVE_TIMES", "REG_SYSTEM_TIME", "REG_RECEIVE_TIME_UNIT",
           "REG_OFFSET", "REG_DELAY", "REG_DIFFERENCE", "REG_CYCLIC_CONTROL", "REG_ACTIVATION",
           "REG_ACTIVATION_STATUS", "REG_START_TIME", "REG_SYNC0_CYCLE", "REG_SYNC1_CYCLE"]

AL_CODE_INVALID_DC_SYNC = 0x0030
AL_CODE_INVALID_SYNC_CYCLE = 0x0035
REG_FEATURES, FEATURE_DC, FEATURE_DC64 = 0x0008, 0x04, 0x08
REG_RECEIVE_TIMES, REG_SYSTEM_TIME, REG_RECEIVE_TIME_UNIT = 0x0900, 0x0910, 0x0918
REG_OFFSET, REG_DELAY, REG_DIFFERENCE = 0x0920, 0x0928, 0x092C
REG_SPEED_START, REG_FILTER_DEPTH, REG_SPEED_FILTER_DEPTH = 0x0930, 0x0934, 0x0935
REG_CYCLIC_CONTROL, REG_ACTIVATION, REG_PULSE_LENGTH, REG_ACTIVATION_STATUS = 0x0980, 0x0981, 0x0982, 0x0984
REG_START_TIME, REG_SYNC0_CYCLE, REG_SYNC1_CYCLE = 0x0990, 0x09A0, 0x09A4
ACTIVATE_CYCLIC, ACTIVATE_SYNC0 = 0x01, 0x02
STATUS_SYNC0_PENDING, STATUS_START_PAST = 0x01, 0x04
MIN_SYNC0_CYCLE_NS = 125_000  # the shortest cycle the smart wheels' firmware runs at (assumed)
THROUGH_NS, CABLE_NS, PASS_NS = 500, 50, 200  # ESC processing and forwarding, a cable, a returning frame
_U64 = (1 << 64) - 1


def port_times(ports: Sequence[tuple[int, ...]]) -> list[list[int]]:
    """When a frame entering the first slave at 0 reaches each port of each slave (processing
    order 0, 3, 1, 2; a slave's next port leads to the next slave in bus order while any
    remain): port 0 on the way out, the others when the frame comes back through them."""
    times = [[0, 0, 0, 0] for _ in ports]

    def visit(k: int, t: int) -> tuple[int, int]:
        times[k][0] = t
        t += THROUGH_NS
        following = k + 1
        for port in (3, 1, 2):
            if port not in ports[k]:
                continue
            if following < len(ports):
                back, following = visit(following, t + CABLE_NS)
                t = back + CABLE_NS
            times[k][port] = t
            t += PASS_NS
        return t, following

    if ports:
        visit(0, 0)
    return times


class SegmentTiming:
    """Tells each DC slave when the current frame reaches it (the segment calls it per frame)."""

    def __init__(self):
        self.key: tuple[int, ...] = ()
        self.times: list[list[int]] = []

    def frame_arrives(self, slaves: Sequence, now_ns: int) -> None:
        key = tuple(map(id, slaves))
        if key != self.key:
            self.key, self.times = key, port_times([s.ports for s in slaves])
        for slave, times in zip(slaves, self.times):
            if slave.clock is not None:
                slave.clock.frame(now_ns, times)


class DistributedClock:
    """The DC registers of one ESC's memory `mem`. `requires_sync0`: the application runs on
    SYNC0 only, so SAFE-OP is refused (0x0030) until SYNC0 is configured and active."""

    def __init__(self, mem: bytearray, requires_sync0: bool = False, min_cycle_ns: int = MIN_SYNC0_CYCLE_NS):
        self.mem, self.requires_sync0, self.min_cycle_ns = mem, requires_sync0, min_cycle_ns
        self.reset()

    def reset(self) -> None:
        """Power-on values (the memory was just cleared)."""
        self.mem[REG_FEATURES] |= FEATURE_DC | FEATURE_DC64
        struct.pack_into("<H", self.mem, REG_SPEED_START, 0x1000)
        self.mem[REG_FILTER_DEPTH], self.mem[REG_SPEED_FILTER_DEPTH] = 0x04, 0x0C
        self.arrival_ns = 0
        self.port_times_ns: Sequence[int] = (0, 0, 0, 0)  # when this frame passed each port
        self.next_sync0: int | None = None  # system time of the next SYNC0 pulse while active

    def frame(self, now_ns: int, times: Sequence[int]) -> None:
        self.arrival_ns, self.port_times_ns = now_ns + times[0], times

    # --- time ---------------------------------------------------------------------------
    @property
    def offset(self) -> int:
        return struct.unpack_from("<Q", self.mem, REG_OFFSET)[0]

    def system_time(self, local_ns: int | None = None) -> int:
        return ((self.arrival_ns if local_ns is None else local_ns) + self.offset) & _U64

    @property
    def cycle_ns(self) -> int:
        return struct.unpack_from("<I", self.mem, REG_SYNC0_CYCLE)[0]

    # --- the master's accesses (hooks of the ESC's read and write) ----------------------
    def before_read(self, start: int, end: int) -> None:
        if end <= REG_SYSTEM_TIME or start >= REG_START_TIME + 8:
            return
        if start < REG_SYSTEM_TIME + 8 and end > REG_SYSTEM_TIME:
            struct.pack_into("<Q", self.mem, REG_SYSTEM_TIME, self.system_time())
        if self.next_sync0 is not None and start < REG_START_TIME + 8 and end > REG_START_TIME:
            struct.pack_into("<Q", self.mem, REG_START_TIME, self._next_pulse(self.system_time()))

    def after_write(self, start: int, end: int, written: bytes | memoryview) -> None:
        """`written`: the datagram's data, which started at `start`."""
        if end <= REG_RECEIVE_TIMES or start > REG_ACTIVATION:
            return
        if start <= REG_RECEIVE_TIMES < end:  # latch this frame's receive times
            struct.pack_into("<4I", self.mem, REG_RECEIVE_TIMES,
                             *((self.arrival_ns - self.port_times_ns[0] + t) & 0xFFFFFFFF for t in self.port_times_ns))
            struct.pack_into("<Q", self.mem, REG_RECEIVE_TIME_UNIT, self.arrival_ns)
        if start < REG_SYSTEM_TIME + 8 and end > REG_SYSTEM_TIME:
            self._compare_system_time(start, end, written)
        if start <= REG_ACTIVATION < end:
            self._activation()

    def _compare_system_time(self, start: int, end: int, written: bytes | memoryview) -> None:
        """A written system time is compared, not stored: the difference goes to 0x092C."""
        lo, hi = max(start, REG_SYSTEM_TIME), min(end, REG_SYSTEM_TIME + 8)
        ours = self.system_time()
        received = written[lo - start:hi - start]
        if lo != REG_SYSTEM_TIME or hi - lo not in (4, 8):  # a part of it: the rest as ours
            value = bytearray(struct.pack("<Q", ours))
            value[lo - REG_SYSTEM_TIME:hi - REG_SYSTEM_TIME] = received
            received = value
        bits = 32 if hi - REG_SYSTEM_TIME <= 4 else 64
        mask = (1 << bits) - 1
        difference = (int.from_bytes(received[:bits // 8], "little") - ours) & mask
        if difference >> (bits - 1):  # the local copy is ahead
            magnitude, sign = (-difference) & mask, 0x80000000
        else:
            magnitude, sign = difference, 0
        struct.pack_into("<I", self.mem, REG_DIFFERENCE, min(magnitude, 0x7FFFFFFF) | sign)
        struct.pack_into("<Q", self.mem, REG_SYSTEM_TIME, ours)

    def _activation(self) -> None:
        active = self.mem[REG_ACTIVATION]
        self.mem[REG_ACTIVATION_STATUS] = 0
        self.next_sync0 = None
        if active & ACTIVATE_CYCLIC and active & ACTIVATE_SYNC0:
            start = struct.unpack_from("<Q", self.mem, REG_START_TIME)[0]
            if start <= self.system_time():
                self.mem[REG_ACTIVATION_STATUS] = STATUS_START_PAST  # never fires
            else:
                self.next_sync0 = start
                self.mem[REG_ACTIVATION_STATUS] = STATUS_SYNC0_PENDING

    # --- the application's view ---------------------------------------------------------
    @property
    def sync0_running(self) -> bool:
        return self.next_sync0 is not None and self.cycle_ns > 0

    def _next_pulse(self, now: int) -> int:
        """The first SYNC0 pulse after system time `now` (while active, 0x0990 reads as it)."""
        cycle = self.cycle_ns
        if now < self.next_sync0 or cycle == 0:
            return self.next_sync0
        return self.next_sync0 + ((now - self.next_sync0) // cycle + 1) * cycle

    def sync0_pulses(self, now_ns: int) -> int:
        """How many SYNC0 pulses came since the last call, up to local time `now_ns`."""
        if self.next_sync0 is None:
            return 0
        now = self.system_time(now_ns)
        if now < self.next_sync0:
            return 0
        cycle = self.cycle_ns
        if cycle == 0:  # a single pulse at the start time
            self.next_sync0 = None
            return 1
        following = self._next_pulse(now)
        pulses = (following - self.next_sync0) // cycle
        self.next_sync0 = following
        self.mem[REG_ACTIVATION_STATUS] &= ~STATUS_SYNC0_PENDING
        return pulses

    def check_sync(self) -> int:
        """PRE-OP -> SAFE-OP: an AL status code if the SYNC0 configuration cannot run the application."""
        if not self.requires_sync0:
            return 0
        active = self.mem[REG_ACTIVATION]
        if (self.mem[REG_CYCLIC_CONTROL] & 0x01 or active & (ACTIVATE_CYCLIC | ACTIVATE_SYNC0)
                != ACTIVATE_CYCLIC | ACTIVATE_SYNC0 or self.next_sync0 is None or self.cycle_ns == 0):
            return AL_CODE_INVALID_DC_SYNC
        if self.cycle_ns < self.min_cycle_ns:
            return AL_CODE_INVALID_SYNC_CYCLE
        return 0
