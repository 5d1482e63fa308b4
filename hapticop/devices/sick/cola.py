"""CoLa A, the ASCII dialect of SICK's TiM5xx: framing, values, commands, replies, scans.

A telegram is STX (0x02), a body of tokens separated by single spaces, ETX (0x03); no length,
no checksum. Integers travel as uppercase hex without leading zeros, Reals as their 8-digit
IEEE-754 bit pattern, strings as a hex length then the raw characters (which may hold spaces).

Everything that decodes bytes from the wire raises `ColaError` and nothing else, whatever the
bytes are: a scanner (or a broken network) may send anything, and the caller only has to
count and skip. A refusal from the device (`sFA <code>`) is the subclass `ColaDeviceError`.

Scans: `parse_scan` walks one `LMDscandata` telegram (docs/devices/sick-tim561.md §4) with a cursor that
uses the counts the telegram carries, and converts the value block of each channel in one
vectorised numpy pass into arrays the caller owns. `build_scan` is its exact inverse, so the
simulator sends what the device sends, byte for byte.

Frames. SICK device frame: 0° and 180° lie across the scanner, 90° points out of the front
window, the field of view is -45°…225°. Sensor frame (REP 103: x forward, y left, z up,
counter-clockwise positive): theta = sick - 90°, not mirrored; a TiM561 covers
-135°…+134.973°. `to_robot_frame` then places the beams with the mount pose (x, y, yaw) of
the scanner on the robot: p_robot = (x, y) + R(yaw) · r (cos theta, sin theta).
"""

from __future__ import annotations

import hashlib
import math
import re
import struct
from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

STX = 0x02
ETX = 0x03
MIN_RANGE_M = 0.05  # TiM5xx minimum range: anything closer (including 0 = no echo) is invalid
TIM561_POINTS = 811
LEVEL3_HASH = "F4724744"  # "Authorized client": md5-fold of "client"

# ---------------------------------------------------------------------------------------------
# errors


class ColaError(ValueError):
    """A telegram that cannot be decoded, or a device reply that says no."""


class ColaDeviceError(ColaError):
    """The device answered `sFA <code>`: it understood the frame and refused the request."""

    def __init__(self, code: int, request: str | None = None):
        self.code = code
        self.request = request
        name, hint = SFA_CODES.get(code, ("UNKNOWN", "code not in SICK's list"))
        about = f" to {request!r}" if request else ""
        super().__init__(f"device refused{about}: sFA {code:X} = {name} ({hint})")


SFA_CODES: dict[int, tuple[str, str]] = {
    0x1: ("METHODIN_ACCESSDENIED", "method needs a higher user level: log in first"),
    0x2: ("METHODIN_UNKNOWNINDEX", "unknown method name"),
    0x3: ("VARIABLE_UNKNOWNINDEX", "unknown variable name"),
    0x4: ("LOCALCONDITIONFAILED", "value out of range for this device"),
    0x5: ("INVALID_DATA", "invalid data (deprecated code)"),
    0x6: ("UNKNOWN_ERROR", "unknown error (deprecated code)"),
    0x7: ("BUFFER_OVERFLOW", "the reply would not fit"),
    0x8: ("BUFFER_UNDERFLOW", "too few parameters"),
    0x9: ("ERROR_UNKNOWN_TYPE", "internal: unknown type"),
    0xA: ("VARIABLE_WRITE_ACCESSDENIED", "write needs a higher user level, or the variable is read-only"),
    0xB: ("UNKNOWN_CMD_FOR_NAMESERVER", "name not understood"),
    0xC: ("UNKNOWN_COLA_COMMAND", "bad command type (not sRN/sWN/sMN/sEN/...)"),
    0xD: ("METHODIN_SERVER_BUSY", "a method call is still running"),
    0xE: ("FLEX_OUT_OF_BOUNDS", "array too long"),
    0xF: ("EVENTREG_UNKNOWNINDEX", "unknown event"),
    0x10: ("COLA_A_VALUE_OVERFLOW", "number too big for the field"),
    0x11: ("COLA_A_INVALID_CHARACTER", "bad character in a number"),
    0x12: ("OSAI_NO_MESSAGE", "internal"),
    0x13: ("OSAI_NO_ANSWER_MESSAGE", "internal"),
    0x14: ("INTERNAL", "internal"),
    0x15: ("HubAddressCorrupted", "internal"),
    0x16: ("HubAddressDecoding", "internal"),
    0x17: ("HubAddressAddressExceeded", "internal"),
    0x18: ("HubAddressBlankExpected", "internal"),
    0x19: ("AsyncMethodsAreSuppressed", "internal"),
    0x20: ("ComplexArraysNotSupported", "internal"),
}

# ---------------------------------------------------------------------------------------------
# framing


