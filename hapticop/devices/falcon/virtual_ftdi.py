"""The USB side of a virtual Falcon: its FT232R chip, with whatever sits on the chip's serial line.

What the host reaches through pyusb (docs/devices/falcon.md §1, §7):

- USB: 0403:CB48 "FALCON HAPTIC", one interface, bulk OUT 0x02 / IN 0x81, 64-byte packets,
  string descriptors, kernel-driver and claim state (the interface and endpoint descriptors
  are the backend's, in `virtual_usb`); faults: no permission, busy, unplugged.
- FT232R: the vendor requests change baud, latency timer, DTR and RTS; bytes travel at the
  set baud rate, each with its arrival time; an IN packet leaves when 62 bytes wait or the
  latency timer expires, and starts with 2 status bytes (only those when there is no data).

`VirtualFtdi` has nothing on its serial line: a subclass plays what is there (the Falcon's
DSP in `virtual_falcon`) through three hooks, `_receive` (host bytes arrived), `_dtr_edge`
and `_baud_changed`, and answers with `_emit`. Failures are pyusb's own errors, as libusb
would raise them, so this module needs pyusb.
"""

from __future__ import annotations

import errno
import math
from collections import deque
from dataclasses import dataclass, field
from types import SimpleNamespace

import usb.core

from hapticop.devices.falcon import ftdi
from hapticop.devices.falcon.virtual_clock import VirtualClock, WallClock

__all__ = ["VirtualFtdi", "usb_error"]


@dataclass(slots=True)
class _Segment:
    """Bytes the DSP sent back to back: byte i reaches the FTDI chip at start + (i+1) * byte_s."""

    start: float
    byte_s: float
    data: bytes
    taken: int = 0

    def ready(self, t: float) -> int:
        """How many of the bytes have arrived by time t (counted from the segment start)."""
        return min(len(self.data), max(0, math.floor((t - self.start) / self.byte_s + 1e-9)))

    def time_of(self, i: int) -> float:
        return self.start + (i + 1) * self.byte_s


def usb_error(message: str, code: int, err: int) -> usb.core.USBError:
    """The USBError libusb would raise: its message, libusb code and errno."""
    return usb.core.USBError(message, code, err)


