"""What a TiM561 answers to each CoLa A request, and the scans it makes: the device without its socket.

Replies copy the real device where captures exist (`sRI 0`, `SerialNumber`, `SetAccessMode`,
`EIHstCola`) and docs/devices/sick-tim561.md (§3, §7) elsewhere; scans are built by
`scan.build_scan`, with counters and device clock advancing as §9 describes: +1 per scan,
66 666/66 667 µs apart, sent 5 ms after the scan, wrapping at 16 and 32 bits. Scan k is sent at
epoch + k/15 s (epoch = the first `advance`), and its ranges come from `ranges_m(t_ns)`, t_ns
being when the scan was taken (5 ms earlier), in the sensor frame at `ANGLES_RAD`.

Login, output range, scan content and measuring outlive a connection; the login and the
subscription belong to one session (`open_session` … `close_session`). Which scans reach the
client, and when, is `simulator.TiMSimulator`'s business.
"""

from __future__ import annotations

import time
from collections.abc import Callable

import numpy as np
from numpy.typing import NDArray

from hapticop.devices.sick import cola, commands, scan
from hapticop.devices.sick.cola import ColaError, encode_int32, encode_string, encode_uint
from hapticop.devices.sick.scan import Channel, ScanHeader

FULL_START = -450000  # 1/10000 degree, SICK frame
FULL_STOP = 2250000
STEP = 3333  # D05: 0.3333 degree, as sent (not 1/3)
POINTS = 811
ANGLES_RAD = np.radians((FULL_START + np.arange(POINTS) * STEP) / 10000.0 - 90.0)  # sensor frame
MEASUREMENT_FREQUENCY = 162  # A2: 16.2 kHz
PASSWORD_HASHES = {2: "B21ACE26", 3: "F4724744", 4: "81BE23AA"}
_NS_PER_CENTIHZ = 100_000_000_000  # period in ns = this / scan_frequency (1/100 Hz)


def room_ranges(angles_rad: NDArray[np.float64] = ANGLES_RAD, *, front: float = 4.0, back: float = 1.0,
                left: float = 2.5, right: float = 2.0) -> NDArray[np.float64]:
    """Ranges to the walls of a rectangular room around the sensor (metres from it, per side)."""
    c, s = np.cos(angles_rad), np.sin(angles_rad)
    with np.errstate(divide="ignore"):
        tx = np.where(c > 0, front / c, np.where(c < 0, -back / c, np.inf))
        ty = np.where(s > 0, left / s, np.where(s < 0, -right / s, np.inf))
    return np.minimum(tx, ty)