def frame(body: bytes | str) -> bytes:
    """STX + body + ETX; the body may not contain either delimiter (there is no escaping)."""
    data = body.encode("latin-1") if isinstance(body, str) else bytes(body)
    if b"\x02" in data or b"\x03" in data:
        raise ValueError("a CoLa A body cannot contain STX (0x02) or ETX (0x03)")
    return b"\x02" + data + b"\x03"


def unframe(telegram: bytes) -> bytes:
    """The body of exactly one framed telegram."""
    data = bytes(telegram)
    if len(data) < 2 or data[0] != STX or data[-1] != ETX:
        raise ColaError("not a CoLa A telegram: it must start with STX (0x02) and end with ETX (0x03)")
    body = data[1:-1]
    if b"\x02" in body or b"\x03" in body:
        raise ColaError("more than one telegram, or a broken one: STX/ETX inside the body")
    return body


# ---------------------------------------------------------------------------------------------
# values (§2.1)

_HEX_TOKEN = re.compile(rb"[0-9A-Fa-f]+\Z")
_DEC_TOKEN = re.compile(rb"[+-][0-9]+\Z")
_REAL_TOKEN = re.compile(rb"[0-9A-Fa-f]{8}\Z")
_CONTROL = re.compile(rb"[\x00-\x1f]")


def encode_uint(value: int, bits: int = 32) -> bytes:
    """Uppercase hex without leading zeros (zero is `0`), as the device sends it."""
    if not 0 <= value < 1 << bits:
        raise ValueError(f"{value} does not fit an unsigned {bits}-bit field")
    return b"%X" % value


def decode_uint(token: bytes, bits: int = 32, what: str = "value") -> int:
    """Hex, leading zeros accepted (the device accepts them too); range-checked."""
    if not _HEX_TOKEN.match(token) or len(token) > 16:
        raise ColaError(f"{what}: {_show(token)} is not a hex number")
    value = int(token, 16)
    if value >> bits:
        raise ColaError(f"{what}: {_show(token)} does not fit {bits} bits")
    return value


def encode_int32(value: int) -> bytes:
    """Hex of the two's-complement pattern: -450000 becomes `FFF92230`."""
    if not -(1 << 31) <= value < 1 << 31:
        raise ValueError(f"{value} does not fit a signed 32-bit field")
    return b"%X" % (value & 0xFFFFFFFF)


def decode_int32(token: bytes, what: str = "value") -> int:
    """Two's-complement hex, or decimal with an explicit sign (`-450000`), which SICK accepts."""
    if _DEC_TOKEN.match(token) and len(token) <= 12:
        value = int(token, 10)
        if not -(1 << 31) <= value < 1 << 31:
            raise ColaError(f"{what}: {_show(token)} does not fit a signed 32-bit field")
        return value
    raw = decode_uint(token, 32, what)
    return raw - (1 << 32) if raw & 0x80000000 else raw


def encode_real(value: float) -> bytes:
    """The float32 bit pattern as exactly 8 uppercase hex digits: 1.0 is `3F800000`."""
    return struct.pack(">f", value).hex().upper().encode()


def decode_real(token: bytes, what: str = "value") -> float:
    if not _REAL_TOKEN.match(token):
        raise ColaError(f"{what}: {_show(token)} is not a Real (exactly 8 hex digits)")
    return struct.unpack(">f", bytes.fromhex(token.decode()))[0]


def encode_string(text: bytes | str) -> bytes:
    """Hex length, a space, the raw characters. An empty string is just `0` (our guess)."""
    data = text.encode("latin-1") if isinstance(text, str) else bytes(text)
    if not data:
        return b"0"
    return encode_uint(len(data), 16) + b" " + data


def _show(token: bytes, limit: int = 24) -> str:
    text = token[:limit].decode("latin-1")
    return repr(text + ("…" if len(token) > limit else ""))


# Vectorised hex for value blocks: bytes.translate maps every byte of the body to its nibble
# (0..15), a space to 16 and anything else to 255, in C; numpy then works on those codes.
_SPACE_CODE = 16
_BAD_CODE = 255
_CODES = bytearray([_BAD_CODE]) * 256
for _i, _c in enumerate(b"0123456789ABCDEF"):
    _CODES[_c] = _i
for _i, _c in enumerate(b"abcdef"):
    _CODES[_c] = 10 + _i
_CODES[0x20] = _SPACE_CODE
_CODE_TABLE = bytes(_CODES)
_INDEX_CACHE: dict[int, NDArray[np.float64]] = {}


def _index(n: int) -> NDArray[np.float64]:
    """0..n-1 as float64, cached: angles are start + i·step for the usual n every scan."""
    index = _INDEX_CACHE.get(n)
    if index is None:
        index = np.arange(n, dtype=np.float64)
        if len(_INDEX_CACHE) < 8:
            _INDEX_CACHE[n] = index
    return index


