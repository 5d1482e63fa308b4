"""The Falcon frame codec against libnifalcon's own encoder/decoder output, and the reader's resync."""

from __future__ import annotations

import json

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from hapticop.devices.falcon.codec import (
    FRAME_SIZE,
    Button,
    Command,
    Flag,
    FrameCodec,
    FrameError,
    FrameReader,
    Status,
    is_valid_frame,
    new_frame,
)
from hapticop.testing import grown_bytes

from .conftest import FIXTURES, SHARED_TESTDATA

# The full reference data when ../shared is present, else the small copies the project ships.
DATA = SHARED_TESTDATA / "falcon" if (SHARED_TESTDATA / "falcon").is_dir() else FIXTURES / "falcon"
needs_data = pytest.mark.skipif(not DATA.is_dir(), reason="no Falcon reference data")


def _load(name: str) -> dict:
    return json.loads((DATA / name).read_text())


def _packets() -> dict:
    return (_load("packet_reference.json") if DATA.is_dir()
            else {"encode_host_to_falcon": [], "decode_falcon_to_host": []})


def _recorded() -> list[dict]:
    return _load("recorded_packets_translate_packet_py.json")["packets"] if DATA.is_dir() else []


def _status_frame(encoders, homed=0, buttons=0) -> bytes:
    out = new_frame()
    FrameCodec().encode_status(encoders, homed, buttons, out)
    return out.tobytes()


# ---------------------------------------------------------------- libnifalcon reference
@needs_data
@pytest.mark.parametrize("case", _packets()["encode_host_to_falcon"], ids=lambda c: c["ascii"])
def test_encoding_reproduces_libnifalcon_bytes(case):
    flags = case["led_bits"] | (Flag.HOMING if case["homing"] else 0)
    out = new_frame()
    FrameCodec().encode_command(case["forces"], flags, out, limit=None)  # libnifalcon wraps
    assert out.tobytes().hex() == case["bytes_hex"]


@needs_data
@pytest.mark.parametrize("case", _packets()["decode_falcon_to_host"], ids=lambda c: c["bytes_hex"][2:28])
def test_decoding_matches_libnifalcon(case):
    codec, status = FrameCodec(), Status()
    frame = bytes.fromhex(case["bytes_hex"])
    if not case["valid"]:
        assert not codec.is_valid(frame)
        with pytest.raises(FrameError):
            codec.decode_status(frame, status)
        return
    codec.decode_status(frame, status)
    assert status.encoders.tolist() == case["encoders"]
    assert status.homed_mask == case["homing_bits"]
    assert status.buttons == case["grip_bits"]
    assert status.all_homed == (case["homing_bits"] == 7)


@needs_data
@pytest.mark.parametrize("packet", _recorded(), ids=lambda p: p["bytes_hex"][2:28])
def test_recorded_packets_decode_to_recorded_values_and_reencode(packet):
    codec = FrameCodec()
    frame = bytes.fromhex(packet["bytes_hex"])
    status = codec.decode_status(frame, Status())
    assert status.encoders.tolist() == packet["decoded_values_libnifalcon"]
    assert status.buttons == packet["byte13_minus_0x41"] and status.spare == packet["byte14_minus_0x41"]
    # They were captured host->Falcon: motor values plus the blue LED bit.
    command = codec.decode_command(frame, Command())
    assert command.motor.tolist() == packet["decoded_values_libnifalcon"]
    assert command.leds == Flag.LED_BLUE and not command.homing
    out = new_frame()
    codec.encode_command(command.motor, command.flags, out)  # within +-4095: no saturation
    assert out.tobytes() == frame
    if "annotation_values" in packet:  # one annotation in the source is a copy/paste slip
        assert ((packet["annotation_values"] == packet["decoded_values_libnifalcon"])
                == packet["annotation_matches_decode"])


