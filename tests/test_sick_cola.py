"""CoLa A codec against real TiM561 captures: values, scans (both ways, byte-exact), replies, fuzz."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from hapticop.devices.sick import cola, commands, scan, scan_loops
from hapticop.devices.sick.cola import ColaDeviceError, ColaError
from hapticop.devices.sick.scan import SensorMount
from hapticop.devices.sick.stream import TelegramReader

HERE = Path(__file__).resolve().parent
LOCAL = HERE / "fixtures" / "sick" / "cola_a"
SHARED = HERE.parent.parent / "shared" / "testdata" / "sick" / "cola_a"


def captures(pattern: str, subdir: str = "") -> list[Path]:
    """The shipped copies, plus the full set in ../shared when it is there."""
    found = sorted((LOCAL / subdir).glob(pattern))
    if (SHARED / subdir).is_dir():
        found += sorted((SHARED / subdir).glob(pattern))
    assert found, f"no capture matches {pattern}"
    return found


def ident(path: Path) -> str:
    return ("shared/" if SHARED in path.parents else "local/") + path.stem


SCANS = captures("tim561_sRA_LMDscandata_*.bin")
SIM00 = [p for p in SCANS if p.stem.endswith("sim00")]
RSSI = [p for p in SCANS if "rssi" in p.stem]


def arrays(n: int = scan.TIM561_POINTS):
    return np.empty(n), np.empty(n), np.empty(n, np.uint16), np.empty(n, np.uint16)


# -- values (§2.1) -------------------------------------------------------------------------

def test_value_encodings_match_the_notes():
    assert cola.encode_uint(0) == b"0" and cola.encode_uint(3333, 16) == b"D05"
    assert cola.encode_int32(-450000) == b"FFF92230" and cola.encode_int32(2250000) == b"225510"
    assert cola.decode_int32(b"FFF92230") == -450000 and cola.decode_int32(b"-450000") == -450000
    assert cola.decode_int32(b"+2250000") == 2250000
    assert cola.encode_real(1.0) == b"3F800000" and cola.encode_real(0.0) == b"00000000"
    assert cola.decode_real(b"40000000") == 2.0
    assert cola.decode_uint(b"03", 8) == 3  # leading zeros are accepted
    assert cola.encode_string("not defined") == b"B not defined"
    reader = cola.TokenReader(b"B not defined 7 Daniyal 0")
    assert reader.string("a") == b"not defined" and reader.string("b") == b"Daniyal" and reader.string("c") == b""
    assert reader.at_end
    for bad, call in [(b"G1", cola.decode_uint), (b"1FFFF", lambda t: cola.decode_uint(t, 16)),
                      (b"3F80000", cola.decode_real), (b"+99999999999", cola.decode_int32),
                      (b"0x10", cola.decode_uint), (b" 1", cola.decode_uint), (b"1_0", cola.decode_uint)]:
        with pytest.raises(ColaError):
            call(bad)


def test_password_hashes_of_the_three_levels():
    assert commands.password_hash("client") == "F4724744" == cola.LEVEL3_HASH
    assert commands.password_hash("main") == "B21ACE26"
    assert commands.password_hash("servicelevel") == "81BE23AA"


def test_framing():
    assert cola.frame("sRN SCdevicestate") == b"\x02sRN SCdevicestate\x03"
    assert cola.unframe(b"\x02sFA 1\x03") == b"sFA 1"
    for bad in (b"", b"\x02", b"sRN X", b"\x02sRN X", b"\x02a\x02b\x03", b"\x02a\x03b\x03"):
        with pytest.raises(ColaError):
            cola.unframe(bad)
    with pytest.raises(ValueError):
        cola.frame(b"a\x03b")


# -- scans (§4, §5, §10) ---------------------------------------------------------------------

@pytest.mark.parametrize("path", SCANS, ids=ident)
def test_every_capture_parses_to_811_points(path):
    ranges, angles, raw, rssi = arrays()
    header = scan.parse_scan(path.read_bytes(), ranges, angles, out_raw=raw, out_rssi=rssi)
    assert header.command_type == "sRA" and header.serial_number == 0x1078AAA
    assert header.dist.count == 811 and header.dist.name == "DIST1"
    assert (header.scan_frequency, header.measurement_frequency) == (1500, 162)
    assert header.scan_period_s == pytest.approx(1 / 15)
    assert header.scan_counter - header.telegram_counter == 2
    invalid = raw < 50
    assert np.isnan(ranges[invalid]).all() and not np.isnan(ranges[~invalid]).any()
    assert np.nanmax(ranges) <= 10.0
    assert angles[0] == pytest.approx(-math.radians(135)) and angles[-1] == pytest.approx(math.radians(134.973))
    if "rssi" in path.stem:
        assert header.rssi is not None and header.rssi.count == 811 and header.device_name is None
        assert (rssi[invalid] == 0).all()  # no echo: no intensity either
        assert set(np.unique(raw[invalid])) == {0, 2}  # both invalid codes of §5 occur
    else:
        assert header.rssi is None and header.device_name == b"Daniyal"


@pytest.mark.parametrize("path", SIM00, ids=ident)
def test_worked_example_of_section_10(path):
    ranges, angles, raw, _ = arrays()
    header = scan.parse_scan(path.read_bytes(), ranges, angles, out_raw=raw)
    assert (header.version, header.device_number, header.serial_number) == (1, 1, 17_271_466)
    assert header.device_status == (0, 0) and header.output_status == (1, 0) and header.input_status == (0, 0)
    assert (header.telegram_counter, header.scan_counter) == (15_906, 15_908)
    assert header.time_since_startup_us == 1_073_560_940
    assert header.time_of_transmission_us - header.time_since_startup_us == 4_952
    dist = header.dist
    assert (dist.scale_factor, dist.scale_offset, dist.start_angle, dist.angular_step) == (1.0, 0.0, -450000, 3333)
    assert list(raw[:3]) == [1598, 1623, 1634]
    assert list(ranges[:3]) == pytest.approx([1.598, 1.623, 1.634], abs=1e-12)
    assert list(np.round(angles[:3], 6)) == [-2.356194, -2.350377, -2.344560]
    assert math.degrees(angles[405]) == pytest.approx(-0.0135, abs=1e-9) and ranges[405] == pytest.approx(0.924)
    assert math.degrees(angles[810]) == pytest.approx(134.973, abs=1e-9) and ranges[810] == pytest.approx(1.109)
    assert (header.position, header.comment, header.timestamp, header.event) == (None, None, None, None)


@pytest.mark.parametrize("path", SCANS, ids=ident)
def test_build_scan_inverts_parse_scan_byte_for_byte(path):
    telegram = path.read_bytes()
    ranges, angles, raw, rssi = arrays()
    header = scan.parse_scan(telegram, ranges, out_raw=raw, out_rssi=rssi)
    assert scan.build_scan(header, raw, rssi if header.rssi else None) == telegram
    streamed = b"\x02sSN" + telegram[4:]  # the same body as a stream frame
    header = scan.parse_scan(streamed[1:-1], ranges, out_raw=raw, out_rssi=rssi)
    assert header.command_type == "sSN"
    assert scan.build_scan(header, raw, rssi if header.rssi else None) == streamed


def test_optional_blocks_round_trip():
    """Blocks the TiM561 captures do not show (8-bit RSSI, position, comment, time, event)."""
    ranges, _, raw, _ = arrays()
    base = scan.parse_scan(SIM00[0].read_bytes(), ranges, out_raw=raw)
    rssi_channel = scan.Channel("RSSI1", 1.0, 0.0, -450000, 3333, 811)
    header = scan.ScanHeader(**{
        **{f: getattr(base, f) for f in base.__dataclass_fields__},
        "encoders": ((0x12345678, 3),), "channels8": (rssi_channel,),
        "position": (1.0, -2.5, 0.0, 0.0, 0.0, 3.25, 1), "device_name": b"a name with spaces",
        "comment": b"", "timestamp": (1970, 1, 1, 0, 50, 14, 136000), "event": (b"FDIN", 7, 99, -450000)})
    rssi = np.arange(811) % 256
    telegram = scan.build_scan(header, raw, rssi)
    out_rssi = np.empty(811, np.uint8)
    parsed = scan.parse_scan(telegram, ranges, out_raw=raw, out_rssi=out_rssi)
    assert parsed == header and (out_rssi == rssi).all()
    assert scan.build_scan(parsed, raw, out_rssi) == telegram


def test_parse_writes_into_float32_ports_and_only_on_success():
    ranges, angles = np.full(811, -1.0, np.float32), np.zeros(811, np.float32)
    body = SIM00[0].read_bytes()[1:-1]
    scan.parse_scan(body, ranges, angles)
    assert ranges[0] == np.float32(1.598) and angles[405] == pytest.approx(-0.000236, abs=1e-6)
    before = ranges.copy()
    with pytest.raises(ColaError):
        scan.parse_scan(body.replace(b"7 Daniyal", b"8 Daniyal"), ranges, angles)  # fails in the trailer
    assert (ranges == before).all()
    with pytest.raises(ColaError, match="811 values"):
        scan.parse_scan(body, np.empty(271))
    assert scan.parse_scan(body, None).dist.count == 811  # header only: to size the arrays


def test_sensor_to_robot_frame():
    ranges = np.array([1.0, 2.0, np.nan])
    angles = np.array([0.0, math.pi / 2, 0.0])
    x, y = np.empty(3), np.empty(3)
    scan.to_robot_frame(ranges, angles, SensorMount(0.3, -0.1, math.pi / 2), x, y)
    assert x[:2] == pytest.approx([0.3, 0.3 - 2.0]) and y[:2] == pytest.approx([-0.1 + 1.0, -0.1])
    assert math.isnan(x[2]) and math.isnan(y[2])


# -- replies and commands (§3, §6) -------------------------------------------------------------

def test_startup_commands_are_the_documented_bytes():
    texts = [command.text for command in commands.startup_sequence(scan_config=commands.ScanDataConfig(rssi=True))]
    assert texts == [
        "sMN SetAccessMode 3 F4724744", "sWN EIHstCola 0", "sRN SCdevicestate",
        "sWN LMPoutputRange 1 D05 FFF92230 225510", "sWN LMDscandatacfg 1 0 1 1 0 0 0 0 0 0 0 1",
        "sMN LMCstartmeas", "sMN Run", "sEN LMDscandata 1",
    ]
    assert [c.text for c in commands.startup_sequence(configure=False)] == ["sEN LMDscandata 1"]
    assert commands.expected_reply(b"\x02sRI0\x03") == (b"sRA", b"0")


@pytest.mark.parametrize("path", captures("*.bin", "replies"), ids=ident)
def test_captured_replies_parse(path):
    reply = commands.parse_reply(path.read_bytes())
    expected = {
        "mrs6124_sAN_SetAccessMode_1": (b"sAN", b"SetAccessMode", b"1"),
        "mrs6124_sWA_EIHstCola": (b"sWA", b"EIHstCola", b""),
        "tim561_fw251_sAN_SetAccessMode_0": (b"sAN", b"SetAccessMode", b"0"),
        "tim561_fw251_sRA_SerialNumber": (b"sRA", b"SerialNumber", b"8 16160456"),
        "tim561_fw251_sRA_index0_deviceident": (b"sRA", b"0", b"6 TiM561 E V2.51-21.08.15"),
    }[path.stem]
    assert (reply.kind, reply.name, reply.params) == expected
    if path.stem.endswith("deviceident"):
        reader = reply.reader()
        assert reader.string("name") == b"TiM561" and reader.string("version") == b"V2.51-21.08.15"
    login = commands.set_access_mode()
    if reply.name == b"SetAccessMode" and reply.params == b"0":
        with pytest.raises(ColaError, match="login refused"):
            login.check(reply)


def test_sfa_is_a_clear_device_error():
    with pytest.raises(ColaDeviceError, match=r"sFA 4 = LOCALCONDITIONFAILED") as caught:
        commands.parse_reply(b"\x02sFA 4\x03", "sWN LMPoutputRange 1 D05 0 1B7740")
    assert caught.value.code == 4 and "LMPoutputRange" in str(caught.value)
    with pytest.raises(ColaDeviceError, match="METHODIN_ACCESSDENIED"):
        scan.parse_scan(b"sFA 1", np.empty(811))
    assert "ComplexArraysNotSupported" in str(ColaDeviceError(0x20))
    with pytest.raises(ColaError):
        commands.parse_reply(b"sXX Foo")


# -- malformed telegrams and fuzz ----------------------------------------------------------------

BODY = SIM00[0].read_bytes()[1:-1]
MALFORMED = {
    "empty": b"",
    "only type": b"sSN",
    "not a scan": b"sRA SCdevicestate 1",
    "leading space": b" " + BODY,
    "trailing space": BODY + b" ",
    "double space": BODY.replace(b" 63E 657", b" 63E  657"),
    "truncated in values": BODY[:600],
    "truncated in trailer": BODY[:-4],
    "extra token": BODY + b" 0",
    "bad hex value": BODY.replace(b" 63E ", b" 6G3 "),
    "value too wide": BODY.replace(b" 63E ", b" 1063E "),
    "count too big": BODY.replace(b"D05 32B", b"D05 32C"),
    "count too small": BODY.replace(b"D05 32B", b"D05 32A"),
    "bad real": BODY.replace(b"3F800000", b"3F80000"),
    "zero scale": BODY.replace(b"3F800000", b"00000000"),
    "nan scale": BODY.replace(b"3F800000", b"7FC00000"),
    "name too long": BODY.replace(b"7 Daniyal", b"9 Daniyal"),
    "flag 2": BODY.replace(b"Daniyal 0 0 0", b"Daniyal 0 2 0"),
    "no DIST": BODY.replace(b"DIST1", b"RSSI1"),
    "short channel name": BODY.replace(b"DIST1", b"DIST"),
    "counter overflow": BODY.replace(b"3E22", b"13E22"),
    "control byte": BODY.replace(b"63E", b"\x0063E"),
}


@pytest.mark.parametrize("compiled", [True, False], ids=["compiled loops", "numpy passes"])
@pytest.mark.parametrize("name", MALFORMED)
def test_malformed_scans_raise_cola_error(name, compiled, monkeypatch):
    ranges, angles, raw, rssi = arrays()
    monkeypatch.setattr(scan_loops, "COMPILED", scan_loops.COMPILED and compiled)
    with pytest.raises(ColaError):
        scan.parse_scan(MALFORMED[name], ranges, angles, out_raw=raw, out_rssi=rssi)


@pytest.mark.parametrize("compiled", [True, False], ids=["compiled loops", "numpy passes"])
@pytest.mark.parametrize("body", [b"", b" ", b" 1 2", b"1  2", b"1 2 "])
def test_an_empty_value_token_is_a_cola_error_on_either_path(body, compiled, monkeypatch):
    """An empty first token once made numpy's decode raise ValueError (a reduction over nothing)."""
    monkeypatch.setattr(scan_loops, "COMPILED", scan_loops.COMPILED and compiled)
    with pytest.raises(ColaError, match="empty value"):
        cola.TokenReader(body).values(3 if body.strip() else 1, 4, "v")