# ---------------------------------------------------------------------------------------------
# reading tokens


class TokenReader:
    """A cursor over a body: one token, one number or one length-prefixed string at a time.

    Never splits the whole body on spaces, because strings may contain spaces; uses the counts
    the telegram carries instead (docs/devices/sick-tim561.md's parser advice, §4).
    """

    __slots__ = ("body", "pos", "end", "_spaces", "_codes")

    def __init__(self, body: bytes, pos: int = 0):
        self.body = body
        self.pos = pos
        self.end = len(body)
        self._spaces: NDArray[np.intp] | None = None
        self._codes: NDArray[np.uint8] | None = None

    @property
    def at_end(self) -> bool:
        return self.pos == self.end + 1 or (self.pos == 0 and self.end == 0)

    def token(self, what: str) -> bytes:
        if self.pos > self.end:
            raise ColaError(f"telegram ends before {what}")
        stop = self.body.find(b" ", self.pos)
        if stop < 0:
            stop = self.end
        token = self.body[self.pos:stop]
        if not token:
            raise ColaError(f"empty token at byte {self.pos} ({what}): a double, leading or trailing space")
        self.pos = stop + 1
        return token

    def uint(self, bits: int, what: str) -> int:
        return decode_uint(self.token(what), bits, what)

    def int32(self, what: str) -> int:
        return decode_int32(self.token(what), what)

    def real(self, what: str) -> float:
        return decode_real(self.token(what), what)

    def flag(self, what: str) -> bool:
        value = self.uint(16, what)
        if value > 1:
            raise ColaError(f"{what}: expected 0 or 1, got {value}")
        return value == 1

    def string(self, what: str) -> bytes:
        length = self.uint(16, f"length of {what}")
        if length == 0:
            return b""
        stop = self.pos + length
        if stop > self.end:
            raise ColaError(f"{what}: {length} characters announced, {max(self.end - self.pos, 0)} left")
        if stop < self.end and self.body[stop] != 0x20:
            raise ColaError(f"{what}: no space after its {length} characters")
        text = self.body[self.pos:stop]
        self.pos = stop + 1
        return text

    def rest(self) -> bytes:
        """Everything not read yet (the parameters of a reply)."""
        return self.body[self.pos:] if self.pos <= self.end else b""

    def expect_end(self, what: str) -> None:
        if not self.at_end:
            raise ColaError(f"unexpected data after {what}: {_show(self.body[self.pos:])}")

    def values(self, count: int, digits: int, what: str) -> NDArray[np.uint32]:
        """`count` hex tokens of at most `digits` digits, decoded in one numpy pass."""
        if count == 0:
            return np.empty(0, np.uint32)
        if self.pos > self.end:
            raise ColaError(f"telegram ends before {what}")
        if self._codes is None:
            self._codes = np.frombuffer(self.body.translate(_CODE_TABLE), dtype=np.uint8)
            self._spaces = np.flatnonzero(self._codes == _SPACE_CODE)
        spaces, codes = self._spaces, self._codes
        first = int(spaces.searchsorted(self.pos))
        available = len(spaces) - first
        ends = np.empty(count, dtype=np.intp)
        if available >= count:
            ends[:] = spaces[first:first + count]
        elif available == count - 1:
            ends[:-1] = spaces[first:]
            ends[-1] = self.end
        else:
            raise ColaError(f"{what}: {count} values announced, the telegram ends after {available + 1} tokens")
        last = int(ends[-1])
        if codes[self.pos:last].max() == _BAD_CODE:
            raise ColaError(f"{what}: a value is not a hex number")
        widths = np.empty(count, dtype=np.intp)
        widths[0] = ends[0] - self.pos
        np.subtract(ends[1:], ends[:-1], out=widths[1:])
        widths[1:] -= 1
        if widths.min() < 1:
            raise ColaError(f"{what}: empty value (double space)")
        if widths.max() > digits:
            raise ColaError(f"{what}: a value has more than {digits} hex digits")
        ends -= 1  # now the last digit of each token
        values = codes[ends].astype(np.uint32)
        near_start = int(ends[0]) < digits  # keep the indexes of padding digits inside the body
        for place in range(1, digits):  # digit `place` from the right, where the token has one
            ends -= 1
            if near_start:
                np.maximum(ends, 0, out=ends)
            digit = codes[ends].astype(np.uint32)
            digit *= widths > place
            digit <<= 4 * place
            values += digit
        self.pos = last + 1
        return values


# ---------------------------------------------------------------------------------------------
# scans (§4, §5)