def test_worked_example_is_negative():
    """`<JFKP...>` is -1447; libnifalcon's header comment says +1447, its code does not."""
    status = FrameCodec().decode_status(b"<JFKPAAAAAAAAAA>", Status())
    assert status.encoders.tolist() == [-1447, 0, 0]


def test_status_byte_may_exceed_P():
    status = FrameCodec().decode_status(b"<AAAAAAAAAAAA\xc0A>", Status())
    assert status.all_homed and status.buttons == Button.PLUS | Button.FORWARD | Button.CENTRE | Button.MINUS
    assert not is_valid_frame(b"<AAAAAAAAAAAA\xc0A>", "command")  # commands carry only 4 flag bits
    assert not is_valid_frame(b"<AAAAAAAAAAAA\xc1A>", "status")  # bit 7 of the status value


# ---------------------------------------------------------------- encoding rules
def test_commands_saturate_at_4095_by_default():
    codec, out = FrameCodec(), new_frame()
    codec.encode_command([40000, -40000, 65535], Flag.HOMING | Flag.LED_RED, out)
    command = codec.decode_command(out, Command())
    assert command.motor.tolist() == [4095, -4095, 4095]
    assert command.homing and command.leds == Flag.LED_RED
    codec.encode_command(np.array([12.9, -12.9, 0.4]), 0, out)  # floats truncate toward zero
    assert codec.decode_command(out, Command()).motor.tolist() == [12, -12, 0]


def test_encode_into_bytearray_and_array_alike():
    codec, a, b = FrameCodec(), new_frame(), bytearray(16)
    codec.encode_command([100, 200, 300], 11, a)
    codec.encode_command([100, 200, 300], 11, b)
    assert a.tobytes() == bytes(b) == bytes.fromhex("3c45474141494d41414d4342414c413e")


@settings(max_examples=300, deadline=None)
@given(st.lists(st.integers(-32768, 32767), min_size=3, max_size=3), st.integers(0, 7), st.integers(0, 15))
def test_status_round_trip(encoders, homed, buttons):
    frame = _status_frame(encoders, homed, buttons)
    assert is_valid_frame(frame, "status")
    status = FrameCodec().decode_status(frame, Status())
    assert status.encoders.tolist() == encoders and status.homed_mask == homed and status.buttons == buttons


@settings(max_examples=300, deadline=None)
@given(st.lists(st.integers(-4095, 4095), min_size=3, max_size=3), st.integers(0, 15))
def test_command_round_trip(motor, flags):
    codec, out = FrameCodec(), new_frame()
    codec.encode_command(motor, flags, out)
    command = codec.decode_command(out, Command())
    assert command.motor.tolist() == motor and command.flags == flags


@pytest.mark.parametrize("index, value",
                         [(0, 0x3D), (15, 0x3C), (1, 0x40), (5, 0x51), (12, 0x00), (14, 0x51), (13, 0xFF)])
def test_each_byte_is_range_checked(index, value):
    frame = bytearray(b"<AAAAAAAAAAAAAA>")
    frame[index] = value
    assert not is_valid_frame(bytes(frame), "status") and not is_valid_frame(bytes(frame), "command")


@settings(max_examples=300, deadline=None)
@given(st.binary(min_size=0, max_size=40))
def test_decoders_raise_only_frame_error(garbage):
    codec = FrameCodec()
    for decode, out in ((codec.decode_status, Status()), (codec.decode_command, Command())):
        try:
            decode(garbage, out)
        except FrameError:
            pass


# ---------------------------------------------------------------- reader
def _stream(n: int, seed: int = 0) -> list[bytes]:
    rng = np.random.default_rng(seed)
    return [_status_frame(rng.integers(-2000, 2000, 3), int(rng.integers(0, 8)), int(rng.integers(0, 16)))
            for _ in range(n)]


def _read_all(reader: FrameReader, data: bytes, cuts: list[int]) -> list[bytes]:
    got, out, last = [], new_frame(), 0
    for cut in sorted(set(cuts)) + [len(data)]:
        reader.feed(data[last:cut])
        last = cut
        while reader.pop(out):
            got.append(out.tobytes())
    return got