class TiMDevice:
    """The TiM561's state and its answers: `answer` turns one request body into the framed reply."""

    def __init__(
        self,
        *,
        ranges_m: Callable[[int], NDArray[np.floating]] | None = None,
        noise_std_m: float = 0.0,
        rng: np.random.Generator | None = None,
        scan_rate_hz: float = 15.0,
        serial_number: int = 0x1078AAA,
        device_name: str = "not defined",
        firmware: str = "V2.51-21.08.15",
        uptime_us: int = 1_073_560_940,
        telegram_counter: int = 0x3E22,
        tx_delay_us: int = 5000,
        max_range_m: float = 10.0,
    ):
        if noise_std_m and rng is None:
            raise ValueError("noise needs an rng (np.random.default_rng(seed)), so runs can be repeated")
        self._room = room_ranges()
        self.ranges_m = ranges_m or (lambda t_ns: self._room)
        self.noise_std_m, self.rng = noise_std_m, rng
        self.scan_frequency = round(scan_rate_hz * 100)
        self.serial_number, self.device_name, self.firmware = serial_number, device_name, firmware
        self.uptime_us, self.telegram_counter0, self.tx_delay_us = uptime_us, telegram_counter, tx_delay_us
        self.max_range_m = max_range_m

        # device state: survives connections
        self.measuring = True
        self.output_range = (FULL_START, FULL_STOP)
        self.scan_config = {"rssi": False, "rssi16": True, "name": True, "comment": False, "time": False, "nth": 1}
        self._pending_range = self.output_range
        self._pending_config = dict(self.scan_config)
        self.dialect = 0
        self.muted = False  # a fault: commands get no reply at all
        # session state
        self.access_level = 0
        self.subscribed = False
        self.rebooting = False  # asked to reboot: it drops off the network once its reply is out
        # time
        self.epoch_ns: int | None = None
        self.now_ns = 0
        self.commands = 0
        # raw buffers
        self._raw = np.zeros(POINTS, np.uint16)
        self._rssi = np.zeros(POINTS, np.uint16)

    # -- sessions and time ---------------------------------------------------------------------

    def open_session(self) -> None:
        """A client connected: logged out, not subscribed."""
        self.access_level = 0
        self.subscribed = False
        self.rebooting = False

    def close_session(self) -> None:
        """The connection ended: no subscription, and a dropped login goes back to measuring, like after Run."""
        self.subscribed = False
        if self.access_level:
            self.access_level = 0
            self.measuring = True

    @property
    def streaming(self) -> bool:
        """Subscribed and measuring: its scans go out as they are made."""
        return self.subscribed and self.measuring

    def advance(self, now_ns: int) -> None:
        """The device's time is now_ns; the first call starts its scan schedule."""
        if self.epoch_ns is None:
            self.epoch_ns = now_ns
        self.now_ns = now_ns

    @property
    def period_ns(self) -> float:
        return _NS_PER_CENTIHZ / self.scan_frequency

    def scan_index(self, t_ns: int) -> int:
        """The newest scan sent at or before t_ns (scan k leaves at epoch + k periods)."""
        assert self.epoch_ns is not None
        return (t_ns - self.epoch_ns) * self.scan_frequency // _NS_PER_CENTIHZ

    def scan_time_ns(self, k: int) -> int:
        """When scan k is sent (its telegram leaves the device)."""
        assert self.epoch_ns is not None
        return self.epoch_ns - (-k * _NS_PER_CENTIHZ // self.scan_frequency)

    # -- scans -----------------------------------------------------------------------------

    def scan_telegram(self, k: int, command_type: str = "sSN") -> bytes:
        """The framed telegram of scan k, as the device would send it now."""
        t_sent = self.scan_time_ns(k)
        assert self.epoch_ns is not None
        t_tx = (self.uptime_us + (t_sent - self.epoch_ns) // 1000) & 0xFFFFFFFF
        t_scan = (t_tx - self.tx_delay_us) & 0xFFFFFFFF
        ranges = np.asarray(self.ranges_m(t_sent - self.tx_delay_us * 1000), dtype=np.float64)
        if ranges.shape != (POINTS,):
            raise ValueError(f"ranges_m must return {POINTS} values, got shape {ranges.shape}")
        if self.noise_std_m:
            assert self.rng is not None
            ranges = ranges + self.rng.normal(0.0, self.noise_std_m, POINTS)
        scan.ranges_to_raw(ranges, self._raw, max_range_m=self.max_range_m)
        # A narrowed output range is cut from the fixed grid -45° + i·0.3333° (how the real device
        # aligns it is not documented): the first point at or after start, the last at or before stop.
        first = -((FULL_START - self.output_range[0]) // STEP)  # ceil((start - FULL_START) / STEP)
        last = (self.output_range[1] - FULL_START) // STEP
        count = last - first + 1
        config = self.scan_config
        dist = Channel("DIST1", 1.0, 0.0, FULL_START + first * STEP, STEP, count)
        rssi_channel = Channel("RSSI1", 1.0, 0.0, dist.start_angle, STEP, count)
        rssi = None
        if config["rssi"]:
            if config["rssi16"]:
                level = np.clip(12000.0 - 0.5 * self._raw, 1000.0, 65535.0)
            else:
                level = np.clip(230.0 - self._raw / 50.0, 10.0, 255.0)
            self._rssi[:] = np.where(self._raw > 0, level, 0.0)
            rssi = self._rssi[first:last + 1]
        timestamp = None
        if config["time"]:  # the device clock from 1970-01-01, as on a TiM whose clock was never set
            parts = time.gmtime(t_scan // 1_000_000)
            timestamp = (parts.tm_year, parts.tm_mon, parts.tm_mday, parts.tm_hour, parts.tm_min,
                         parts.tm_sec, t_scan % 1_000_000)
        telegram_counter = (self.telegram_counter0 + k) & 0xFFFF
        header = ScanHeader(
            command_type, 1, 1, self.serial_number, (0, 0), telegram_counter, (telegram_counter + 2) & 0xFFFF,
            t_scan, t_tx, (0, 0), (1, 0), 0, self.scan_frequency, MEASUREMENT_FREQUENCY, (),
            (dist, rssi_channel) if config["rssi"] and config["rssi16"] else (dist,),
            (rssi_channel,) if config["rssi"] and not config["rssi16"] else (),
            None,
            self.device_name.encode("latin-1") if config["name"] else None,
            None,
            timestamp,
            None,
        )
        return scan.build_scan(header, self._raw[first:last + 1], rssi)

    # -- commands (§3, §7) -------------------------------------------------------------------

    def answer(self, body: bytes) -> bytes | None:
        """The framed reply to one request body; None when the device stays silent."""
        if not body or not commands.is_text(body) or self.muted:
            return None  # empty frame, other dialect or binary noise: the device stays silent
        self.commands += 1
        kind, _, rest = body.partition(b" ")
        if kind.startswith(b"sRI") and len(kind) > 3:  # "sRI0", as uos/sick_tim sends it
            kind, rest = b"sRI", kind[3:] + (b" " + rest if rest else b"")
        name, _, params = rest.partition(b" ")
        tokens = params.split(b" ") if params else []
        handler = {b"sRN": self._read_variable, b"sWN": self._write_variable, b"sMN": self._method,
                   b"sEN": self._event, b"sRI": self._read_index}.get(kind)
        if handler is None or not name:
            return _sfa(0xC)
        try:
            return handler(name, tokens)
        except ColaError:
            return _sfa(0x11)
        except IndexError:
            return _sfa(0x8)

    def _read_index(self, name: bytes, tokens: list[bytes]) -> bytes:
        if cola.decode_uint(name, 16) != 0:
            return _sfa(0x3)
        return _reply(b"sRA", name, encode_string("TiM561") + b" " + encode_string(self.firmware))

    def _read_variable(self, name: bytes, tokens: list[bytes]) -> bytes:
        values: dict[bytes, Callable[[], bytes]] = {
            b"SCdevicestate": lambda: b"1" if self.measuring and not self.access_level else b"0",
            b"LMPoutputRange": lambda: b"1 " + encode_uint(STEP, 16) + b" " + encode_int32(self.output_range[0])
            + b" " + encode_int32(self.output_range[1]),
            b"SerialNumber": lambda: encode_string(str(self.serial_number)),
            b"FirmwareVersion": lambda: encode_string(self.firmware.split("-")[0]),
            b"LocationName": lambda: encode_string(self.device_name),
            b"EIHstCola": lambda: encode_uint(self.dialect, 8),
            b"ODoprh": lambda: encode_uint(0x68C),
            b"ODpwrc": lambda: encode_uint(0x79),
            b"LMDscandatacfg": lambda: _scan_config_tokens(self.scan_config),
        }
        if name == b"LMDscandata":
            assert self.epoch_ns is not None
            return self.scan_telegram(self.scan_index(self.now_ns), "sRA")
        value = values.get(name)
        return _sfa(0x3) if value is None else _reply(b"sRA", name, value())

    def _write_variable(self, name: bytes, tokens: list[bytes]) -> bytes:
        if name not in (b"EIHstCola", b"LMPoutputRange", b"LMDscandatacfg", b"LocationName"):
            return _sfa(0x3)
        if not self.access_level:
            return _sfa(0xA)
        if name == b"EIHstCola":
            value = cola.decode_uint(tokens[0], 8)
            if value > 1:
                return _sfa(0x4)
            self.dialect = value  # stored, never applied: this simulator speaks CoLa A only
        elif name == b"LMPoutputRange":
            sectors, step = cola.decode_uint(tokens[0], 16), cola.decode_uint(tokens[1], 32)
            start, stop = cola.decode_int32(tokens[2]), cola.decode_int32(tokens[3])
            if sectors != 1 or step != STEP or not FULL_START <= start < stop <= FULL_STOP:
                return _sfa(0x4)
            self._pending_range = (start, stop)
        elif name == b"LMDscandatacfg":
            if len(tokens) < 12:
                return _sfa(0x8)
            v = [cola.decode_uint(t, 16) for t in tokens[:12]]
            if v[11] < 1:
                return _sfa(0x4)
            self._pending_config = {"rssi": bool(v[2]), "rssi16": bool(v[3]), "name": bool(v[8]),
                                    "comment": bool(v[9]), "time": bool(v[10]), "nth": v[11]}
        else:
            return _sfa(0xA)  # the name is set with SOPAS here
        return _reply(b"sWA", name)

    def _method(self, name: bytes, tokens: list[bytes]) -> bytes:
        if name == b"SetAccessMode":
            level = cola.decode_uint(tokens[0], 8)
            good = PASSWORD_HASHES.get(level) == tokens[1].decode("latin-1").upper()
            if good:
                self.access_level = level
                self.measuring = False  # logged in: the device stops measuring until Run
            return _reply(b"sAN", name, b"1" if good else b"0")
        if name == b"Run":
            self.output_range, self.scan_config = self._pending_range, dict(self._pending_config)
            self.access_level = 0
            self.measuring = True
            return _reply(b"sAN", name, b"1")
        if name not in (b"LMCstartmeas", b"LMCstopmeas", b"mEEwriteall", b"mSCreboot"):
            return _sfa(0x2)
        if not self.access_level:
            return _sfa(0x1)
        if name == b"LMCstartmeas":
            return _reply(b"sAN", name, b"0")
        if name == b"LMCstopmeas":
            self.measuring = False
            return _reply(b"sAN", name, b"0")
        if name == b"mEEwriteall":
            return _reply(b"sAN", name, b"1")
        self.rebooting = True  # mSCreboot: the device drops off the network
        return _reply(b"sAN", name)

    def _event(self, name: bytes, tokens: list[bytes]) -> bytes:
        if name != b"LMDscandata":
            return _sfa(0xF)
        on = cola.decode_uint(tokens[0], 8)
        if on > 1:
            return _sfa(0x4)
        self.subscribed = bool(on)
        return _reply(b"sEA", name, tokens[0])


def _reply(kind: bytes, name: bytes, value: bytes | None = None) -> bytes:
    return cola.frame(kind + b" " + name + (b" " + value if value is not None else b""))


def _sfa(code: int) -> bytes:
    return cola.frame(b"sFA " + encode_uint(code, 16))


def _scan_config_tokens(config: dict) -> bytes:
    values = (1, 0, int(config["rssi"]), int(config["rssi16"]), 0, 0, 0, 0, int(config["name"]),
              int(config["comment"]), int(config["time"]), config["nth"])
    return b" ".join(encode_uint(v, 16) for v in values)
