"""TelegramReader: any chunking gives the same telegrams; garbage is counted and skipped; bounded."""

from __future__ import annotations

import random
from pathlib import Path

from hypothesis import given, settings
from hypothesis import strategies as st

from hapticop.devices.sick.stream import TelegramReader

FIXTURES = Path(__file__).resolve().parent / "fixtures" / "sick" / "cola_a"
SCAN = (FIXTURES / "tim561_sRA_LMDscandata_sim00.bin").read_bytes()
REPLY = b"\x02sRA SCdevicestate 1\x03"


def collect(reader: TelegramReader, chunks) -> list[bytes]:
    return [body for chunk in chunks for body in reader.push(chunk)]


def test_a_scan_split_at_every_byte_boundary():
    for cut in range(len(SCAN) + 1):
        reader = TelegramReader()
        assert collect(reader, [SCAN[:cut], SCAN[cut:]]) == [SCAN[1:-1]]
        assert reader.discarded_bytes == 0 and reader.buffered == 0


def test_segments_as_in_the_capture_and_several_frames_per_recv():
    stream = SCAN + REPLY + SCAN
    reader = TelegramReader()
    chunks = [stream[:1448], stream[1448:1448 + 1926], stream[3374:]]  # 1448 + 1926 bytes, as on the wire
    assert collect(reader, chunks) == [SCAN[1:-1], REPLY[1:-1], SCAN[1:-1]]
    assert collect(reader, [REPLY * 3]) == [REPLY[1:-1]] * 3


@settings(max_examples=200, deadline=None)
@given(st.lists(st.integers(1, 5000), min_size=1, max_size=20))
def test_any_chunking_gives_the_same_telegrams(sizes):
    stream = (SCAN + REPLY) * 3
    chunks, at = [], 0
    for size in sizes:
        chunks.append(stream[at:at + size])
        at += size
    chunks.append(stream[at:])
    assert collect(TelegramReader(), chunks) == [SCAN[1:-1], REPLY[1:-1]] * 3


def test_garbage_between_frames_is_counted_and_skipped():
    reader = TelegramReader()
    bodies = collect(reader, [b"hello", REPLY, b"\xff\x00junk\x03", REPLY])
    assert bodies == [REPLY[1:-1]] * 2
    assert reader.discarded_bytes == len(b"hello") + len(b"\xff\x00junk\x03")
    assert reader.broken_frames == 0


def test_a_new_stx_inside_a_frame_resynchronises():
    reader = TelegramReader()
    broken = b"\x02sSN LMDscandata 1 1 107"  # cut short: the device (or the network) lost the rest
    assert collect(reader, [broken, REPLY]) == [REPLY[1:-1]]
    assert reader.broken_frames == 1 and reader.discarded_bytes == len(broken)


def test_an_endless_frame_is_dropped_and_the_buffer_stays_bounded():
    reader = TelegramReader(max_telegram=1000)
    rng = random.Random(1)
    junk = bytes(rng.choice(b"0123456789ABCDEF ") for _ in range(10_000))
    bodies = []
    for i in range(0, len(junk), 300):
        bodies += reader.push((b"\x02" if i == 0 else b"") + junk[i:i + 300])
        assert reader.buffered <= 1000
    assert bodies == [] and reader.overflows == 1
    assert collect(reader, [b"tail of the long frame\x03", REPLY]) == [REPLY[1:-1]]
    assert reader.discarded_bytes == 1 + len(junk) + len(b"tail of the long frame\x03")


def test_a_frame_of_exactly_the_limit_passes_and_an_empty_frame_is_a_telegram():
    reader = TelegramReader(max_telegram=len(SCAN))
    assert collect(reader, [SCAN, b"\x02\x03"]) == [SCAN[1:-1], b""]
    small = TelegramReader(max_telegram=len(SCAN) - 1)
    assert collect(small, [SCAN, REPLY]) == [REPLY[1:-1]] and small.overflows == 1


def test_reset_drops_a_partial_frame():
    reader = TelegramReader()
    assert collect(reader, [SCAN[:100]]) == []
    reader.reset()
    assert reader.discarded_bytes == 100 and reader.buffered == 0
    assert collect(reader, [SCAN[100:], REPLY]) == [REPLY[1:-1]]