def _decode_everything(data: bytes) -> None:
    """Every decoder on untrusted bytes: only ColaError may come out."""
    ranges, angles, raw, rssi = arrays()
    for call in (lambda d: scan.parse_scan(d, ranges, angles, out_raw=raw, out_rssi=rssi),
                 commands.parse_reply, cola.unframe, lambda d: cola.TokenReader(d).values(3, 4, "v")):
        try:
            call(data)
        except ColaError:
            pass
    reader = TelegramReader(max_telegram=4096)
    for body in reader.push(data):
        try:
            scan.parse_scan(body, ranges, angles)
        except ColaError:
            pass
    assert reader.buffered <= 4096


_TOKENS = [b"", b" ", b"0", b"1", b"FFFF", b"FFFFFFFF", b"10000", b"G", b"-1", b"+5", b"1 2", b"32B", b"7FC00000",
           b"sFA", b"DIST1", b"RSSI1", b"FFFFFFFFFFFFFFFFF", b"\x02", b"\x03", b"\xff"]
_mutation = st.tuples(st.sampled_from(["flip", "insert", "delete", "truncate", "token", "swap-sep"]),
                      st.integers(0, 1 << 20), st.integers(0, 255), st.sampled_from(_TOKENS))


def _mutate(body: bytes, mutations) -> bytes:
    data = bytearray(body)
    for kind, where, byte, token in mutations:
        at = where % (len(data) + 1)
        if kind == "flip" and data:
            data[at % len(data)] = byte
        elif kind == "insert":
            data[at:at] = bytes([byte])
        elif kind == "delete":
            del data[at:at + 1 + byte % 8]
        elif kind == "truncate":
            del data[at:]
        elif kind == "token":
            tokens = bytes(data).split(b" ")
            tokens[where % len(tokens)] = token
            data = bytearray(b" ".join(tokens))
        elif kind == "swap-sep" and data:
            data[at % len(data)] = 0x20 if data[at % len(data)] != 0x20 else 0x30
    return bytes(data)


FUZZ = settings(max_examples=1000, deadline=2000, suppress_health_check=[HealthCheck.too_slow])
REAL_BODIES = [p.read_bytes()[1:-1] for p in SCANS] + [p.read_bytes()[1:-1] for p in captures("*.bin", "replies")]


@pytest.mark.timeout(60)
@FUZZ
@given(st.one_of(st.binary(max_size=600),
                 st.binary(max_size=400).map(lambda b: b"sSN LMDscandata " + b),
                 st.lists(st.sampled_from(_TOKENS + [b"sSN", b"LMDscandata", b"A2", b"5DC"]), max_size=80)
                 .map(lambda tokens: b" ".join(tokens))))
def test_fuzz_random_bytes_only_raise_cola_error(data):
    _decode_everything(data)


@pytest.mark.timeout(60)
@FUZZ
@given(st.sampled_from(REAL_BODIES), st.lists(_mutation, min_size=1, max_size=4), st.booleans())
def test_fuzz_mutated_real_telegrams_only_raise_cola_error(body, mutations, framed):
    data = _mutate(body, mutations)
    _decode_everything(b"\x02" + data + b"\x03" if framed else data)
