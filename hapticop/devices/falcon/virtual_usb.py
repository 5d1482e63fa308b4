"""A Falcon at the far end of a virtual USB cable: a pyusb backend that plays the device.

The USB driver (`usb_driver`) runs unchanged against it: it enumerates, opens, sends FTDI
vendor requests and bulk transfers through pyusb, and this backend answers as the hardware
would (docs/devices/falcon.md §7), in three layers:

- USB: 0403:CB48 "FALCON HAPTIC", one interface, bulk OUT 0x02 / IN 0x81, 64-byte packets,
  string descriptors, kernel-driver and claim state; faults: no permission, busy, unplugged.
- FT232R: the vendor requests change baud, latency timer, DTR and RTS; bytes travel at the
  set baud rate, each with its arrival time; an IN packet leaves when 62 bytes wait or the
  latency timer expires, and starts with 2 status bytes (only those when there is no data).
- DSP: a boot ROM with no firmware that answers nothing until a DTR pulse, then the
  handshake (`\\nC\\r` -> `\\nD,\\r` at 9600 baud), the autobaud `A`, and echoes every uploaded
  byte; when the host switches to 1.5 Mbaud after at least `min_upload` bytes, the
  "firmware" runs: each valid 16-byte command frame gets one status frame from a
  `SimulatedFalcon`, the same physics as the `sim` driver. It never looks at the image.

Time comes from a clock with `now()` and `sleep(s)`: `VirtualClock` only moves when a read
waits for the chip (tests: deterministic and instant), `WallClock` really sleeps, so a
benchmark sees the loop rate the latency timer allows.
"""

from __future__ import annotations

import enum
import errno
import math
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field
from types import SimpleNamespace

import usb.backend
import usb.core
from numpy.typing import ArrayLike

from hapticop.devices.falcon import ftdi
from hapticop.devices.falcon.codec import FrameReader, new_frame
from hapticop.devices.falcon.homing import HomingHand
from hapticop.devices.falcon.simulated import SimulatedFalcon

__all__ = ["VirtualClock", "WallClock", "Phase", "VirtualFalcon", "VirtualUsbBackend", "HomingHand"]

LOADER_BAUD = 9600.0
NORMAL_BAUD = 1_500_000.0
AUTOBAUD_MAX = 250_000.0  # the C2000 SCI autobaud locks onto slow rates only
TOLERANCE = 0.03  # a UART reads bytes sent within ~3 % of its own rate
HANDSHAKE = b"\nC\r"


class VirtualClock:
    """Simulated seconds that advance only when someone sleeps."""

    def __init__(self, start: float = 0.0) -> None:
        self.t = float(start)

    def now(self) -> float:
        return self.t

    def sleep(self, seconds: float) -> None:
        if seconds > 0:
            self.t += seconds


class WallClock:
    """The monotonic clock, with real sleeps (for benchmarks)."""

    now = staticmethod(time.monotonic)

    @staticmethod
    def sleep(seconds: float) -> None:
        if seconds > 0:
            time.sleep(seconds)


class Phase(enum.Enum):
    BOOT_ROM = "boot ROM, no firmware"  # silent until a DTR pulse
    HANDSHAKE = "loader handshake"  # waits for \nC\r at 9600 baud
    AUTOBAUD = "autobaud"  # waits for 'A'
    UPLOAD = "upload"  # echoes every byte
    RUNNING = "firmware running"  # 16-byte frames at 1.5 Mbaud


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


def _usb_error(message: str, code: int, err: int) -> usb.core.USBError:
    return usb.core.USBError(message, code, err)


