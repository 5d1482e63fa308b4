"""The Falcon on USB: FTDI set-up, firmware loading and the 1 kHz frame exchange, over pyusb.

The sequence is libnifalcon's libusb backend as docs/devices/falcon.md §2 describes it, with
three deliberate differences:
- the loader's replies are collected over several USB packets (a 4-byte reply at 9600 baud
  can straddle two), and the reply to `A` may carry a leading 0x13 (§2.3 step 8);
- normal-mode reads are one 64-byte packet each, latency timer 1 ms, and the bytes go
  through `FrameReader`, which resynchronises after a lost or extra byte (§4.3);
- every wait is bounded in USB packets, not wall time, so the driver needs no clock.

The I/O cycle (§5) is one-for-one: `exchange` first reads the reply to the previous command,
then writes the next one. If nothing came back it does not write again (the firmware answers
each command exactly once) until `resend_after` empty reads, then assumes the reply lost.

The driver talks only pyusb's API; which backend is beneath (libusb, or the project's virtual
Falcon in `virtual_usb`) is the caller's choice, and the driver cannot tell them apart. What
it raises, and the advice its messages carry, is in `usb_errors`.
"""

from __future__ import annotations

import array
import errno
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from hapticop.devices.falcon import ftdi
from hapticop.devices.falcon.codec import FrameCodec, FrameReader, Status, new_frame
from hapticop.devices.falcon.usb_errors import FalconLoaderError, FalconUsbError, explain

__all__ = ["FalconUsb", "FalconInfo", "system_backend", "find_falcons", "describe_falcons", "connect"]

HANDSHAKE = b"\nC\r"
HANDSHAKE_REPLIES = (b"\nD,\r", b"\x00\nD,\r")  # the leading 00 was seen on macOS
AUTOBAUD = b"A"
CHUNK = 62  # one USB packet's worth of data: 62 + 2 status bytes = 64


def system_backend(find_library: Callable[[str], str | None] | None = None):
    """The libusb backend pyusb would use, or a FalconUsbError saying what to install."""
    try:
        import usb.backend.libusb0
        import usb.backend.libusb1
    except ImportError:
        raise FalconUsbError("pyusb is not installed: pip install 'hapticop[hw]'") from None
    for module in (usb.backend.libusb1, usb.backend.libusb0):
        backend = module.get_backend(find_library=find_library)
        if backend is not None:
            return backend
    raise FalconUsbError("no USB backend: libusb is not installed "
                         "(Debian/Ubuntu: apt install libusb-1.0-0; macOS: brew install libusb)")


def find_falcons(backend=None) -> list:
    """Every device with the Falcon's VID:PID 0403:CB48 (listing needs no permissions)."""
    import usb.core

    backend = backend if backend is not None else system_backend()
    try:
        return list(usb.core.find(find_all=True, idVendor=ftdi.VENDOR_ID, idProduct=ftdi.PRODUCT_ID,
                                  backend=backend))
    except usb.core.USBError as error:
        raise explain(error, "listing USB devices") from None


@dataclass
class FalconInfo:
    """What `hapticop devices` shows about one Falcon."""

    index: int
    bus: int | None
    address: int | None
    serial: str | None = None
    product: str | None = None
    firmware_running: bool | None = None  # None: not probed
    problem: str | None = None  # why it cannot be used, in words


def describe_falcons(backend=None, probe_firmware: bool = True) -> list[FalconInfo]:
    """Open each Falcon briefly: strings, access rights and whether firmware answers."""
    found = []
    for index, device in enumerate(find_falcons(backend)):
        info = FalconInfo(index, device.bus, device.address)
        falcon = None
        try:
            import usb.util

            falcon = FalconUsb(device)  # first: it names permission problems, string reads hide them
            info.serial = usb.util.get_string(device, device.iSerialNumber) if device.iSerialNumber else None
            info.product = usb.util.get_string(device, device.iProduct) if device.iProduct else None
            if probe_firmware:
                falcon.normal_mode()
                info.firmware_running = falcon.firmware_running(groups=1)
        except FalconUsbError as error:
            info.problem = str(error)
        except Exception as error:  # noqa: BLE001 - pyusb raises USBError and ValueError alike
            info.problem = str(explain(error, "opening the Falcon"))
        finally:
            if falcon is not None:
                falcon.close()
            else:
                _dispose(device)
        found.append(info)
    return found