@dataclass(frozen=True, slots=True)
class Channel:
    """Header of one data channel: name, scaling and the angles of its values."""

    name: str  # DIST1, RSSI1, ...
    scale_factor: float  # multiply the raw value
    scale_offset: float  # then add (always 0 on a TiM)
    start_angle: int  # 1/10000 degree, SICK frame (int32)
    angular_step: int  # 1/10000 degree (uint16)
    count: int  # number of values

    @property
    def start_rad(self) -> float:
        """Angle of value 0 in the sensor frame (x forward, y left)."""
        return math.radians(self.start_angle / 10000.0 - 90.0)

    @property
    def step_rad(self) -> float:
        return math.radians(self.angular_step / 10000.0)


@dataclass(frozen=True, slots=True)
class ScanHeader:
    """Every field of an LMDscandata telegram except the values, enough to rebuild it exactly."""

    command_type: str  # "sRA" (poll reply) or "sSN" (stream)
    version: int
    device_number: int
    serial_number: int
    device_status: tuple[int, int]  # "0 0" ok
    telegram_counter: int  # +1 per scan, wraps at 16 bits
    scan_counter: int
    # Device clock (µs, wraps every 71.6 min) of the scan. We read it as the time of the last
    # point, as SICK's TiM5xx technical information says (sick_scan_xd's comment says the start;
    # the two differ by under one scan period, §5): point i is (n-1-i)·point_interval_s earlier.
    time_since_startup_us: int
    time_of_transmission_us: int
    input_status: tuple[int, int]
    output_status: tuple[int, int]
    reserved: int  # layer angle on multi-layer models, 0 on a TiM
    scan_frequency: int  # 1/100 Hz: 1500 = 15 Hz
    measurement_frequency: int  # 100 Hz units: 162 = 16.2 kHz between neighbouring points
    encoders: tuple[tuple[int, int], ...] = ()  # (position, speed)
    channels16: tuple[Channel, ...] = ()
    channels8: tuple[Channel, ...] = ()
    position: tuple[float, float, float, float, float, float, int] | None = None
    device_name: bytes | None = None
    comment: bytes | None = None
    timestamp: tuple[int, int, int, int, int, int, int] | None = None  # y, mo, d, h, mi, s, µs
    event: tuple[bytes, int, int, int] | None = None  # type, encoder position, time µs, angle

    @property
    def dist(self) -> Channel:
        for channel in self.channels16:
            if channel.name.startswith("DIST"):
                return channel
        raise ColaError("scan carries no 16-bit DIST channel")

    @property
    def rssi(self) -> Channel | None:
        for channel in (*self.channels16, *self.channels8):
            if channel.name.startswith("RSSI"):
                return channel
        return None

    @property
    def scan_period_s(self) -> float:
        return 100.0 / self.scan_frequency if self.scan_frequency else math.nan

    @property
    def point_interval_s(self) -> float:
        """Time between neighbouring points: point i lies (n-1-i)·this before the last."""
        return 1.0 / (self.measurement_frequency * 100.0) if self.measurement_frequency else math.nan