@dataclass
class VirtualFalcon:
    """One Falcon: its USB identity, its FTDI chip state, its loader and its firmware.

    Test knobs (all optional): `firmware_loaded` (firmware survived from an earlier session),
    `handshake_failures` (that many handshakes get no answer), `handshake_leading_zero`
    (the macOS `00`), `autobaud_reply` (`b"A"` or `b"\\x13A"`), `corrupt_echo_at` (one upload
    byte arrives damaged: its echo differs and the image will not boot), `packet_data_limit`
    (smaller USB packets, to split frames), `permission_denied`, `busy`, `kernel_driver`.
    Faults during a run: `lose_bytes(n)`, `insert_bytes(data)`, `corrupt_byte(k)`, `mute()`, `unplug()`.
    The handle is `falcon` (a SimulatedFalcon); `hand(t, falcon)` returns the operator's force.
    """

    clock: VirtualClock | WallClock = field(default_factory=VirtualClock)
    serial: str = "FTVF0001"
    bus: int = 1
    address: int = 4
    falcon: SimulatedFalcon = field(default_factory=lambda: SimulatedFalcon(rng=0))
    hand: Callable[[float, SimulatedFalcon], ArrayLike] | None = None
    firmware_loaded: bool = False
    handshake_failures: int = 0
    handshake_leading_zero: bool = False
    autobaud_reply: bytes = b"A"
    corrupt_echo_at: int | None = None
    min_upload: int = 1024
    packet_data_limit: int = ftdi.PACKET_SIZE - ftdi.STATUS_BYTES
    status_bytes: bytes = b"\x01\x60"
    reply_delay_s: float = 50e-6  # firmware time from a command's last byte to its reply's first
    permission_denied: bool = False
    busy: bool = False
    kernel_driver: bool = False

    def __post_init__(self) -> None:
        self.plugged = True
        self._t = -math.inf
        self.phase = Phase.RUNNING if self.firmware_loaded else Phase.BOOT_ROM
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
        # loader state
        self._handshake = bytearray()
        self._handshake_done = False
        self._locked_baud = 0.0
        self.uploaded = 0
        self._image_damaged = False
        self.boots = 1 if self.firmware_loaded else 0
        # firmware state
        self._commands = FrameReader("command")
        self._frame = new_frame()
        self._reply = new_frame()
        self._sim_t = self._time()
        self.muted = False
        self.physics_ns = 0  # CPU time spent simulating the handle (benchmarks subtract it)
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

    def mute(self, on: bool = True) -> None:
        """The firmware stops answering frames (a hung DSP); USB stays up."""
        self.muted = on

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
            raise _usb_error("No such device (it may have been disconnected)", -4, errno.ENODEV)

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
            self._set_baud(ftdi.baud_from_divisor(value, index))
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
            if dtr and not self.dtr:  # rising edge: the DSP resets into its boot loader
                self._reset_to_loader()
            elif not dtr and self.dtr and self.phase is Phase.HANDSHAKE and self._handshake_done:
                self.phase = Phase.AUTOBAUD
            self.dtr = dtr

    def _reset_to_loader(self) -> None:
        self.phase = Phase.HANDSHAKE
        self._handshake.clear()
        self._handshake_done = False
        self.uploaded = 0
        self._image_damaged = False

    def _set_baud(self, baud: float) -> None:
        self.baud = baud
        if self.phase is Phase.UPLOAD and _near(baud, NORMAL_BAUD):
            if self.uploaded >= self.min_upload and not self._image_damaged:
                self._boot()
            else:
                self.phase = Phase.BOOT_ROM  # a short or damaged image: the DSP runs off into nothing

    def _boot(self) -> None:
        """The uploaded image starts: counts restart relative to where the handle is now."""
        old = self.falcon
        self.falcon = SimulatedFalcon(old.kinematics.geometry, old.mass, old.damping, rng=0,
                                      drive=old.kinematics.drive, initial_position=old.position,
                                      motor_limit=old.motor_limit, command_hold_s=old.command_hold_s)
        self.phase = Phase.RUNNING
        self._commands.clear()
        self._sim_t = self._time()
        self.boots += 1

    # ------------------------------------------------------------ the DSP
    def _receive(self, data: bytes, start: float, byte_s: float) -> None:
        end = start + len(data) * byte_s
        if self.phase is Phase.RUNNING:
            if _near(self.baud, NORMAL_BAUD):
                self._commands.feed(data)
                while self._commands.pop(self._frame):
                    self._command(end)
        elif self.phase is Phase.HANDSHAKE:
            if _near(self.baud, LOADER_BAUD):
                self._handshake += data
                if self._handshake.endswith(HANDSHAKE):
                    self._handshake.clear()
                    if self.handshake_failures > 0:
                        self.handshake_failures -= 1
                    else:
                        lead = b"\x00" if self.handshake_leading_zero else b""
                        self._emit(lead + b"\nD,\r", end, self.baud)
                        self._handshake_done = True
                del self._handshake[:-8]
        elif self.phase is Phase.AUTOBAUD:
            if self.baud <= AUTOBAUD_MAX and data[:1] == b"A":
                self._locked_baud = self.baud
                self.phase = Phase.UPLOAD
                self._emit(self.autobaud_reply, start + byte_s, self.baud)
                if len(data) > 1:
                    self._receive(data[1:], start + byte_s, byte_s)
        elif self.phase is Phase.UPLOAD:
            if _near(self.baud, self._locked_baud):
                echo = bytearray(data)
                at = self.corrupt_echo_at
                if at is not None and self.uploaded <= at < self.uploaded + len(data):
                    echo[at - self.uploaded] ^= 0x5A
                    self._image_damaged = True
                    self.corrupt_echo_at = None  # one line error, not a broken device
                self.uploaded += len(data)
                self._emit(bytes(echo), start + byte_s, self.baud)

    def _command(self, t: float) -> None:
        """One valid command frame arrived at t: physics up to t, then one status frame.

        As in the `sim` driver, the command acts over the interval since the previous one.
        """
        if self.muted:
            return
        started = time.thread_time_ns()
        falcon = self.falcon
        hand = self.hand(t, falcon) if self.hand is not None else (0.0, 0.0, 0.0)
        reply = falcon.exchange(self._frame, max(t - self._sim_t, 1e-6), hand, out=self._reply)
        self._sim_t = t
        self.physics_ns += time.thread_time_ns() - started
        if reply is not None:
            self._emit(self._reply.tobytes(), t + self.reply_delay_s, NORMAL_BAUD)

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



