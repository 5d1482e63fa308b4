"""The Falcon's 16-byte normal-mode frames (docs/devices/falcon.md §4), both directions.

A frame is `<`, twelve nibble characters carrying three int16 values (least-significant
nibble first, each byte 0x41 + nibble), a flags/status byte, a spare byte and `>`. Host to
Falcon the values are motor commands and byte 13 holds the homing and LED bits; Falcon to
host they are encoder counts and byte 13 holds buttons (low nibble) and per-axis homed
flags (bits 4-6), so it may exceed 'P' (0xB1 = all homed).

`FrameReader` turns USB reads of any size into frames. libnifalcon walks its buffer in
16-byte steps and never recovers from a lost byte (§4.3); following docs/devices/falcon.md, we scan for
`<`, check `>` 15 bytes later and the range of every byte between (`<` and `>` can never
occur inside a valid frame, so this resynchronises within one frame), and count what we
drop. Byte 14's meaning is unknown (0x41 in every observed frame): it is accepted in
'A'..'P' and exposed as `spare`, never interpreted.

Frames are checked and packed with bytes operations (`translate`, `struct`) on Python ints:
numpy's per-call overhead on 16 bytes was most of the cost. Encoding, decoding and reading
write into caller-provided buffers: nothing created per 1 ms cycle stays. One codec or
reader per thread.
"""

from __future__ import annotations

import array
import enum
import struct
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
#: Motor command saturation docs/devices/falcon.md recommend (Novint's driver was seen sending 4095).
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
        a, b, c = self.homed.tolist()
        return a | b << 1 | c << 2

    @property
    def all_homed(self) -> bool:
        """libnifalcon's `isHomed()`: all three flags (before 2012 it took any one)."""
        a, b, c = self.homed.tolist()
        return a and b and c


def new_frame() -> U8:
    """A zeroed 16-byte frame buffer; numpy arrays hand their bytes to USB writes as is."""
    return np.zeros(FRAME_SIZE, dtype=np.uint8)


#: Byte -> its nibble for 'A'..'P', 0xFF for every other byte: a `bytes.translate` table.
_NIBBLE = bytes(b - _BASE if _BASE <= b <= _BASE + 0xF else 0xFF for b in range(256))
_NOT_NIBBLE = 0xFF
#: Bytes 0..15: '<', three values of four nibble bytes, byte 13, byte 14, '>'.
_LAYOUT = struct.Struct("<BIIIBBB")


def _byte13_max(kind: Kind) -> int:
    """Highest valid byte 13: commands carry 4 flag bits, status also the homed bits 4-6, so it
    may exceed 'P'."""
    if kind == "status":
        return _BASE + 0x7F
    if kind == "command":
        return _BASE + 0xF
    raise ValueError(f"kind must be 'status' or 'command', not {kind!r}")


def _checked_nibbles(frame: bytearray, byte13_max: int) -> bytearray | None:
    """The §4.3 checks on a 16-byte frame: `<` ... `>`, every byte between in its range.
    Returns the frame translated to nibbles (bytes 1-12 and 14 then hold 0..15), or None."""
    if frame[0] != START or frame[15] != END or not _BASE <= frame[13] <= byte13_max:
        return None
    nibbles = frame.translate(_NIBBLE)
    if nibbles.find(_NOT_NIBBLE, 1, 13) >= 0 or nibbles[14] == _NOT_NIBBLE:
        return None
    return nibbles


def _nibble_bytes_table() -> array.array:
    """For every 16-bit value, its four frame bytes as one little-endian uint32: least
    significant nibble first, each byte 'A' + nibble. 256 KiB, looked up per value packed."""
    v = np.arange(1 << 16, dtype=np.uint32)
    spread = (v & 0xF) | (v & 0xF0) << 4 | (v & 0xF00) << 8 | (v & 0xF000) << 12
    table = array.array("I")
    table.frombytes((spread + 0x41414141).astype(f"={table.typecode}").tobytes())
    return table


_NIBBLE_BYTES = _nibble_bytes_table()


def _int16(nibbles: bytearray, at: int) -> int:
    """The signed 16-bit value of the four nibbles from `at`, least significant first."""
    value = nibbles[at] | nibbles[at + 1] << 4 | nibbles[at + 2] << 8 | nibbles[at + 3] << 12
    return (value ^ 0x8000) - 0x8000


