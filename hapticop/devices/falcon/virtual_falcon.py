"""The DSP behind a virtual Falcon's FTDI chip: its boot loader, then its firmware's frame exchange.

What answers on the chip's serial line (docs/devices/falcon.md §2, §4): a boot ROM with no
firmware that answers nothing until a DTR pulse, then the handshake (`\\nC\\r` -> `\\nD,\\r`
at 9600 baud), the autobaud `A`, and echoes every uploaded byte; when the host switches to
1.5 Mbaud after at least `min_upload` bytes, the "firmware" runs: each valid 16-byte
command frame gets one status frame from a `SimulatedFalcon`, the same physics as the `sim`
driver. It never looks at the image.
"""

from __future__ import annotations

import enum
import time
from collections.abc import Callable
from dataclasses import dataclass, field

from numpy.typing import ArrayLike

from hapticop.devices.falcon.codec import FrameReader, new_frame
from hapticop.devices.falcon.simulated import SimulatedFalcon
from hapticop.devices.falcon.virtual_ftdi import VirtualFtdi

__all__ = ["Phase", "VirtualFalcon"]

LOADER_BAUD = 9600.0
NORMAL_BAUD = 1_500_000.0
AUTOBAUD_MAX = 250_000.0  # the C2000 SCI autobaud locks onto slow rates only
TOLERANCE = 0.03  # a UART reads bytes sent within ~3 % of its own rate
HANDSHAKE = b"\nC\r"


class Phase(enum.Enum):
    BOOT_ROM = "boot ROM, no firmware"  # silent until a DTR pulse
    HANDSHAKE = "loader handshake"  # waits for \nC\r at 9600 baud
    AUTOBAUD = "autobaud"  # waits for 'A'
    UPLOAD = "upload"  # echoes every byte
    RUNNING = "firmware running"  # 16-byte frames at 1.5 Mbaud


def _near(baud: float, wanted: float) -> bool:
    return wanted > 0 and abs(baud - wanted) <= TOLERANCE * wanted


@dataclass
class VirtualFalcon(VirtualFtdi):
    """One Falcon: the FTDI chip and USB identity of `VirtualFtdi`, its loader and its firmware.

    Test knobs (all optional), besides the chip's: `firmware_loaded` (firmware survived from
    an earlier session), `handshake_failures` (that many handshakes get no answer),
    `handshake_leading_zero` (the macOS `00`), `autobaud_reply` (`b"A"` or `b"\\x13A"`),
    `corrupt_echo_at` (one upload byte arrives damaged: its echo differs and the image will
    not boot). A fault during a run, besides the chip's: `mute()`.
    The handle is `falcon` (a SimulatedFalcon); `hand(t, falcon)` returns the operator's force.
    """

    falcon: SimulatedFalcon = field(default_factory=lambda: SimulatedFalcon(rng=0))
    hand: Callable[[float, SimulatedFalcon], ArrayLike] | None = None
    firmware_loaded: bool = False
    handshake_failures: int = 0
    handshake_leading_zero: bool = False
    autobaud_reply: bytes = b"A"
    corrupt_echo_at: int | None = None
    min_upload: int = 1024
    reply_delay_s: float = 50e-6  # firmware time from a command's last byte to its reply's first

    def __post_init__(self) -> None:
        super().__post_init__()
        self.phase = Phase.RUNNING if self.firmware_loaded else Phase.BOOT_ROM
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

    def mute(self, on: bool = True) -> None:
        """The firmware stops answering frames (a hung DSP); USB stays up."""
        self.muted = on

    # ------------------------------------------------------------ the chip's lines
    def _dtr_edge(self, rising: bool) -> None:
        if rising:  # the DSP resets into its boot loader
            self._reset_to_loader()
        elif self.phase is Phase.HANDSHAKE and self._handshake_done:
            self.phase = Phase.AUTOBAUD

    def _reset_to_loader(self) -> None:
        self.phase = Phase.HANDSHAKE
        self._handshake.clear()
        self._handshake_done = False
        self.uploaded = 0
        self._image_damaged = False

    def _baud_changed(self) -> None:
        if self.phase is Phase.UPLOAD and _near(self.baud, NORMAL_BAUD):
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