def _near(baud: float, wanted: float) -> bool:
    return wanted > 0 and abs(baud - wanted) <= TOLERANCE * wanted


_CONFIG = SimpleNamespace(bLength=9, bDescriptorType=2, wTotalLength=32, bNumInterfaces=1, bConfigurationValue=1,
                          iConfiguration=0, bmAttributes=0x80, bMaxPower=45, extra_descriptors=[])
_INTERFACE = SimpleNamespace(bLength=9, bDescriptorType=4, bInterfaceNumber=0, bAlternateSetting=0, bNumEndpoints=2,
                             bInterfaceClass=0xFF, bInterfaceSubClass=0xFF, bInterfaceProtocol=0xFF, iInterface=2,
                             extra_descriptors=[])
_ENDPOINTS = tuple(SimpleNamespace(bLength=7, bDescriptorType=5, bEndpointAddress=address, bmAttributes=2,
                                   wMaxPacketSize=ftdi.PACKET_SIZE, bInterval=0, bRefresh=0, bSynchAddress=0,
                                   extra_descriptors=[])
                   for address in (ftdi.EP_IN, ftdi.EP_OUT))
_GET_DESCRIPTOR = 6
_STRING = 3
_GET_LATENCY = 0x0A
_GET_MODEM_STATUS = 0x05


class _Handle:
    def __init__(self, device: VirtualFalcon) -> None:
        self.device = device
        self.open = True


