"""A Falcon on USB as a `FalconLink`: opened on a helper thread, then the driver's 1 kHz halves.

Opening a Falcon may load its firmware, which takes seconds at 9600 baud; the block's thread
must keep cycling meanwhile, so `connect` runs on a thread of its own and `ready` says when it
is done (raising what it raised). The lines it logs are handed over then, on the caller's
thread. A USB error during the run (unplugged, powered off) is logged once and the frames
just stop: the block's `frames_ok` tells the rest of the system.

`virtual_falcon` builds the virtual Falcon of `virtual_falcon` on a run's clock, reached through
the pyusb backend of `virtual_usb`, so the same block runs against it in tests
(`usb_backend: virtual`).
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from typing import Protocol

import numpy as np
from numpy.typing import NDArray

from hapticop.devices.falcon.codec import Status
from hapticop.devices.falcon.mechanism import Geometry
from hapticop.devices.falcon.usb_driver import FalconUsb, connect
from hapticop.devices.falcon.usb_errors import FalconUsbError

__all__ = ["UsbLink", "virtual_falcon"]


class _Log(Protocol):
    def info(self, message: str, *args: object) -> None: ...
    def error(self, message: str, *args: object) -> None: ...


class UsbLink:
    """The Falcon at `index` on `backend`, opened (and its firmware `image` loaded) in the background."""

    def __init__(self, image: bytes | None, index: int, backend, log: _Log) -> None:
        self.log = log
        self.falcon: FalconUsb | None = None
        self.failed = False  # a USB error was logged: the device is gone until reopened
        self._lines: list[str] = []
        self._error: BaseException | None = None
        self.opening: threading.Thread | None = threading.Thread(
            target=self._open, args=(image, index, backend), name="falcon-usb-open", daemon=True)
        self.opening.start()

    def _open(self, image: bytes | None, index: int, backend) -> None:
        try:
            self.falcon = connect(image, index, backend, log=self._lines.append)
        except BaseException as error:  # noqa: BLE001 - raised again by `ready`, on the caller's thread
            self._error = error

    def ready(self) -> bool:
        opening = self.opening
        if opening is not None:
            if opening.is_alive():
                return False
            self.opening = None
            for line in self._lines:
                self.log.info("%s", line)
            if self._error is not None:
                raise self._error
        return self.falcon is not None

    def send(self, command: NDArray[np.uint8]) -> None:
        try:
            self.falcon.send(command)
        except FalconUsbError as error:
            self._lost(error)

    def receive(self, status: Status) -> bool:
        try:
            return self.falcon.receive(status)
        except FalconUsbError as error:
            self._lost(error)
            return False

    def _lost(self, error: Exception) -> None:
        if not self.failed:
            self.failed = True
            self.log.error("%s", error)

    def close(self) -> None:
        if self.opening is not None:  # closed while still opening: wait for it, then let go
            self.opening.join(30.0)
            self.opening = None
        if self.falcon is not None:
            self.falcon.close()
            self.falcon = None


class _RunClock:
    """A run's clock in seconds, as the virtual USB device wants it (sleeping only in real time)."""

    def __init__(self, now_ns: Callable[[], int], sleeps: bool) -> None:
        self.now_ns, self.sleeps = now_ns, sleeps

    def now(self) -> float:
        return self.now_ns() / 1e9

    def sleep(self, seconds: float) -> None:
        if seconds > 0 and self.sleeps:
            time.sleep(seconds)


def virtual_falcon(geometry: Geometry, now_ns: Callable[[], int], sleeps: bool, rng: np.random.Generator):
    """A virtual USB Falcon on a run's clock, whose simulated hand homes it and then lets go, and the
    pyusb backend that reaches it: (device, backend)."""
    from hapticop.devices.falcon.homing import HomingHand
    from hapticop.devices.falcon.simulated import SimulatedFalcon
    from hapticop.devices.falcon.virtual_falcon import VirtualFalcon
    from hapticop.devices.falcon.virtual_usb import VirtualUsbBackend

    device = VirtualFalcon(_RunClock(now_ns, sleeps), falcon=SimulatedFalcon(geometry, rng=rng), hand=HomingHand())
    return device, VirtualUsbBackend(device)