def parse_scan(
    body: bytes,
    out_ranges_m: NDArray[np.floating] | None,
    out_angles_rad: NDArray[np.floating] | None = None,
    *,
    out_raw: NDArray[np.integer] | None = None,
    out_rssi: NDArray[np.generic] | None = None,
    min_range_m: float = MIN_RANGE_M,
) -> ScanHeader:
    """Decode one `sRA`/`sSN LMDscandata` body (or framed telegram) into the caller's arrays.

    `out_ranges_m` gets the first DIST channel in metres (raw · scale / 1000 + offset), NaN
    where the value is below `min_range_m` (0 = no echo, 2 = seen on real TiMs); its length
    must equal the telegram's value count (None: only decode and check, e.g. to size the
    arrays from a first telegram). `out_angles_rad` gets the beam angles in the sensor
    frame; leave it None when the output range does not change (the angles do not either).
    `out_raw` gets the raw DIST values, `out_rssi` the raw RSSI values if the scan has them.
    Nothing is written unless the whole telegram decodes.
    """
    data = bytes(body)
    if data[:1] == b"\x02":
        data = unframe(data)
    reader = TokenReader(data)
    kind = reader.token("command type")
    if kind == b"sFA":
        raise ColaDeviceError(_sfa_code(reader), "LMDscandata")
    if kind not in (b"sRA", b"sSN"):
        raise ColaError(f"not a scan: command type {_show(kind)}, expected sRA or sSN")
    name = reader.token("command name")
    if name != b"LMDscandata":
        raise ColaError(f"not a scan: {_show(kind + b' ' + name)}")
    u = reader.uint
    fields = _fast_fixed_fields(data, reader)
    if fields is None:  # the token-by-token path: slower, and it names the field that is wrong
        fields = [u(bits, what) for bits, what in _FIXED_FIELDS]
    (version, device_number, serial, status0, status1, telegram_counter, scan_counter, t_scan, t_tx,
     input0, input1, output0, output1, reserved, scan_frequency, measurement_frequency, n_encoders) = fields
    status, inputs, outputs = (status0, status1), (input0, input1), (output0, output1)
    encoders = tuple((u(32, "encoder position"), u(16, "encoder speed")) for _ in range(n_encoders))

    dist_values = rssi_values = None
    channels: list[list[Channel]] = [[], []]
    for block, (bits, digits) in enumerate(((16, 4), (8, 2))):
        for _ in range(u(16, f"number of {bits}-bit channels")):
            channel = _fast_channel(data, reader)
            if channel is None:
                channel_name = reader.token(f"{bits}-bit channel name")
                if len(channel_name) != 5:
                    raise ColaError(f"channel name {_show(channel_name)} is not 5 characters")
                channel = Channel(
                    channel_name.decode("latin-1"),
                    reader.real("scale factor"),
                    reader.real("scale offset"),
                    reader.int32("start angle"),
                    u(16, "angular step"),
                    u(16, "number of values"),
                )
            values = reader.values(channel.count, digits, f"{channel.name} values")
            if block == 0 and dist_values is None and channel.name.startswith("DIST"):
                dist_values = (channel, values)
            elif rssi_values is None and channel.name.startswith("RSSI"):
                rssi_values = (channel, values)
            channels[block].append(channel)

    position = None
    if reader.flag("position block present"):
        position = (*(reader.real("position") for _ in range(6)), u(8, "rotation type"))
    device_name = reader.string("device name") if reader.flag("device name present") else None
    comment = reader.string("comment") if reader.flag("comment present") else None
    timestamp = None
    if reader.flag("time block present"):
        timestamp = (u(16, "year"), u(8, "month"), u(8, "day"), u(8, "hour"), u(8, "minute"),
                     u(8, "second"), u(32, "microseconds"))
    event = None
    if reader.flag("event block present"):
        event = (reader.token("event type"), u(32, "event encoder position"), u(32, "event time"),
                 reader.int32("event angle"))
    reader.expect_end("the event block flag")

    if dist_values is None:
        raise ColaError("scan carries no 16-bit DIST channel")
    dist, raw = dist_values
    if out_ranges_m is not None:
        _check_out(out_ranges_m, dist.count, "out_ranges_m")
    if out_angles_rad is not None:
        _check_out(out_angles_rad, dist.count, "out_angles_rad")
    if out_raw is not None:
        _check_out(out_raw, dist.count, "out_raw")
    if out_rssi is not None and rssi_values is not None:
        _check_out(out_rssi, rssi_values[0].count, "out_rssi")
    if not (math.isfinite(dist.scale_factor) and dist.scale_factor > 0 and math.isfinite(dist.scale_offset)):
        raise ColaError(f"{dist.name}: unusable scale factor {dist.scale_factor} / offset {dist.scale_offset}")

    if out_ranges_m is not None:
        np.multiply(raw, dist.scale_factor / 1000.0, out=out_ranges_m)
        if dist.scale_offset:
            out_ranges_m += dist.scale_offset
        np.copyto(out_ranges_m, np.nan, where=out_ranges_m < min_range_m)
    if out_angles_rad is not None:
        np.multiply(_index(dist.count), dist.step_rad, out=out_angles_rad)
        out_angles_rad += dist.start_rad
    if out_raw is not None:
        out_raw[:] = raw
    if out_rssi is not None and rssi_values is not None:
        out_rssi[:] = rssi_values[1]

    return ScanHeader(
        kind.decode(), version, device_number, serial, status, telegram_counter, scan_counter, t_scan, t_tx,
        inputs, outputs, reserved, scan_frequency, measurement_frequency, encoders,
        tuple(channels[0]), tuple(channels[1]), position, device_name, comment, timestamp, event,
    )


# The fixed part after "sRA LMDscandata": (bits, name) of tokens 2..18 (§4).
_FIXED_FIELDS = (
    (16, "version"), (16, "device number"), (32, "serial number"), (8, "device status"), (8, "device status"),
    (16, "telegram counter"), (16, "scan counter"), (32, "time since start-up"), (32, "time of transmission"),
    (8, "input status"), (8, "input status"), (8, "output status"), (8, "output status"), (16, "reserved"),
    (32, "scan frequency"), (32, "measurement frequency"), (16, "number of encoders"),
)
_FIXED_RE = re.compile(rb" ([0-9A-Fa-f]{1,16})" * len(_FIXED_FIELDS) + rb"(?= |\Z)")
_CHANNEL_RE = re.compile(rb"([^ ]{5}) ([0-9A-Fa-f]{8}) ([0-9A-Fa-f]{8}) ([0-9A-Fa-f]{1,8}) "
                         rb"([0-9A-Fa-f]{1,4}) ([0-9A-Fa-f]{1,4})(?= |\Z)")


