"""Fuzzing the wire parsers, 10,000 cases each: only the parser's own error, never a hang.

Every byte a LIDAR or a Falcon sends is untrusted: the CoLa A decoders may raise only
`ColaError`, the Falcon frame decoders only `FrameError`, and the stream splitters
(`TelegramReader`, `FrameReader`) nothing at all, while accounting for every byte.

Each test draws one byte string (hypothesis's cheapest strategy: 10,000 composite
strategies would take a minute) and reads it as a recipe: its first byte picks raw bytes,
bytes from the protocol's own alphabet, or a real telegram or frame with mutations, so
the search reaches past the first check and still shrinks. Examples are derandomised
(tests/conftest.py); the pytest timeout is the hang detector.
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from hapticop.devices.falcon.codec import (
    FRAME_SIZE,
    Command,
    FrameCodec,
    FrameError,
    FrameReader,
    Status,
    is_valid_frame,
    new_frame,
)
from hapticop.devices.sick import cola, commands, scan
from hapticop.devices.sick.cola import ColaError
from hapticop.devices.sick.commands import Reply
from hapticop.devices.sick.probe import parse_identity
from hapticop.devices.sick.stream import TelegramReader
from tests.test_sick_cola import _TOKENS, REAL_BODIES, _mutate

FUZZ = settings(max_examples=10_000, deadline=None, suppress_health_check=list(HealthCheck))
_MUTATIONS = ("flip", "insert", "delete", "truncate", "token", "swap-sep")


def _pick(seq, byte: int):
    return seq[byte % len(seq)]


# ---------------------------------------------------------------- CoLa A
_COLA_TOKENS = [b"sRA", b"sSN", b"sAN", b"sFA", b"sWA", b"sEA", b"LMDscandata", b"0", b"1", b"2", b"6", b"E", b"FF",
                b"FFFF", b"FFFFFFFF", b"1FFFFFFFF", b"-1", b"+7", b"3F800000", b"7FC00000", b"DIST1", b"RSSI1",
                b"TiM561", b"V2.51-21.08.15", b"", b" ", b"\x02", b"\x03", b"\xff", b"G"]


def _cola_input(recipe: bytes) -> bytes:
    """Raw bytes, a token soup, or a real telegram body with up to 4 mutations; maybe framed."""
    if not recipe:
        return b""
    mode, rest = recipe[0], recipe[1:]
    if mode % 3 == 0:
        data = rest
    elif mode % 3 == 1:
        data = b" ".join(_pick(_COLA_TOKENS, b) for b in rest)
    else:
        body = _pick(REAL_BODIES, rest[0]) if rest else REAL_BODIES[0]
        steps = [(_pick(_MUTATIONS, rest[i]), int.from_bytes(rest[i + 1:i + 4], "little"), rest[i + 4],
                  _pick(_TOKENS, rest[i + 5])) for i in range(1, min(len(rest), 25) - 5, 6)]
        data = _mutate(body, steps or [("flip", len(rest), 0x20, b"")])
    return b"\x02" + data + b"\x03" if mode & 0x80 else data


_SCAN_OUT = tuple(np.zeros(scan.TIM561_POINTS, dtype=t) for t in (np.float64, np.float64, np.uint32, np.uint32))


def _cola_decoders(data: bytes) -> None:
    ranges, angles, raw, rssi = _SCAN_OUT
    reader = cola.TokenReader(data)
    calls = (
        lambda: scan.parse_scan(data, ranges, angles, out_raw=raw, out_rssi=rssi),
        lambda: scan.parse_scan(data, None),
        lambda: commands.parse_reply(data, "sRN LMDscandata"),
        lambda: cola.unframe(data),
        lambda: cola.decode_uint(data, 16),
        lambda: cola.decode_int32(data),
        lambda: cola.decode_real(data),
        lambda: parse_identity(Reply(b"sRA", b"0", data)),
        lambda: (reader.uint(32, "a"), reader.int32("b"), reader.real("c"), reader.flag("d"), reader.string("e"),
                 reader.values(3, 4, "f"), reader.expect_end("g")),
    )
    for call in calls:
        try:
            call()
        except ColaError:
            pass


@pytest.mark.timeout(120)
@FUZZ
@given(st.binary(max_size=160))
def test_fuzz_cola_a_decoders_raise_only_cola_error(recipe):
    _cola_decoders(_cola_input(recipe))


_STREAM_PIECES = [b"\x02", b"\x03", b"sRA 0 ", b"x" * 40, b"\xff", b"sSN LMDscandata 1 ", b"\x02sAN Run 1\x03"]


@pytest.mark.timeout(120)
@FUZZ
@given(st.binary(max_size=200))
def test_fuzz_cola_a_stream_splits_anything_and_accounts_for_every_byte(recipe):
    head, rest = recipe[:4].ljust(4, b"\0"), recipe[4:]
    max_telegram = 2 + head[0] * 4  # 2..1022: small limits exercise the overflow path
    if head[1] % 3 == 0:
        data = rest
    elif head[1] % 3 == 1:
        data = b"".join(_pick(_STREAM_PIECES, b) for b in rest)
    else:  # real telegrams, back to back, with the recipe's bytes spliced in between
        data = b"".join(b"\x02" + _pick(REAL_BODIES, b) + b"\x03" + rest[i:i + 3] for i, b in enumerate(rest[:4]))
    cuts = sorted({min(len(data), b * 13) for b in head[2:]} | {len(data)})
    reader, bodies, last = TelegramReader(max_telegram=max_telegram), [], 0
    for cut in cuts:
        bodies += list(reader.push(data[last:cut]))
        last = cut
    assert all(b"\x02" not in b and b"\x03" not in b for b in bodies)
    assert reader.buffered <= max_telegram
    assert sum(len(b) + 2 for b in bodies) + reader.discarded_bytes + reader.buffered == len(data)


# ---------------------------------------------------------------- Falcon frames
_FRAME_ALPHABET = b"<>ABCDEFGHIJKLMNOPQ@\x00\xb1\xff"
_CODEC, _STATUS, _COMMAND, _OUT = FrameCodec(), Status(), Command(), new_frame()


def _frame_input(recipe: bytes) -> bytes:
    """Raw bytes, bytes of the frame alphabet, or a valid status frame with one byte damaged."""
    if not recipe:
        return b""
    mode, rest = recipe[0], recipe[1:]
    if mode % 3 == 0:
        return rest
    if mode % 3 == 1:
        return bytes(_pick(_FRAME_ALPHABET, b) for b in rest)
    raw = rest.ljust(10, b"\0")
    values = np.frombuffer(raw[:6], dtype="<i2").astype(np.int64)
    frame = bytearray(_CODEC.encode_status(values, raw[6] >> 4, raw[6] & 0xF, _OUT).tobytes())
    frame[raw[7] % FRAME_SIZE] ^= raw[8] if mode & 0x80 else 0  # half of them stay valid
    return bytes(frame)


@pytest.mark.timeout(120)
@FUZZ
@given(st.binary(max_size=24))
def test_fuzz_falcon_frame_decoders_raise_only_frame_error_and_round_trip(recipe):
    data = _frame_input(recipe)
    try:
        _CODEC.decode_status(data, _STATUS)
    except FrameError:
        assert not is_valid_frame(data, "status")
    else:
        if data[14] == 0x41:  # the unknown spare byte is always 'A' when we encode
            again = _CODEC.encode_status(_STATUS.encoders, _STATUS.homed_mask, _STATUS.buttons, _OUT).tobytes()
            assert again == data
    try:
        _CODEC.decode_command(data, _COMMAND)
    except FrameError:
        assert not is_valid_frame(data, "command")
    else:
        assert -32768 <= _COMMAND.motor.min() and _COMMAND.motor.max() <= 32767 and 0 <= _COMMAND.flags <= 15


@pytest.mark.timeout(120)
@FUZZ
@given(st.binary(max_size=240))
def test_fuzz_falcon_frame_reader_never_raises_and_accounts_for_every_byte(recipe):
    head, rest = recipe[:4].ljust(4, b"\0"), recipe[4:]
    kind = "status" if head[0] & 1 else "command"
    capacity = (16, 40, 1024)[head[0] % 3]
    data = b"".join(_frame_input(rest[i:i + 12]) for i in range(0, len(rest), 12))
    cuts = sorted({min(len(data), b * 3) for b in head[1:]} | {len(data)})
    reader, out, delivered, last = FrameReader(kind, capacity), new_frame(), 0, 0
    for cut in cuts:
        reader.feed(data[last:cut])
        last = cut
        while reader.pop(out):
            assert is_valid_frame(out, kind)
            delivered += 1
    assert delivered == reader.frames
    assert FRAME_SIZE * reader.frames + reader.discarded + reader.buffered == len(data)
    assert reader.buffered <= capacity
