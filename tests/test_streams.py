"""Stream buffers: round trips, queue overflow policies, no torn reads under contention
(threads and processes over shared memory) and no allocation on the cycle path."""

from __future__ import annotations

import multiprocessing
import sys
import threading
from multiprocessing.shared_memory import SharedMemory

import numpy as np
import pytest

from hapticop.blocks.interface import Port
from hapticop.runtime.streams import (
    MAX_RETRIES,
    SAMPLE_ALIGN,
    LatestSlot,
    SpscQueue,
    latest_nbytes,
    queue_nbytes,
)
from hapticop.testing import allocation_stats

PORTS = {
    "scalar": Port("float64", ()),
    "vec3": Port("float64", (3,), "m"),
    "scan": Port("float32", (811,), "m"),
    "bytes": Port("uint8", (4, 36)),
}
SCAN = PORTS["scan"]
CONTENTION_SAMPLES = 200_000
QUEUE_SAMPLES = 100_000


def buffer_for(nbytes: int) -> np.ndarray:
    """A zeroed, cache-line-aligned byte buffer, as the runtime hands out."""
    backing = np.zeros(nbytes + SAMPLE_ALIGN, dtype=np.uint8)
    skip = -backing.ctypes.data % SAMPLE_ALIGN
    return backing[skip : skip + nbytes]


def sample(port: Port, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return (rng.random(port.shape) * 200).astype(port.dtype)


def new_out(port: Port) -> tuple[np.ndarray, np.ndarray]:
    return np.zeros(port.shape, dtype=port.dtype), np.zeros(2, dtype=np.int64)


# ---------------------------------------------------------------- sizes and handles


@pytest.mark.parametrize("port", PORTS.values(), ids=PORTS.keys())
def test_sizes_are_whole_cache_lines(port: Port) -> None:
    size = latest_nbytes(port)
    assert size % SAMPLE_ALIGN == 0 and size >= port.nbytes + 24
    assert queue_nbytes(port, 5) % SAMPLE_ALIGN == 0
    assert queue_nbytes(port, 5) >= 5 * size + 2 * SAMPLE_ALIGN


def test_bad_buffers_are_refused() -> None:
    with pytest.raises(ValueError, match="needs"):
        LatestSlot(buffer_for(latest_nbytes(SCAN) - 64), SCAN)
    with pytest.raises(ValueError, match="aligned"):
        LatestSlot(buffer_for(latest_nbytes(SCAN) + 64)[4:], SCAN)
    with pytest.raises(ValueError, match="read-only"):
        LatestSlot(bytes(latest_nbytes(SCAN)), SCAN)
    with pytest.raises(ValueError, match="overflow"):
        SpscQueue(buffer_for(queue_nbytes(SCAN, 2)), SCAN, 2, "block")  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="capacity"):
        queue_nbytes(SCAN, 0)


# ---------------------------------------------------------------- latest slot


@pytest.mark.parametrize("synchronised", [True, False], ids=["seqlock", "plain"])
@pytest.mark.parametrize("port", PORTS.values(), ids=PORTS.keys())
def test_latest_round_trip(port: Port, synchronised: bool) -> None:
    slot = LatestSlot(buffer_for(latest_nbytes(port)), port, synchronised)
    out, meta = new_out(port)
    assert not slot.read_into(out, meta)
    assert not out.any() and not meta.any()

    for n in range(1, 4):
        value = sample(port, n)
        slot.write(value, stamp_ns=1_000 * n)
        assert slot.read_into(out, meta)
        np.testing.assert_array_equal(out, value)
        assert meta.tolist() == [n, 1_000 * n]
    assert slot.count == 3
    assert "count=3" in repr(slot)


def test_handles_over_the_same_bytes_share_the_stream() -> None:
    buffer = buffer_for(latest_nbytes(SCAN))
    writer, reader = LatestSlot(buffer, SCAN), LatestSlot(memoryview(buffer), SCAN)
    writer.write(sample(SCAN, 1), 5)
    out, meta = new_out(SCAN)
    assert reader.read_into(out, meta) and meta.tolist() == [1, 5]
    np.testing.assert_array_equal(out, sample(SCAN, 1))


def test_a_stuck_writer_makes_reads_fail_not_hang() -> None:
    buffer = buffer_for(latest_nbytes(SCAN))
    slot = LatestSlot(buffer, SCAN)
    slot.write(sample(SCAN, 1), 5)
    buffer.view(np.uint64)[0] += 1  # the writer died mid-write: the sequence stays odd
    out, meta = new_out(SCAN)
    assert not slot.read_into(out, meta)
    assert not out.any() and not meta.any()  # the caller's arrays are untouched
    assert MAX_RETRIES > 0


def test_a_failed_write_leaves_the_slot_readable() -> None:
    slot = LatestSlot(buffer_for(latest_nbytes(SCAN)), SCAN)
    slot.write(sample(SCAN, 1), 5)
    with pytest.raises(ValueError):
        slot.write(np.zeros(3, dtype=np.float32), 6)  # wrong shape
    out, meta = new_out(SCAN)
    assert slot.read_into(out, meta) and meta.tolist() == [1, 5]
    np.testing.assert_array_equal(out, sample(SCAN, 1))