def _fast_fixed_fields(data: bytes, reader: TokenReader) -> list[int] | None:
    """Tokens 2..18 with one regex match (the token-by-token path costs ~4x more)."""
    match = _FIXED_RE.match(data, reader.pos - 1)
    if match is None:
        return None
    fields = [int(token, 16) for token in match.groups()]
    if any(value >> bits for value, (bits, _) in zip(fields, _FIXED_FIELDS)):
        return None
    reader.pos = match.end() + 1
    return fields


def _fast_channel(data: bytes, reader: TokenReader) -> Channel | None:
    """One channel header with one regex match; None sends the caller down the careful path."""
    if reader.pos > reader.end:
        return None
    match = _CHANNEL_RE.match(data, reader.pos)
    if match is None:
        return None
    name, factor, offset, start, step, count = match.groups()
    start_angle = int(start, 16)
    reader.pos = match.end() + 1
    return Channel(name.decode("latin-1"), struct.unpack(">f", bytes.fromhex(factor.decode()))[0],
                   struct.unpack(">f", bytes.fromhex(offset.decode()))[0],
                   start_angle - (1 << 32) if start_angle & 0x80000000 else start_angle,
                   int(step, 16), int(count, 16))


def _check_out(array: np.ndarray, count: int, what: str) -> None:
    if array.ndim != 1 or array.shape[0] != count:
        raise ColaError(f"the scan has {count} values; {what} has shape {array.shape}")


def build_scan(header: ScanHeader, dist_raw: ArrayLike, rssi_raw: ArrayLike | None = None) -> bytes:
    """The framed telegram for `header` and raw values: the exact inverse of `parse_scan`.

    The TiM layout: the first 16-bit channel is DIST, an RSSI channel (16- or 8-bit) takes
    `rssi_raw`. Raises ValueError (not ColaError: this is our own data) on anything else.
    """
    e = encode_uint
    parts = [
        header.command_type.encode(), b"LMDscandata",
        e(header.version, 16), e(header.device_number, 16), e(header.serial_number),
        e(header.device_status[0], 8), e(header.device_status[1], 8),
        e(header.telegram_counter, 16), e(header.scan_counter, 16),
        e(header.time_since_startup_us), e(header.time_of_transmission_us),
        e(header.input_status[0], 8), e(header.input_status[1], 8),
        e(header.output_status[0], 8), e(header.output_status[1], 8),
        e(header.reserved, 16), e(header.scan_frequency), e(header.measurement_frequency),
        e(len(header.encoders), 16),
    ]
    for position, speed in header.encoders:
        parts += [e(position), e(speed, 16)]
    used_dist = used_rssi = False
    for bits, channels in ((16, header.channels16), (8, header.channels8)):
        parts.append(e(len(channels), 16))
        for channel in channels:
            if bits == 16 and not used_dist and channel.name.startswith("DIST"):
                values, used_dist = dist_raw, True
            elif not used_rssi and channel.name.startswith("RSSI") and rssi_raw is not None:
                values, used_rssi = rssi_raw, True
            else:
                raise ValueError(f"no values for channel {channel.name}")
            parts += [channel.name.encode("latin-1"), encode_real(channel.scale_factor),
                      encode_real(channel.scale_offset), encode_int32(channel.start_angle),
                      e(channel.angular_step, 16), e(channel.count, 16)]
            if channel.count:
                parts.append(_encode_values(values, channel.count, bits))
    if not used_dist:
        raise ValueError("the header has no 16-bit DIST channel")
    parts.append(b"1" if header.position is not None else b"0")
    if header.position is not None:
        parts += [encode_real(v) for v in header.position[:6]] + [e(header.position[6], 8)]
    for text in (header.device_name, header.comment):
        parts.append(b"1" if text is not None else b"0")
        if text is not None:
            parts.append(encode_string(text))
    parts.append(b"1" if header.timestamp is not None else b"0")
    if header.timestamp is not None:
        parts += [e(v, b) for v, b in zip(header.timestamp, (16, 8, 8, 8, 8, 8, 32))]
    parts.append(b"1" if header.event is not None else b"0")
    if header.event is not None:
        kind, position, time_us, angle = header.event
        parts += [bytes(kind), e(position), e(time_us), encode_int32(angle)]
    return frame(b" ".join(parts))


