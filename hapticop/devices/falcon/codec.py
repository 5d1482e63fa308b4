"""The Falcon's 16-byte normal-mode frames (falcon-protocol.md §4), both directions.

A frame is `<`, twelve nibble characters carrying three int16 values (least-significant
nibble first, each byte 0x41 + nibble), a flags/status byte, a spare byte and `>`. Host to
Falcon the values are motor commands and byte 13 holds the homing and LED bits; Falcon to
host they are encoder counts and byte 13 holds buttons (low nibble) and per-axis homed
flags (bits 4-6), so it may exceed 'P' (0xB1 = all homed).

`FrameReader` turns USB reads of any size into frames. libnifalcon walks its buffer in
16-byte steps and never recovers from a lost byte (§4.3); following the notes we scan for
`<`, check `>` 15 bytes later and the range of every byte between (`<` and `>` can never
occur inside a valid frame, so this resynchronises within one frame), and count what we
drop. Byte 14's meaning is unknown (0x41 in every observed frame): it is accepted in
'A'..'P' and exposed as `spare`, never interpreted. Encoding, decoding and reading write into preallocated arrays: nothing is created
per 1 ms cycle. One codec or reader per thread.
"""

from __future__ import annotations

import enum
from collections.abc import Iterator
from dataclasses import dataclass, field
from typing import Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = [
    "FRAME_SIZE", "START", "END", "MOTOR_LIMIT", "Flag", "Button", "FrameError",
    "Command", "Status", "FrameCodec", "FrameReader", "new_frame", "is_valid_frame",
]

FRAME_SIZE = 16
START = 0x3C  # '<'
END = 0x3E  # '>'
_BASE = 0x41  # 'A' = nibble 0
#: Motor command saturation the notes recommend (Novint's driver was seen sending 4095).
MOTOR_LIMIT = 4095

U8 = NDArray[np.uint8]
Kind = Literal["status", "command"]


class Flag(enum.IntFlag):
    """Host-to-Falcon byte 13 bits. libnifalcon's code values; a doc comment in its header
    says red/green/blue and homing 0x10, which the code never uses (§4.1: trust the code)."""

    HOMING = 0x01
    LED_GREEN = 0x02
    LED_BLUE = 0x04
    LED_RED = 0x08


class Button(enum.IntFlag):
    """Grip button bits of the status byte's low nibble (4-button ball grip, §4.2)."""

    PLUS = 0x01  # right
    FORWARD = 0x02
    CENTRE = 0x04
    MINUS = 0x08  # left


class FrameError(ValueError):
    """A single frame handed to a decoder is not a valid frame of that direction."""


@dataclass(slots=True)
class Command:
    """A decoded host-to-Falcon frame (the simulator's view)."""

    motor: NDArray[np.int64] = field(default_factory=lambda: np.zeros(3, dtype=np.int64))
    flags: int = 0  # Flag bits
    spare: int = 0  # byte 14 - 0x41, always 0 in practice

    @property
    def homing(self) -> bool:
        return bool(self.flags & Flag.HOMING)

    @property
    def leds(self) -> int:
        return self.flags & (Flag.LED_GREEN | Flag.LED_BLUE | Flag.LED_RED)


@dataclass(slots=True)
class Status:
    """A decoded Falcon-to-host frame; decoding overwrites it in place."""

    encoders: NDArray[np.int64] = field(default_factory=lambda: np.zeros(3, dtype=np.int64))
    homed: NDArray[np.bool_] = field(default_factory=lambda: np.zeros(3, dtype=np.bool_))
    buttons: int = 0  # Button bits
    spare: int = 0  # byte 14 - 0x41, 0 in every observed frame

    @property
    def homed_mask(self) -> int:
        """Bit 0 = axis 1 (top), bit 1 = axis 2 (right), bit 2 = axis 3 (left)."""
        return int(self.homed[0]) | int(self.homed[1]) << 1 | int(self.homed[2]) << 2

    @property
    def all_homed(self) -> bool:
        """libnifalcon's `isHomed()`: all three flags (before 2012 it took any one)."""
        return bool(self.homed.all())


def new_frame() -> U8:
    """A zeroed 16-byte frame buffer; numpy arrays hand their bytes to USB writes as is."""
    return np.zeros(FRAME_SIZE, dtype=np.uint8)


def _limits(kind: Kind) -> tuple[U8, U8]:
    """Per-byte (low, span) of a valid frame: byte - low (mod 256) <= span. The §4.3 rules."""
    if kind not in ("status", "command"):
        raise ValueError(f"kind must be 'status' or 'command', not {kind!r}")
    lo = np.full(FRAME_SIZE, _BASE, dtype=np.uint8)
    span = np.full(FRAME_SIZE, 0xF, dtype=np.uint8)
    lo[0], lo[15] = START, END
    span[0] = span[15] = 0
    if kind == "status":
        span[13] = 0x7F  # buttons | homed << 4 can exceed 'P'
    return lo, span


