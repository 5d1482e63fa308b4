"""The TiM's scan telegram, `LMDscandata` (docs/devices/sick-tim561.md §4, §5), and where its beams land on the robot.

`parse_scan` walks one telegram with a cursor that uses the counts the telegram carries, and
converts the value block of each channel in one vectorised numpy pass into arrays the caller
owns. `build_scan` is its exact inverse, so the simulator sends what the device sends, byte
for byte. Both use the CoLa A values and token reader of `cola`, and raise its errors.

Frames. SICK device frame: 0° and 180° lie across the scanner, 90° points out of the front
window, the field of view is -45°…225°. Sensor frame (REP 103: x forward, y left, z up,
counter-clockwise positive): theta = sick - 90°, not mirrored; a TiM561 covers
-135°…+134.973°. `to_robot_frame` then places the beams with the mount pose (x, y, yaw) of
the scanner on the robot: p_robot = (x, y) + R(yaw) · r (cos theta, sin theta).
"""

from __future__ import annotations

import math
import re
import struct
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

from hapticop.devices.sick import scan_loops
from hapticop.devices.sick.cola import (
    ColaDeviceError,
    ColaError,
    TokenReader,
    encode_int32,
    encode_real,
    encode_string,
    encode_uint,
    frame,
    show_token,
    unframe,
)
from hapticop.devices.sick.commands import sfa_code

MIN_RANGE_M = 0.05  # TiM5xx minimum range: anything closer (including 0 = no echo) is invalid
TIM561_POINTS = 811

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
# the telegram


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
        raise ColaDeviceError(sfa_code(reader), "LMDscandata")
    if kind not in (b"sRA", b"sSN"):
        raise ColaError(f"not a scan: command type {show_token(kind)}, expected sRA or sSN")
    name = reader.token("command name")
    if name != b"LMDscandata":
        raise ColaError(f"not a scan: {show_token(kind + b' ' + name)}")
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
                    raise ColaError(f"channel name {show_token(channel_name)} is not 5 characters")
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
        if scan_loops.COMPILED and _loopable(out_ranges_m):  # `values` gives uint32 either way
            scan_loops.scale_ranges(raw, dist.scale_factor / 1000.0, dist.scale_offset, min_range_m, out_ranges_m)
        else:
            np.multiply(raw, dist.scale_factor / 1000.0, out=out_ranges_m)
            if dist.scale_offset:
                out_ranges_m += dist.scale_offset
            np.copyto(out_ranges_m, np.nan, where=out_ranges_m < min_range_m)
    if out_angles_rad is not None:
        if scan_loops.COMPILED and _loopable(out_angles_rad):
            scan_loops.beam_angles(dist.start_rad, dist.step_rad, out_angles_rad)
        else:
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


def _loopable(array: np.ndarray) -> bool:
    """What the compiled loops write (scan_loops.py): a contiguous, writable float64 array."""
    return array.dtype == np.float64 and array.flags.c_contiguous and array.flags.writeable


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