@settings(max_examples=100, deadline=None)
@given(st.lists(st.integers(0, 50 * 16), max_size=60))
def test_reader_reassembles_any_chunking(cuts):
    frames = _stream(50)
    reader = FrameReader()
    assert _read_all(reader, b"".join(frames), cuts) == frames
    assert reader.discarded == 0 and reader.rejected == 0 and reader.frames == 50 and reader.buffered == 0


@settings(max_examples=100, deadline=None)
@given(st.integers(0, 19), st.integers(0, 15), st.lists(st.integers(0, 20 * 16), max_size=10))
def test_reader_resyncs_after_a_lost_byte(k, i, cuts):
    frames = _stream(20, seed=1)
    data = b"".join(frames)
    at = 16 * k + i
    reader = FrameReader()
    got = _read_all(reader, data[:at] + data[at + 1:], cuts)
    assert got == frames[:k] + frames[k + 1:]  # exactly the damaged frame is lost
    assert reader.discarded + reader.buffered == 15  # a damaged last frame still waits


@settings(max_examples=100, deadline=None)
@given(st.integers(0, 19), st.integers(1, 15), st.integers(0, 255))
def test_reader_resyncs_after_an_extra_byte(k, i, extra):
    frames = _stream(20, seed=2)
    data = b"".join(frames)
    at = 16 * k + i
    reader = FrameReader()
    damaged = data[:at] + bytes([extra]) + data[at:]
    got = _read_all(reader, damaged, [])
    if frames[k] in damaged:  # e.g. a '<' right after the start: the frame is still whole, one byte later
        assert got == frames and reader.discarded == 1
    else:
        assert got == frames[:k] + frames[k + 1:]  # exactly the damaged frame is lost
        assert reader.discarded == 17


def test_reader_skips_garbage_between_frames_and_counts_it():
    frames = _stream(3, seed=3)
    garbage = b"\x00\x01>>AAAA\xff" * 3
    reader = FrameReader()
    got = _read_all(reader, frames[0] + garbage + frames[1] + b"<<<" + frames[2], [5, 40])
    assert got == frames
    assert reader.discarded == len(garbage) + 3 and reader.rejected == 3


@settings(max_examples=200, deadline=None)
@given(st.binary(max_size=200), st.lists(st.integers(0, 400), max_size=8))
def test_reader_never_raises_and_recovers_after_any_garbage(garbage, cuts):
    frames = _stream(4, seed=4)
    reader = FrameReader()
    data = garbage + b"".join(frames)
    got = _read_all(reader, data, cuts)
    assert got[len(got) - 4:] == frames  # a valid frame never overlaps garbage, so all survive
    assert 16 * reader.frames + reader.discarded + reader.buffered == len(data)


def test_reader_bounded_by_capacity():
    reader = FrameReader(capacity=64)
    reader.feed(bytes(1000))  # more than capacity in one read
    reader.feed(b"<AAAA" * 30)  # partial frames piling up
    frame = _status_frame([1, 2, 3])
    reader.feed(frame)
    out = new_frame()
    assert reader.pop(out) and out.tobytes() == frame
    assert not reader.pop(out)
    assert reader.discarded == 1000 + 150 and reader.buffered == 0


def test_reader_holds_partial_frames_and_iterates():
    frames = _stream(2, seed=5)
    reader = FrameReader()
    assert list(reader.frames_in(frames[0] + frames[1][:9])) == [frames[0]]
    assert reader.buffered == 9
    assert list(reader.frames_in(np.frombuffer(frames[1][9:], dtype=np.uint8))) == [frames[1]]
    reader.feed(bytearray(frames[0][:3]))
    reader.feed(memoryview(frames[0])[3:])
    out = bytearray(16)
    assert reader.pop(out) and bytes(out) == frames[0]