_ALL_OK = np.ones(FRAME_SIZE, dtype=np.bool_).tobytes()


def _copy_out(out: U8 | bytearray, frame: U8) -> None:
    """Frame into a numpy array or any writable buffer (bytearray refuses arrays directly)."""
    if isinstance(out, np.ndarray):
        np.copyto(out, frame)
    else:
        memoryview(out)[:] = frame  # type: ignore[index]


class FrameCodec:
    """Encodes and decodes single frames with preallocated scratch (no per-call arrays)."""

    _SHIFTS = np.array([0, 4, 8, 12], dtype=np.int64)
    _WEIGHTS = np.array([1, 16, 256, 4096], dtype=np.int64)
    _HOMED = tuple(np.array([(m >> i) & 1 for i in range(3)], dtype=np.bool_) for m in range(8))

    def __init__(self) -> None:
        self._frame = new_frame()
        self._mv = memoryview(self._frame)  # type: ignore[arg-type]
        self._payload = self._frame[1:13].reshape(3, 4)  # view: values x nibbles
        self._d = new_frame()  # frame - low: the nibbles, once checked
        self._d_payload = self._d[1:13].reshape(3, 4)
        self._v = np.zeros(3, dtype=np.int64)
        self._vcol = self._v[:, None]
        self._nib = np.zeros((3, 4), dtype=np.int64)
        self._ok = np.zeros(FRAME_SIZE, dtype=np.bool_)
        self._limits = {k: _limits(k) for k in ("status", "command")}

    # -------------------------------------------------------------- internals
    def _pack(self, values: ArrayLike, limit: int | None, b13: int, b14: int, out: U8 | bytearray) -> None:
        v, nib = self._v, self._nib
        np.copyto(v, values, casting="unsafe")  # floats truncate toward zero
        if limit is not None:
            np.minimum(v, limit, out=v)
            np.maximum(v, -limit, out=v)
        np.bitwise_and(v, 0xFFFF, out=v)  # two's complement, low 16 bits
        np.right_shift(self._vcol, self._SHIFTS, out=nib)
        np.bitwise_and(nib, 0xF, out=nib)
        np.add(nib, _BASE, out=nib)
        f = self._frame
        f[0], f[15] = START, END
        np.copyto(self._payload, nib, casting="unsafe")
        f[13], f[14] = _BASE + b13, _BASE + b14
        _copy_out(out, f)

    def _load(self, frame: ArrayLike | bytes, kind: Kind) -> bool:
        """Copy a frame into scratch and check it; False if malformed or not 16 bytes."""
        try:
            self._mv[:] = frame  # type: ignore[index]
        except (ValueError, TypeError):
            return False
        lo, span = self._limits[kind]
        np.subtract(self._frame, lo, out=self._d)
        np.less_equal(self._d, span, out=self._ok)
        return self._ok.tobytes() == _ALL_OK

    def _unpack(self, out_values: NDArray[np.int64]) -> None:
        np.copyto(self._nib, self._d_payload)
        self._nib.dot(self._WEIGHTS, out=out_values)
        np.bitwise_xor(out_values, 0x8000, out=out_values)  # 16-bit two's complement
        np.subtract(out_values, 0x8000, out=out_values)

    # -------------------------------------------------------------- public
    def is_valid(self, frame: ArrayLike | bytes, kind: Kind = "status") -> bool:
        """The §4.3 checks: `<` ... `>`, every byte between in its nibble range."""
        return self._load(frame, kind)

    def encode_command(self, motor: ArrayLike, flags: int, out: U8 | bytearray, *,
                       limit: int | None = MOTOR_LIMIT) -> U8 | bytearray:
        """Host-to-Falcon frame: three motor commands, Flag bits (homing, LEDs) into `out`.

        Commands saturate at +-`limit`. `limit=None` keeps only the low 16 bits, which is
        libnifalcon's (unsafe) behaviour: 40000 wraps to -25536. Resend the homing and LED
        bits in every frame: each frame is the whole state.
        """
        self._pack(motor, limit, int(flags) & 0xF, 0, out)
        return out

    def decode_command(self, frame: ArrayLike | bytes, out: Command) -> Command:
        """Parse a host-to-Falcon frame into `out`; FrameError if it is not one."""
        if not self._load(frame, "command"):
            raise FrameError("not a valid host-to-Falcon frame")
        self._unpack(out.motor)
        out.flags = int(self._d[13])
        out.spare = int(self._d[14])
        return out

    def encode_status(self, encoders: ArrayLike, homed_mask: int, buttons: int,
                      out: U8 | bytearray) -> U8 | bytearray:
        """Falcon-to-host frame (the simulator's side). Encoders wrap to int16 like the wire."""
        self._pack(encoders, None, (int(buttons) & 0xF) | (int(homed_mask) & 0x7) << 4, 0, out)
        return out

    def decode_status(self, frame: ArrayLike | bytes, out: Status) -> Status:
        """Parse a Falcon-to-host frame into `out`; FrameError if it is not one.

        Counts are signed: `<JFKP...>` is -1447 (libnifalcon's comment says +1447; its code
        and this agree on -1447).
        """
        if not self._load(frame, "status"):
            raise FrameError("not a valid Falcon-to-host frame")
        self._unpack(out.encoders)
        b13 = int(self._d[13])
        out.buttons = b13 & 0xF
        np.copyto(out.homed, self._HOMED[b13 >> 4])
        out.spare = int(self._d[14])
        return out