def _dispose(device) -> None:
    try:
        import usb.util

        usb.util.dispose_resources(device)
    except Exception:  # noqa: BLE001 - closing what may already be gone
        pass


class FalconUsb:
    """One opened Falcon: FTDI requests, the loader, and the normal-mode frame exchange."""

    def __init__(self, device, *, timeout_ms: int = 1000, read_timeout_ms: int = 20,
                 resend_after: int = 10) -> None:
        import usb.core

        self._usb = usb.core
        self.device = device
        self.timeout_ms = int(timeout_ms)
        self.read_timeout_ms = int(read_timeout_ms)
        self.resend_after = int(resend_after)
        self.reader = FrameReader("status")
        self._codec = FrameCodec()
        self._packet = array.array("B", bytes(ftdi.PACKET_SIZE))
        self._packet_mv = memoryview(self._packet)
        self._command = array.array("B", bytes(16))
        self._command_mv = memoryview(self._command)
        self._frame = new_frame()
        self._probe = new_frame()
        self._probe_status = Status()
        self._codec.encode_command((0, 0, 0), 0, self._probe)
        self._pending = False
        self._waited = 0
        self._got = False  # the last receive brought a reply (send then sends the next command)
        self.latency_ms = 16
        # counters
        self.exchanges = self.frames = self.sends = self.resends = self.empty_reads = self.timeouts = 0
        self._claim()

    # ------------------------------------------------------------ opening
    @classmethod
    def open(cls, index: int = 0, backend=None, **options) -> FalconUsb:
        """The `index`-th Falcon on the bus (0 = first)."""
        devices = find_falcons(backend)
        if not devices:
            raise FalconUsbError("no Falcon found on USB (VID:PID 0403:CB48): is it plugged in and powered?")
        if index >= len(devices):
            raise FalconUsbError(f"Falcon index {index} asked for, but only {len(devices)} found on USB")
        return cls(devices[index], **options)

    def _claim(self) -> None:
        dev = self.device
        try:
            try:
                dev.get_active_configuration()
            except self._usb.USBError as error:
                if getattr(error, "errno", None) in (errno.EACCES, errno.EPERM, errno.ENODEV):
                    raise
                dev.set_configuration()
            try:
                if dev.is_kernel_driver_active(ftdi.INTERFACE):
                    dev.detach_kernel_driver(ftdi.INTERFACE)
            except NotImplementedError:  # a backend without kernel-driver queries (not Linux)
                pass
            import usb.util

            usb.util.claim_interface(dev, ftdi.INTERFACE)
        except self._usb.USBError as error:
            _dispose(dev)
            raise explain(error, "opening the Falcon") from None

    def close(self) -> None:
        """Release the interface; safe to call twice, or after an unplug."""
        try:
            import usb.util

            usb.util.release_interface(self.device, ftdi.INTERFACE)
        except Exception:  # noqa: BLE001
            pass
        _dispose(self.device)

    def __enter__(self) -> FalconUsb:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # ------------------------------------------------------------ FTDI requests
    def _control(self, request: int, value: int, index: int = 0, timeout_ms: int | None = None) -> None:
        try:
            self.device.ctrl_transfer(ftdi.VENDOR_OUT, request, value, index, None,
                                      self.timeout_ms if timeout_ms is None else timeout_ms)
        except self._usb.USBError as error:
            raise explain(error, f"sending FTDI request {request:#04x}") from None

    def purge(self) -> None:
        """Empty both FTDI FIFOs (libnifalcon always issues both) and forget partial frames."""
        self._control(ftdi.Request.RESET, ftdi.PURGE_RX)
        self._control(ftdi.Request.RESET, ftdi.PURGE_TX)
        self.reader.clear()
        self._pending = False

    def set_latency(self, ms: int) -> None:
        self._control(ftdi.Request.LATENCY, int(ms))
        self.latency_ms = int(ms)

    def set_baud(self, divisor: ftdi.Baud) -> None:
        self._control(ftdi.Request.BAUD, int(divisor))

    def _modem(self, value: int) -> None:
        self._control(ftdi.Request.MODEM_CTRL, value)

    def normal_mode(self) -> None:
        """§2.5: latency 1 ms, 1.5 Mbaud, purge. The 1 ms timer is what makes 1 kHz possible."""
        self.set_latency(1)
        self.set_baud(ftdi.Baud.NORMAL)
        self.purge()

    # ------------------------------------------------------------ raw I/O
    def _write(self, data) -> None:
        try:
            self.device.write(ftdi.EP_OUT, data, self.timeout_ms)
        except self._usb.USBTimeoutError:
            raise FalconUsbError("the Falcon did not take a write within "
                                 f"{self.timeout_ms} ms: is its power supply connected?") from None
        except self._usb.USBError as error:
            raise explain(error, "writing to the Falcon") from None

    def _read_packet(self, timeout_ms: int) -> int:
        """One bulk IN packet into `_packet`; the number of data bytes after the 2 status bytes."""
        try:
            n = self.device.read(ftdi.EP_IN, self._packet, timeout_ms)
        except self._usb.USBTimeoutError:
            self.timeouts += 1
            return 0
        except self._usb.USBError as error:
            raise explain(error, "reading from the Falcon") from None
        return max(0, n - ftdi.STATUS_BYTES)

    def _collect(self, want: int, max_packets: int, done: Callable[[bytes], bool] | None = None) -> bytes:
        """Data bytes of up to `max_packets` packets, until `want` bytes came or `done` says so."""
        got = bytearray()
        for _ in range(max_packets):
            n = self._read_packet(self.timeout_ms)
            got += self._packet_mv[ftdi.STATUS_BYTES:ftdi.STATUS_BYTES + n]
            if len(got) >= want or (done is not None and done(bytes(got))):
                break
        return bytes(got)

    # ------------------------------------------------------------ firmware
    def load_firmware(self, image: bytes, handshake_tries: int = 100) -> None:
        """§2.3-2.5: DTR pulse, handshake, autobaud, upload with echo check, normal mode.

        Raises FalconLoaderError on any step that fails; the caller reopens and retries.
        """
        self.purge()
        self.set_latency(16)  # libnifalcon: the handshake checks fail with shorter timers
        self.set_baud(ftdi.Baud.LOADER)
        self._control(ftdi.Request.LINE, ftdi.LINE_8N1)
        self._control(ftdi.Request.FLOW_CTRL, ftdi.FLOW_NONE)
        self._modem(ftdi.RTS_LOW)
        self._modem(ftdi.DTR_LOW)
        self._modem(ftdi.DTR_HIGH)
        for _ in range(handshake_tries):
            self._write(HANDSHAKE)
            reply = self._collect(5, 4, lambda got: got.endswith(b"\nD,\r"))
            if reply in HANDSHAKE_REPLIES:
                break
        else:
            raise FalconLoaderError(f"the Falcon's boot loader did not answer the handshake in {handshake_tries} "
                                    "tries: is the Falcon's own power supply plugged in? "
                                    "(USB power alone is not enough)")
        self._modem(ftdi.DTR_LOW)
        self.set_baud(ftdi.Baud.UPLOAD)
        self._write(AUTOBAUD)
        reply = self._collect(2, 4, lambda got: AUTOBAUD in got)
        if reply not in (AUTOBAUD, b"\x13" + AUTOBAUD):
            raise FalconLoaderError(f"the boot loader answered the autobaud 'A' with {reply!r}, not 'A'")
        for start in range(0, len(image), CHUNK):
            chunk = image[start:start + CHUNK]
            self._write(array.array("B", chunk))
            echo = self._collect(len(chunk), 64)
            if echo != chunk:
                where = next((i for i, (a, b) in enumerate(zip(echo, chunk)) if a != b), min(len(echo), len(chunk)))
                raise FalconLoaderError(f"firmware upload: the echo differs from the image at byte {start + where} "
                                        f"of {len(image)} (got {len(echo)} of {len(chunk)} bytes back)")
        self.normal_mode()

    def firmware_running(self, groups: int = 10, per_group: int = 100) -> bool:
        """§2.2: does a valid status frame come back within `groups` x `per_group` I/O cycles?"""
        for _ in range(groups):
            self._pending = False
            for _ in range(per_group):
                if self.exchange(self._probe, self._probe_status):
                    return True
        return False

    # ------------------------------------------------------------ the 1 kHz cycle
    def exchange(self, command: NDArray[np.uint8], status: Status) -> bool:
        """Read the reply to the last command, then send `command`; True if `status` is new.

        One 64-byte USB read per call. Without a reply the command is not resent (the
        firmware answers each one once) until `resend_after` empty reads in a row.
        """
        got = self.receive(status)
        self.send(command)
        return got

    def receive(self, status: Status) -> bool:
        """The first half of `exchange`, for a loop that computes in between: read the reply
        to the last command into `status`; True if it is new."""
        self.exchanges += 1
        got = False
        if self._pending:
            n = self._read_packet(self.read_timeout_ms)
            if n:
                self.reader.feed(self._packet_mv[ftdi.STATUS_BYTES:ftdi.STATUS_BYTES + n])
                while self.reader.pop(self._frame):  # keep the newest if several came
                    got = True
            if got:
                self._codec.decode_status(self._frame, status)  # FrameReader checked it already
                self.frames += 1
                self._waited = 0
            else:
                self.empty_reads += 1
                self._waited += 1
        self._got = got
        return got

    def send(self, command: NDArray[np.uint8]) -> None:
        """The second half: send `command`, unless the last one is still unanswered and the
        firmware may yet reply to it (fewer than `resend_after` empty reads)."""
        got = self._got
        if got or not self._pending or self._waited >= self.resend_after:
            if self._pending and not got:
                self.resends += 1
            self._command_mv[:] = command
            self._write(self._command)
            self.sends += 1
            self._pending, self._waited = True, 0
        self._got = False

def connect(image: bytes | None, index: int = 0, backend=None, attempts: int = 10,
            log: Callable[[str], None] | None = None, **options) -> FalconUsb:
    """Open the Falcon and make sure its firmware runs, loading `image` if it does not.

    As libnifalcon's tools do (§2.6): up to `attempts` tries, closing and reopening the device
    between them.
    """
    last = "no attempt made"
    for attempt in range(1, attempts + 1):
        falcon = FalconUsb.open(index, backend, **options)
        try:
            falcon.normal_mode()
            if falcon.firmware_running():
                return falcon
            if image is None:
                raise FalconUsbError("the Falcon's firmware is not running and no firmware image was given")
            if log:
                log(f"loading firmware, attempt {attempt} of {attempts}")
            falcon.load_firmware(image)
            if falcon.firmware_running():
                return falcon
            last = "the firmware was uploaded but does not answer frames"
        except FalconLoaderError as error:
            last = str(error)
        except BaseException:
            falcon.close()
            raise
        falcon.close()
        if log:
            log(f"attempt {attempt} failed: {last}")
    raise FalconLoaderError(f"could not start the Falcon's firmware in {attempts} attempts; last: {last}")