def _three_ints(values: ArrayLike) -> tuple[int, int, int]:
    """Three values as ints, floats truncated toward zero; arrays through `tolist` (cheap)."""
    a, b, c = values.tolist() if isinstance(values, np.ndarray) else values  # type: ignore[misc]
    return int(a), int(b), int(c)


class FrameCodec:
    """Encodes and decodes single frames with a preallocated 16-byte scratch buffer."""

    _STATUS_MAX, _COMMAND_MAX = _byte13_max("status"), _byte13_max("command")

    def __init__(self) -> None:
        self._frame = bytearray(FRAME_SIZE)
        self._mv = memoryview(self._frame)

    # -------------------------------------------------------------- internals
    def _pack(self, values: ArrayLike, limit: int | None, b13: int, b14: int, out: U8 | bytearray) -> None:
        a, b, c = _three_ints(values)
        if limit is not None:
            a, b, c = min(max(a, -limit), limit), min(max(b, -limit), limit), min(max(c, -limit), limit)
        table = _NIBBLE_BYTES
        _LAYOUT.pack_into(self._frame, 0, START, table[a & 0xFFFF], table[b & 0xFFFF], table[c & 0xFFFF],
                          _BASE + b13, _BASE + b14, END)  # & 0xFFFF: two's complement, low 16 bits
        memoryview(out)[:] = self._frame  # type: ignore[index]  # numpy uint8 array or bytearray

    def _load(self, frame: ArrayLike | bytes, byte13_max: int) -> bytearray | None:
        """Copy a frame into scratch and check it; its nibbles, or None if malformed or not 16 bytes."""
        try:
            self._mv[:] = frame  # type: ignore[index]
        except (ValueError, TypeError):
            return None
        return _checked_nibbles(self._frame, byte13_max)

    def _unpack(self, nibbles: bytearray, out_values: NDArray[np.int64]) -> None:
        out_values[0] = _int16(nibbles, 1)
        out_values[1] = _int16(nibbles, 5)
        out_values[2] = _int16(nibbles, 9)

    # -------------------------------------------------------------- public
    def is_valid(self, frame: ArrayLike | bytes, kind: Kind = "status") -> bool:
        """The §4.3 checks: `<` ... `>`, every byte between in its nibble range."""
        return self._load(frame, _byte13_max(kind)) is not None

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
        nibbles = self._load(frame, self._COMMAND_MAX)
        if nibbles is None:
            raise FrameError("not a valid host-to-Falcon frame")
        self._unpack(nibbles, out.motor)
        out.flags = nibbles[13]
        out.spare = nibbles[14]
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
        nibbles = self._load(frame, self._STATUS_MAX)
        if nibbles is None:
            raise FrameError("not a valid Falcon-to-host frame")
        self._unpack(nibbles, out.encoders)
        b13 = self._frame[13] - _BASE  # may exceed a nibble: homed bits 4-6
        out.buttons = b13 & 0xF
        homed = out.homed
        homed[0], homed[1], homed[2] = b13 >> 4 & 1, b13 >> 5 & 1, b13 >> 6 & 1
        out.spare = nibbles[14]
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
        self._byte13_max = _byte13_max(kind)
        self._cap = int(capacity)
        self._buf = bytearray(self._cap)
        self._start = self._end = 0
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
            candidate = buf[i:i + FRAME_SIZE]
            if _checked_nibbles(candidate, self._byte13_max) is not None:
                self._start = i + FRAME_SIZE
                if self._start == self._end:
                    self._start = self._end = 0
                self.frames += 1
                memoryview(out)[:] = candidate  # type: ignore[index]  # numpy uint8 array or bytearray
                return True
            self.rejected += 1
            self._drop_to(i + 1)

    def frames_in(self, chunk: bytes | bytearray | memoryview | U8 = b"") -> Iterator[bytes]:
        """Feed `chunk`, then yield every complete frame as bytes (off the cycle path)."""
        self.feed(chunk)
        frame = new_frame()
        while self.pop(frame):
            yield frame.tobytes()