def is_valid_frame(frame: ArrayLike | bytes, kind: Kind = "status") -> bool:
    """Convenience `FrameCodec().is_valid` for code off the cycle path."""
    return FrameCodec().is_valid(frame, kind)


class FrameReader:
    """Reassembles valid frames from arbitrary byte chunks, resynchronising on garbage.

    `feed(chunk)` appends what a USB read delivered (FTDI status bytes already stripped);
    `pop(out)` copies the next valid frame into `out` and returns True, or returns False
    when no complete frame is buffered. Bytes that cannot start a valid frame are dropped
    and counted in `discarded`; `rejected` counts candidate frames (a `<`) that failed the
    checks, `frames` the frames delivered. Nothing here raises on bad input. If more than
    `capacity` unread bytes pile up, the oldest are dropped (and counted).
    """

    def __init__(self, kind: Kind = "status", capacity: int = 1024) -> None:
        if capacity < FRAME_SIZE:
            raise ValueError("capacity must hold at least one frame")
        self.kind: Kind = kind
        self._lo, self._span = _limits(kind)
        self._cap = int(capacity)
        self._buf = bytearray(self._cap)
        self._arr = np.frombuffer(self._buf, dtype=np.uint8)
        self._start = self._end = 0
        self._cand, self._d = new_frame(), new_frame()
        self._ok = np.zeros(FRAME_SIZE, dtype=np.bool_)
        self.discarded = 0
        self.rejected = 0
        self.frames = 0

    @property
    def buffered(self) -> int:
        """Bytes waiting (a partial frame, usually)."""
        return self._end - self._start

    def clear(self) -> None:
        """Drop everything buffered (counted), e.g. after a FIFO purge."""
        self.discarded += self._end - self._start
        self._start = self._end = 0

    def feed(self, chunk: bytes | bytearray | memoryview | U8) -> None:
        """Append one read's bytes (any uint8 buffer)."""
        if isinstance(chunk, np.ndarray):  # bytearray slices refuse arrays, not their buffers
            chunk = memoryview(chunk)
        n = len(chunk)
        if n == 0:
            return
        if n > self._cap:  # keep only the newest `capacity` bytes
            self.discarded += self._end - self._start + n - self._cap
            self._start = self._end = 0
            chunk = memoryview(chunk)[n - self._cap:]  # type: ignore[arg-type]
            n = self._cap
        if self._end + n > self._cap:
            overflow = self._end - self._start + n - self._cap
            if overflow > 0:  # unread bytes exceed capacity: the oldest go
                self._start += overflow
                self.discarded += overflow
            keep = self._end - self._start
            self._buf[:keep] = self._buf[self._start:self._end]
            self._start, self._end = 0, keep
        self._buf[self._end:self._end + n] = chunk
        self._end += n

    def _valid(self) -> bool:
        np.subtract(self._cand, self._lo, out=self._d)
        np.less_equal(self._d, self._span, out=self._ok)
        return self._ok.tobytes() == _ALL_OK

    def _drop_to(self, i: int) -> None:
        self.discarded += i - self._start
        self._start = i

    def pop(self, out: U8 | bytearray) -> bool:
        """Copy the next valid frame into `out`; False if none is complete yet."""
        buf = self._buf
        while True:
            i = buf.find(START, self._start, self._end)
            if i < 0:
                self._drop_to(self._end)
                self._start = self._end = 0
                return False
            self._drop_to(i)
            if self._end - i < FRAME_SIZE:
                # A second '<' already in view proves this candidate broken: drop it now.
                j = buf.find(START, i + 1, self._end)
                if j < 0:
                    return False
                self.rejected += 1
                self._drop_to(j)
                continue
            self._cand[:] = self._arr[i:i + FRAME_SIZE]
            if self._valid():
                self._start = i + FRAME_SIZE
                if self._start == self._end:
                    self._start = self._end = 0
                self.frames += 1
                _copy_out(out, self._cand)
                return True
            self.rejected += 1
            self._drop_to(i + 1)

    def frames_in(self, chunk: bytes | bytearray | memoryview | U8 = b"") -> Iterator[bytes]:
        """Feed `chunk`, then yield every complete frame as bytes (off the cycle path)."""
        self.feed(chunk)
        frame = new_frame()
        while self.pop(frame):
            yield frame.tobytes()