def test_command_reader():
    out = new_frame()
    FrameCodec().encode_command([1, -2, 3], Flag.HOMING, out)
    reader = FrameReader("command")
    assert list(reader.frames_in(b"\x00" + out.tobytes())) == [out.tobytes()]
    assert list(reader.frames_in(_status_frame([0, 0, 0], 7))) == []  # 0xB1 is no command byte
    with pytest.raises(ValueError):
        FrameReader("both")  # type: ignore[arg-type]


def test_cycle_path_allocates_nothing_that_stays():
    codec, reader, status, cmd, frame = FrameCodec(), FrameReader(), Status(), new_frame(), new_frame()
    data = b"".join(_stream(64, seed=6))
    motor = np.array([100, -200, 300], dtype=np.int64)

    def cycles(n):
        for i in range(n):
            j = 16 * (i % 64)
            reader.feed(data[j:j + 7])
            reader.feed(data[j + 7:j + 16])
            while reader.pop(frame):
                codec.decode_status(frame, status)
            codec.encode_command(motor, 3, cmd)

    cycles(500)
    grown = grown_bytes(lambda: cycles(5000))
    assert grown < 2048
    assert reader.frames == 5500 and reader.discarded == 0
    assert FRAME_SIZE == 16


# ---------------------------------------------------------------- the rules, stated directly
def _rules_say_valid(frame: bytes, kind: str) -> bool:
    """§4.3 byte by byte: '<', twelve 'A'..'P', byte 13 ('A'..'P', status up to 'A' + 0x7F), 'A'..'P', '>'."""
    if len(frame) != FRAME_SIZE or frame[0] != 0x3C or frame[15] != 0x3E:
        return False
    top13 = 0x41 + (0x7F if kind == "status" else 0xF)
    return all(0x41 <= b <= 0x50 for b in frame[1:13] + frame[14:15]) and 0x41 <= frame[13] <= top13


def _direct_frame(values, b13: int) -> bytes:
    nibbles = [0x41 + ((v & 0xFFFF) >> (4 * k) & 0xF) for v in values for k in range(4)]
    return bytes([0x3C, *nibbles, 0x41 + b13, 0x41, 0x3E])


@settings(max_examples=500, deadline=None)
@given(st.lists(st.sampled_from(b"<>@ABHOPQ\x00\x50\x51\xb1\xc0\xc1\xff"), min_size=14, max_size=14),
       st.booleans(), st.sampled_from([15, 16, 17]))
def test_validity_is_exactly_the_byte_rules(middle, framed, length):
    frame = (b"<" + bytes(middle) + b">" if framed else bytes(middle) + b"AA")[:length]
    codec = FrameCodec()
    for kind in ("status", "command"):
        assert codec.is_valid(frame, kind) == _rules_say_valid(frame, kind)
        assert codec.is_valid(np.frombuffer(frame, dtype=np.uint8), kind) == _rules_say_valid(frame, kind)


@settings(max_examples=300, deadline=None)
@given(st.lists(st.integers(-70000, 70000), min_size=3, max_size=3), st.integers(0, 7), st.integers(0, 15))
def test_encoding_is_the_nibble_formula(values, homed, buttons):
    codec, out = FrameCodec(), bytearray(16)
    codec.encode_status(values, homed, buttons, out)
    assert bytes(out) == _direct_frame(values, buttons | homed << 4)
    codec.encode_command(values, buttons, out)
    assert bytes(out) == _direct_frame([min(max(v, -4095), 4095) for v in values], buttons)


def test_a_frame_must_be_a_16_byte_buffer():
    codec = FrameCodec()
    for bad in ([0x3C] + [0x41] * 14 + [0x3E], np.frombuffer(b"<AAAAAAAAAAAAAA>", np.uint8).astype(np.int64),
                "<AAAAAAAAAAAAAA>", None, b"<AAAAAAAAAAAAAA>A"):
        assert not codec.is_valid(bad)
        with pytest.raises(FrameError):
            codec.decode_status(bad, Status())