def test_close_releases_shared_memory() -> None:
    shm = SharedMemory(create=True, size=latest_nbytes(SCAN) + queue_nbytes(SCAN, 3))
    try:
        slot = LatestSlot(shm.buf[: latest_nbytes(SCAN)], SCAN)
        queue = SpscQueue(shm.buf[latest_nbytes(SCAN) :], SCAN, 3)
        slot.close()
        queue.close()
        shm.close()  # raises BufferError while a view is still exported
    finally:
        shm.unlink()


# ---------------------------------------------------------------- queue


def make_queue(
    capacity: int, overflow: str = "drop_oldest", port: Port = PORTS["vec3"]
) -> SpscQueue:
    buffer = buffer_for(queue_nbytes(port, capacity))
    return SpscQueue(buffer, port, capacity, overflow)  # type: ignore[arg-type]


def drain(queue: SpscQueue) -> list[tuple[float, int, int]]:
    out, meta = new_out(queue.port)
    got = []
    while queue.pop_into(out, meta):
        got.append((float(out[0]), int(meta[0]), int(meta[1])))
    return got


def test_queue_is_fifo() -> None:
    queue = make_queue(4)
    out, meta = new_out(queue.port)
    assert not queue.pop_into(out, meta) and queue.pending() == 0
    for i in range(1, 4):
        assert queue.push(np.full(3, i), 10 * i)
        assert queue.pending() == i
    assert drain(queue) == [(1.0, 1, 10), (2.0, 2, 20), (3.0, 3, 30)]
    assert queue.pending() == 0 and queue.dropped == 0
    queue.push(np.full(3, 4), 40)  # the ring wraps around
    assert drain(queue) == [(4.0, 4, 40)]


def test_queue_drop_oldest_keeps_the_newest() -> None:
    queue = make_queue(4, "drop_oldest")
    for i in range(1, 11):
        assert queue.push(np.full(3, i), 10 * i)
    assert queue.pending() == 4
    assert [v for v, _, _ in drain(queue)] == [7.0, 8.0, 9.0, 10.0]
    assert queue.dropped == 6 and queue.pending() == 0
    assert "dropped=6" in repr(queue)


def test_queue_drop_newest_keeps_the_oldest() -> None:
    queue = make_queue(4, "drop_newest")
    accepted = [queue.push(np.full(3, i), 10 * i) for i in range(1, 11)]
    assert accepted == [True] * 4 + [False] * 6
    assert queue.dropped == 6 and queue.pending() == 4
    assert drain(queue) == [(1.0, 1, 10), (2.0, 2, 20), (3.0, 3, 30), (4.0, 4, 40)]
    assert queue.push(np.full(3, 11), 110)  # room again once consumed
    assert drain(queue) == [(11.0, 5, 110)]


def test_queue_of_one() -> None:
    queue = make_queue(1)
    queue.push(np.full(3, 1), 1)
    queue.push(np.full(3, 2), 2)
    assert drain(queue) == [(2.0, 2, 2)] and queue.dropped == 1


# ---------------------------------------------------------------- contention
# Writers fill every element with the sample number, so a torn read shows as unequal
# elements, or elements that disagree with the sample number in `meta`.


def write_numbered(slot: LatestSlot, n: int) -> None:
    value = np.empty(SCAN.shape, dtype=np.float32)
    for i in range(1, n + 1):
        value.fill(i)
        slot.write(value, 10 * i)


def writer_process(name: str, n: int) -> None:
    shm = SharedMemory(name=name)
    try:
        slot = LatestSlot(shm.buf[: latest_nbytes(SCAN)], SCAN)
        write_numbered(slot, n)
        slot.close()
    finally:
        shm.close()


def producer_process(name: str, n: int, capacity: int, overflow: str) -> None:
    shm = SharedMemory(name=name)
    try:
        buffer = shm.buf[: queue_nbytes(SCAN, capacity)]
        queue = SpscQueue(buffer, SCAN, capacity, overflow)  # type: ignore[arg-type]
        del buffer  # the queue holds its own views; shm.close() needs this one gone
        value = np.empty(SCAN.shape, dtype=np.float32)
        for i in range(1, n + 1):
            value.fill(i)
            queue.push(value, 10 * i)
        queue.close()
    finally:
        shm.close()


def read_while(slot: LatestSlot, writer_alive) -> tuple[int, int]:
    """Read until the writer is gone; check every read. Returns (last number, reads)."""
    out, meta = new_out(SCAN)
    last = reads = polls = 0
    while True:
        polls += 1
        finished = polls % 1024 == 0 and not writer_alive()
        if slot.read_into(out, meta):
            n = int(meta[0])
            assert n >= last, "sequence went backwards"
            assert out[0] == n and (out == out[0]).all(), f"torn read at sample {n}"
            assert meta[1] == 10 * n
            last, reads = n, reads + 1
        if finished:  # this read began after the writer ended: it saw the last sample
            return last, reads