def _encode_values(values: ArrayLike, count: int, bits: int) -> bytes:
    array = np.asarray(values)
    if array.shape != (count,):
        raise ValueError(f"expected {count} values, got shape {array.shape}")
    integers = array.astype(np.int64)
    if (integers != array).any() or integers.min() < 0 or integers.max() >= 1 << bits:
        raise ValueError(f"values must be integers in 0..{(1 << bits) - 1}")
    return (("%X " * count) % tuple(integers.tolist()))[:-1].encode()


def ranges_to_raw(ranges_m: ArrayLike, out: NDArray[np.integer], *, scale_factor: float = 1.0,
                  min_range_m: float = MIN_RANGE_M, max_range_m: float = 10.0) -> NDArray[np.integer]:
    """Metres to the raw values a device sends (mm / scale), 0 (no echo) where out of range or NaN."""
    ranges = np.asarray(ranges_m, dtype=np.float64)
    valid = np.isfinite(ranges) & (ranges >= min_range_m) & (ranges <= max_range_m)
    raw = np.rint(np.where(valid, ranges, 0.0) * (1000.0 / scale_factor))
    np.clip(raw, 0, 0xFFFF, out=raw)
    out[:] = raw
    return out


# ---------------------------------------------------------------------------------------------
# mounting


class SensorMount(NamedTuple):
    """Pose of the scanner's sensor frame in the robot frame (x forward, y left, yaw CCW)."""

    x_m: float = 0.0
    y_m: float = 0.0
    yaw_rad: float = 0.0


def to_robot_frame(ranges_m: NDArray[np.floating], angles_rad: NDArray[np.floating], mount: SensorMount,
                   out_x: NDArray[np.floating], out_y: NDArray[np.floating]) -> None:
    """Beam end points in the robot frame: (x, y) + R(yaw)·r(cos θ, sin θ); NaN stays NaN.

    The beam direction in the robot frame is simply θ + yaw; the translation moves the origin.
    """
    np.add(angles_rad, mount.yaw_rad, out=out_x)
    np.sin(out_x, out=out_y)
    np.cos(out_x, out=out_x)
    out_x *= ranges_m
    out_y *= ranges_m
    out_x += mount.x_m
    out_y += mount.y_m


# ---------------------------------------------------------------------------------------------
# requests and replies (§2.2, §3, §6)

REQUEST_TYPES = {b"sRN": b"sRA", b"sWN": b"sWA", b"sMN": b"sAN", b"sEN": b"sEA", b"sRI": b"sRA"}
REPLY_TYPES = frozenset({b"sRA", b"sWA", b"sAN", b"sMA", b"sEA", b"sSN", b"sFA"})


def password_hash(password: str) -> str:
    """SICK's login hash: MD5, XOR-fold 16 bytes into 4, little-endian uint32, 8 hex digits."""
    digest = hashlib.md5(password.encode("latin-1")).digest()
    folded = bytes(digest[k] ^ digest[k + 4] ^ digest[k + 8] ^ digest[k + 12] for k in range(4))
    return f"{struct.unpack('<I', folded)[0]:08X}"


def request(kind: str, name: str, *params: bytes | str | int) -> bytes:
    """A framed request; ints are encoded as unsigned hex, bytes/str are sent as they are."""
    parts = [kind.encode(), name.encode()]
    for param in params:
        if isinstance(param, bool) or isinstance(param, int):
            parts.append(encode_uint(int(param)))
        elif isinstance(param, str):
            parts.append(param.encode("latin-1"))
        else:
            parts.append(bytes(param))
    return frame(b" ".join(parts))


@dataclass(frozen=True, slots=True)
class Reply:
    """A decoded reply: type, name, and the raw parameters (strings may contain spaces)."""

    kind: bytes  # sRA, sWA, sAN, sMA, sEA, sSN
    name: bytes
    params: bytes

    def reader(self) -> TokenReader:
        return TokenReader(self.params)


def is_text(body: bytes) -> bool:
    """No control bytes: a CoLa A body, not a CoLa B frame or binary noise."""
    return _CONTROL.search(body) is None


def parse_reply(body: bytes, request_text: str | None = None) -> Reply:
    """Decode a reply body (or framed telegram); `sFA <code>` raises ColaDeviceError."""
    data = bytes(body)
    if data[:1] == b"\x02":
        data = unframe(data)
    if not is_text(data):
        raise ColaError("not CoLa A: control bytes in the body (a CoLa B frame?)")
    reader = TokenReader(data)
    kind = reader.token("command type")
    if kind == b"sFA":
        raise ColaDeviceError(_sfa_code(reader), request_text)
    if kind not in REPLY_TYPES:
        raise ColaError(f"unknown reply type {_show(kind)}")
    name = reader.token("name")
    return Reply(kind, name, reader.rest())


def _sfa_code(reader: TokenReader) -> int:
    code = reader.uint(16, "sFA error code")
    reader.expect_end("the sFA error code")
    return code