@dataclass
class VirtualFtdi:
    """One FT232R behind USB: its identity, its requests, and the timing of its serial line.

    Test knobs (all optional): `packet_data_limit` (smaller USB packets, to split frames),
    `permission_denied`, `busy`, `kernel_driver`. Line faults during a run, on the bytes the
    far end sends: `lose_bytes(n)`, `insert_bytes(data)`, `corrupt_byte(k)`; and `unplug()`.
    """

    clock: VirtualClock | WallClock = field(default_factory=VirtualClock)
    serial: str = "FTVF0001"
    bus: int = 1
    address: int = 4
    packet_data_limit: int = ftdi.PACKET_SIZE - ftdi.STATUS_BYTES
    status_bytes: bytes = b"\x01\x60"
    permission_denied: bool = False
    busy: bool = False
    kernel_driver: bool = False

    def __post_init__(self) -> None:
        self.plugged = True
        self._t = -math.inf
        # FTDI chip state
        self.baud = 9600.0
        self.latency_ms = 16
        self.dtr = self.rts = False
        self.line = ftdi.LINE_8N1
        self.flow = ftdi.FLOW_NONE
        self._segments: deque[_Segment] = deque()
        self._tx_free = 0.0  # DSP -> chip line busy until
        self._rx_free = 0.0  # chip -> DSP line busy until
        self._last_flush = -math.inf
        # faults
        self._lose = 0
        self._insert = bytearray()
        self._corrupt: list[tuple[int, int]] = []  # (index in the sent stream, xor)
        self._sent = 0
        # observation
        self.requests: list[tuple[int, int, int]] = []  # (bRequest, wValue, wIndex), in order
        self.packets_sent = 0
        self.claimed_by: object | None = None

    # ------------------------------------------------------------ faults
    def lose_bytes(self, n: int) -> None:
        """The next n bytes the device sends never reach the host (a line error)."""
        self._lose += int(n)

    def corrupt_byte(self, k: int = 0, xor: int = 0x20) -> None:
        """The k-th byte the device sends from now on arrives with bits flipped."""
        self._corrupt.append((self._sent + int(k), int(xor)))

    def insert_bytes(self, data: bytes) -> None:
        """Spurious bytes ahead of the device's next reply."""
        self._insert += data

    def unplug(self) -> None:
        self.plugged = False

    # ------------------------------------------------------------ time
    def _time(self) -> float:
        """The device's time: the clock's, but never behind what the device already lived
        through (a clock that cannot sleep, such as a runtime's virtual clock inside one
        cycle, would otherwise keep a waiting read from ever seeing its data)."""
        self._t = max(self._t, self.clock.now())
        return self._t

    def _wait(self, now: float, seconds: float) -> None:
        if seconds > 0:
            self.clock.sleep(seconds)
            self._t = max(self._t, now + seconds)

    # ------------------------------------------------------------ USB: transfers
    def check(self) -> None:
        if not self.plugged:
            raise usb_error("No such device (it may have been disconnected)", -4, errno.ENODEV)

    def control_out(self, request: int, value: int, index: int) -> None:
        self.check()
        self.requests.append((request, value, index))
        now = self._time()
        if request == ftdi.Request.RESET:
            if value in (0, ftdi.PURGE_RX):
                self._purge_rx(now)
        elif request == ftdi.Request.MODEM_CTRL:
            self._modem(value)
        elif request == ftdi.Request.FLOW_CTRL:
            self.flow = value
        elif request == ftdi.Request.BAUD:
            self.baud = ftdi.baud_from_divisor(value, index)
            self._baud_changed()
        elif request == ftdi.Request.LINE:
            self.line = value
        elif request == ftdi.Request.LATENCY:
            self.latency_ms = max(1, value & 0xFF)

    def write(self, data: bytes) -> int:
        """Host bytes leave the chip at the set baud rate, back to back with earlier ones."""
        self.check()
        byte_s = 10.0 / self.baud
        start = max(self._time(), self._rx_free)
        self._rx_free = start + len(data) * byte_s
        self._receive(bytes(data), start, byte_s)
        return len(data)

    def read(self, buff, timeout_ms: int) -> int:
        """One IN packet: when 62 bytes wait or the latency timer runs out, whichever first."""
        self.check()
        now = self._time()
        limit = max(0, min(self.packet_data_limit, len(buff) - ftdi.STATUS_BYTES))
        due = self._flush_due(now, limit)
        if timeout_ms and due - now > timeout_ms / 1000.0:
            self._wait(now, timeout_ms / 1000.0)
            raise usb.core.USBTimeoutError("Operation timed out", -7, errno.ETIMEDOUT)
        self._wait(now, due - now)
        # The chip flushed at `due`; a host that wakes late gets the packet late, but the
        # chip's timer restarted at `due` and bytes arriving since belong to the next packet.
        view = memoryview(buff).cast("B")
        view[0:ftdi.STATUS_BYTES] = self.status_bytes
        n = self._take(due, limit, view, ftdi.STATUS_BYTES)
        self._last_flush = due
        self.packets_sent += 1
        return ftdi.STATUS_BYTES + n

    def _flush_due(self, now: float, limit: int) -> float:
        due = self._last_flush + self.latency_ms / 1000.0
        if due <= now:
            return now
        seen = 0
        for segment in self._segments:  # when would `limit` bytes have gathered?
            left = len(segment.data) - segment.taken
            if seen + left >= limit:
                return max(now, min(due, segment.time_of(segment.taken + limit - seen - 1)))
            seen += left
        return due

    def _take(self, now: float, limit: int, buff: memoryview, at: int) -> int:
        n = 0
        while self._segments and n < limit:
            segment = self._segments[0]
            k = min(segment.ready(now) - segment.taken, limit - n)
            if k <= 0:
                break
            buff[at + n:at + n + k] = segment.data[segment.taken:segment.taken + k]
            segment.taken += k
            n += k
            if segment.taken == len(segment.data):
                self._segments.popleft()
        return n

    def _purge_rx(self, now: float) -> None:
        """Drop what the chip holds; bytes still on the wire from the DSP arrive later."""
        while self._segments:
            segment = self._segments[0]
            segment.taken = max(segment.taken, segment.ready(now))
            if segment.taken < len(segment.data):
                break
            self._segments.popleft()

    def _emit(self, data: bytes, t: float, baud: float) -> None:
        """The DSP sends `data` from time t at `baud`, after whatever it is still sending."""
        if self._insert:
            data, self._insert = bytes(self._insert) + data, bytearray()
        if self._lose:
            k = min(self._lose, len(data))
            data, self._lose = data[k:], self._lose - k
        if not data:
            return
        if self._corrupt:
            damaged = bytearray(data)
            for at, xor in [c for c in self._corrupt if self._sent <= c[0] < self._sent + len(data)]:
                damaged[at - self._sent] ^= xor
                self._corrupt.remove((at, xor))
            data = bytes(damaged)
        self._sent += len(data)
        byte_s = 10.0 / baud
        start = max(t, self._tx_free)
        self._segments.append(_Segment(start, byte_s, data))
        self._tx_free = start + len(data) * byte_s

    # ------------------------------------------------------------ the chip's lines
    def _modem(self, value: int) -> None:
        mask, level = value >> 8, value & 0xFF
        if mask & ftdi.RTS:
            self.rts = bool(level & ftdi.RTS)
        if mask & ftdi.DTR:
            dtr = bool(level & ftdi.DTR)
            if dtr != self.dtr:
                self._dtr_edge(dtr)
            self.dtr = dtr

    # ------------------------------------------------------------ the far end of the serial line
    def _receive(self, data: bytes, start: float, byte_s: float) -> None:
        """Host bytes reach the far end: the first at `start`, each `byte_s` long. Nobody listens here."""

    def _dtr_edge(self, rising: bool) -> None:
        """DTR is about to change level (rising: to high). Nothing is wired to it here."""

    def _baud_changed(self) -> None:
        """The host set a new baud rate (`self.baud`). The far end does not care here."""

    # ------------------------------------------------------------ descriptors
    @property
    def device_descriptor(self) -> SimpleNamespace:
        return SimpleNamespace(
            bLength=18, bDescriptorType=1, bcdUSB=0x0200, bDeviceClass=0, bDeviceSubClass=0,
            bDeviceProtocol=0, bMaxPacketSize0=8, idVendor=ftdi.VENDOR_ID, idProduct=ftdi.PRODUCT_ID,
            bcdDevice=0x0600, iManufacturer=1, iProduct=2, iSerialNumber=3, bNumConfigurations=1,
            address=self.address, bus=self.bus, port_number=1, port_numbers=(1,), speed=2)

    def strings(self, index: int) -> str | None:
        return {1: "NOVINT", 2: ftdi.PRODUCT, 3: self.serial}.get(index)