def test_no_torn_reads_across_processes() -> None:
    shm = SharedMemory(create=True, size=latest_nbytes(SCAN))
    ctx = multiprocessing.get_context("spawn")
    writer = ctx.Process(target=writer_process, args=(shm.name, CONTENTION_SAMPLES))
    slot = None
    try:
        slot = LatestSlot(shm.buf[: latest_nbytes(SCAN)], SCAN)
        writer.start()
        last, reads = read_while(slot, writer.is_alive)
        writer.join()
        assert writer.exitcode == 0
        assert last == CONTENTION_SAMPLES and reads > 0
    finally:
        if writer.is_alive():
            writer.terminate()
        if writer.pid is not None:
            writer.join()
        if slot is not None:
            slot.close()
        shm.close()
        shm.unlink()


def test_no_torn_reads_across_threads() -> None:
    """One handle shared by the writer and two readers, as when they live in one process."""
    n = CONTENTION_SAMPLES // 4
    slot = LatestSlot(buffer_for(latest_nbytes(SCAN)), SCAN)
    writer = threading.Thread(target=write_numbered, args=(slot, n))
    results: list[tuple[int, int] | BaseException] = []

    def second_reader() -> None:
        try:
            results.append(read_while(slot, writer.is_alive))
        except BaseException as error:  # noqa: BLE001 - handed to the test thread
            results.append(error)

    reader = threading.Thread(target=second_reader)
    interval = sys.getswitchinterval()
    sys.setswitchinterval(1e-5)  # hand the GIL over often, mid-write included
    try:
        writer.start()
        reader.start()
        results.append(read_while(slot, writer.is_alive))
    finally:
        writer.join()
        reader.join()
        sys.setswitchinterval(interval)
    for result in results:
        if isinstance(result, BaseException):
            raise result
        last, reads = result
        assert last == n and reads > 0
    assert len(results) == 2


@pytest.mark.parametrize("overflow", ["drop_oldest", "drop_newest"])
def test_queue_across_processes_loses_nothing_unaccounted(overflow: str) -> None:
    capacity = 8
    size = queue_nbytes(SCAN, capacity)
    shm = SharedMemory(create=True, size=size)
    ctx = multiprocessing.get_context("spawn")
    args = (shm.name, QUEUE_SAMPLES, capacity, overflow)
    producer = ctx.Process(target=producer_process, args=args)
    queue = None
    try:
        queue = SpscQueue(shm.buf[:size], SCAN, capacity, overflow)  # type: ignore[arg-type]
        producer.start()
        out, meta = new_out(SCAN)
        values, numbers, polls = [], [], 0
        while True:
            polls += 1
            finished = polls % 1024 == 0 and not producer.is_alive()
            while queue.pop_into(out, meta):
                assert (out == out[0]).all(), f"torn sample {int(meta[0])}"
                assert meta[1] == 10 * out[0]
                values.append(int(out[0]))
                numbers.append(int(meta[0]))
            if finished:
                break
        producer.join()
        assert producer.exitcode == 0
        assert all(a < b for a, b in zip(values, values[1:]))
        assert all(a < b for a, b in zip(numbers, numbers[1:]))
        if overflow == "drop_oldest":
            assert values == numbers  # slot numbers are the producer's numbers
            assert values[-1] == QUEUE_SAMPLES  # the newest is never lost
        else:
            assert values[0] == 1  # the oldest is never lost
        assert len(values) + queue.dropped == QUEUE_SAMPLES
        assert queue.pending() == 0
    finally:
        if producer.is_alive():
            producer.terminate()
        if producer.pid is not None:
            producer.join()
        if queue is not None:
            queue.close()
        shm.close()
        shm.unlink()


# ---------------------------------------------------------------- allocation


def traced_growth(cycle, cycles: int = 10_000) -> tuple[int, int]:
    """Bytes still allocated, and the peak above the start, after `cycles` calls."""
    return allocation_stats(cycle, cycles, warmup=1_000)


@pytest.mark.parametrize("synchronised", [True, False], ids=["seqlock", "plain"])
@pytest.mark.parametrize("port", [PORTS["vec3"], SCAN], ids=["vec3", "scan"])
def test_latest_cycle_allocates_nothing(port: Port, synchronised: bool) -> None:
    slot = LatestSlot(buffer_for(latest_nbytes(port)), port, synchronised)
    value = sample(port, 1)
    out, meta = new_out(port)

    def cycle() -> None:
        slot.write(value, 123_456_789_000)
        slot.read_into(out, meta)

    growth, peak = traced_growth(cycle)
    assert growth < 4096
    assert peak < 1024  # transient ints at most: a copy of the scan alone is 3 KiB


@pytest.mark.parametrize("overflow", ["drop_oldest", "drop_newest"])
def test_queue_cycle_allocates_nothing(overflow: str) -> None:
    queue = make_queue(4, overflow, SCAN)
    value = sample(SCAN, 1)
    out, meta = new_out(SCAN)

    def cycle() -> None:
        queue.push(value, 123_456_789_000)
        queue.push(value, 123_456_789_001)
        queue.pop_into(out, meta)

    growth, peak = traced_growth(cycle)
    assert growth < 4096
    assert peak < 1024