def expected_reply(request_body: bytes) -> tuple[bytes, bytes]:
    """(reply type, name) that answers a request: `sRN X` → (`sRA`, `X`); sFA answers any."""
    data = request_body[1:-1] if request_body[:1] == b"\x02" else request_body
    kind, _, rest = data.partition(b" ")
    if kind.startswith(b"sRI") and len(kind) > 3:  # uos/sick_tim's "sRI0"
        return b"sRA", kind[3:]
    if kind not in REQUEST_TYPES:
        raise ValueError(f"not a CoLa request: {data[:20]!r}")
    return REQUEST_TYPES[kind], rest.partition(b" ")[0]


@dataclass(frozen=True, slots=True)
class Command:
    """One start-up step: the request, the reply that answers it, and what counts as success."""

    request: bytes  # framed
    ok: tuple[bytes, ...] | None = None  # accepted reply parameters; None: anything
    refused: str = "unexpected reply"
    reply: tuple[bytes, bytes] = field(init=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "reply", expected_reply(self.request))

    @property
    def text(self) -> str:
        return self.request[1:-1].decode("latin-1")

    def check(self, reply: Reply) -> None:
        """Raise ColaError when the reply means the step failed."""
        if self.ok is not None and reply.params not in self.ok:
            raise ColaError(f"{self.text!r} → {reply.kind.decode()} {reply.name.decode()} "
                            f"{reply.params.decode('latin-1')!r}: {self.refused}")


@dataclass(frozen=True, slots=True)
class OutputRange:
    """`LMPoutputRange`: angular step and start/stop in 1/10000°, SICK frame (-45°…225° on a TiM)."""

    step: int = 3333
    start: int = -450000
    stop: int = 2250000

    def params(self) -> bytes:
        return b"1 " + encode_uint(self.step, 16) + b" " + encode_int32(self.start) + b" " + encode_int32(self.stop)


@dataclass(frozen=True, slots=True)
class ScanDataConfig:
    """`LMDscandatacfg` (12 tokens, from sick_scan_xd's template; not tested on a TiM561)."""

    rssi: bool = False
    rssi_16bit: bool = True
    device_name: bool = False
    comment: bool = False
    time: bool = False
    every_nth: int = 1

    def params(self) -> bytes:
        flags = (1, 0, int(self.rssi), int(self.rssi_16bit), 0, 0, 0, 0, int(self.device_name),
                 int(self.comment), int(self.time), self.every_nth)
        return b" ".join(encode_uint(v, 16) for v in flags)


def set_access_mode(level: int = 3, hash_hex: str = LEVEL3_HASH) -> Command:
    return Command(request("sMN", "SetAccessMode", level, hash_hex), (b"1",),
                   "login refused: wrong level or password hash")


def set_cola_dialect(binary: bool = False) -> Command:
    return Command(request("sWN", "EIHstCola", int(binary)), (b"",))


def read_device_state() -> Command:
    return Command(request("sRN", "SCdevicestate"), (b"0", b"1"),
                   "device state is not ready/busy (2 = error: reboot it with sMN mSCreboot)")


def set_output_range(output: OutputRange = OutputRange()) -> Command:
    return Command(request("sWN", "LMPoutputRange", output.params()), (b"",))


def set_scan_data_config(config: ScanDataConfig) -> Command:
    return Command(request("sWN", "LMDscandatacfg", config.params()), (b"",))


def start_measurement() -> Command:
    return Command(request("sMN", "LMCstartmeas"), (b"0",), "start of measurement refused")


def run() -> Command:
    return Command(request("sMN", "Run"), (b"1",), "Run (apply settings, log out) refused")


def subscribe_scans(on: bool = True) -> Command:
    return Command(request("sEN", "LMDscandata", int(on)), (b"1" if on else b"0",), "subscription refused")


def startup_sequence(*, configure: bool = True, level: int = 3, hash_hex: str = LEVEL3_HASH,
                     output_range: OutputRange | None = OutputRange(),
                     scan_config: ScanDataConfig | None = None) -> tuple[Command, ...]:
    """The order of sick_scan_xd and docs/devices/sick-tim561.md: login, CoLa A, state, range, (content), start,
    Run, subscribe last (so no scan arrives between configuration replies). With
    `configure=False` only the subscription: a powered TiM measures on its own.
    """
    steps: list[Command] = []
    if configure:
        steps += [set_access_mode(level, hash_hex), set_cola_dialect(False), read_device_state()]
        if output_range is not None:
            steps.append(set_output_range(output_range))
        if scan_config is not None:
            steps.append(set_scan_data_config(scan_config))
        steps += [start_measurement(), run()]
    steps.append(subscribe_scans(True))
    return tuple(steps)