class VirtualUsbBackend(usb.backend.IBackend):
    """pyusb's backend interface over a list of VirtualFalcons (pass it as `backend=`)."""

    def __init__(self, *devices: VirtualFalcon) -> None:
        super().__init__()
        self.devices = list(devices)

    def _device(self, handle: _Handle) -> VirtualFalcon:
        if not handle.open:
            raise _usb_error("Invalid parameter (closed handle)", -2, errno.EINVAL)
        handle.device.check()
        return handle.device

    # -- enumeration and descriptors
    def enumerate_devices(self):
        return [d for d in self.devices if d.plugged]

    def get_parent(self, dev):
        return None

    def get_device_descriptor(self, dev):
        return dev.device_descriptor

    def get_configuration_descriptor(self, dev, config):
        if config != 0:
            raise IndexError(config)
        return _CONFIG

    def get_interface_descriptor(self, dev, intf, alt, config):
        if (intf, alt, config) != (0, 0, 0):
            raise IndexError(intf)
        return _INTERFACE

    def get_endpoint_descriptor(self, dev, ep, intf, alt, config):
        return _ENDPOINTS[ep]

    # -- handles and interfaces
    def open_device(self, dev):
        dev.check()
        if dev.permission_denied:
            raise _usb_error("Access denied (insufficient permissions)", -3, errno.EACCES)
        return _Handle(dev)

    def close_device(self, handle):
        if handle.device.claimed_by is handle:
            handle.device.claimed_by = None
        handle.open = False

    def set_configuration(self, handle, config_value):
        self._device(handle)

    def get_configuration(self, handle):
        self._device(handle)
        return 1

    def set_interface_altsetting(self, handle, intf, altsetting):
        self._device(handle)

    def claim_interface(self, handle, intf):
        dev = self._device(handle)
        if dev.busy or (dev.claimed_by is not None and dev.claimed_by is not handle):
            raise _usb_error("Resource busy", -6, errno.EBUSY)
        if dev.kernel_driver:
            raise _usb_error("Resource busy (a kernel driver holds the interface)", -6, errno.EBUSY)
        dev.claimed_by = handle

    def release_interface(self, handle, intf):
        if handle.device.claimed_by is handle:
            handle.device.claimed_by = None

    def is_kernel_driver_active(self, handle, intf):
        return self._device(handle).kernel_driver

    def detach_kernel_driver(self, handle, intf):
        self._device(handle).kernel_driver = False

    def attach_kernel_driver(self, handle, intf):
        self._device(handle).kernel_driver = True

    def clear_halt(self, handle, ep):
        self._device(handle)

    def reset_device(self, handle):
        self._device(handle)

    # -- transfers
    def _claimed(self, handle) -> VirtualFalcon:
        dev = self._device(handle)
        if dev.claimed_by is not handle:
            raise _usb_error("Resource busy (interface not claimed)", -6, errno.EBUSY)
        return dev

    def bulk_write(self, handle, ep, intf, data, timeout):
        if ep != ftdi.EP_OUT:
            raise _usb_error("Pipe error", -9, errno.EPIPE)
        return self._claimed(handle).write(data.tobytes())

    def bulk_read(self, handle, ep, intf, buff, timeout):
        if ep != ftdi.EP_IN:
            raise _usb_error("Pipe error", -9, errno.EPIPE)
        return self._claimed(handle).read(buff, timeout)

    def ctrl_transfer(self, handle, bmRequestType, bRequest, wValue, wIndex, data, timeout):
        dev = self._device(handle)
        if bmRequestType == 0x80 and bRequest == _GET_DESCRIPTOR and wValue >> 8 == _STRING:
            index = wValue & 0xFF
            text = dev.strings(index)
            if index == 0:
                raw = bytes([4, _STRING, 0x09, 0x04])  # one language: en-US
            elif text is None:
                raise _usb_error("Pipe error", -9, errno.EPIPE)
            else:
                encoded = text.encode("utf-16-le")
                raw = bytes([2 + len(encoded), _STRING]) + encoded
            n = min(len(raw), len(data))
            memoryview(data).cast("B")[:n] = raw[:n]
            return n
        if bmRequestType == ftdi.VENDOR_OUT:
            dev.control_out(bRequest, wValue, wIndex)
            return 0
        if bmRequestType == 0xC0 and bRequest == _GET_LATENCY and len(data) >= 1:
            data[0] = dev.latency_ms & 0xFF
            return 1
        if bmRequestType == 0xC0 and bRequest == _GET_MODEM_STATUS and len(data) >= 2:
            memoryview(data).cast("B")[0:2] = dev.status_bytes
            return 2
        raise _usb_error("Pipe error (request not supported)", -9, errno.EPIPE)
