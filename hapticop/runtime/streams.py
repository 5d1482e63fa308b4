"""Stream buffers in shared memory: a latest-sample slot and a bounded one-reader queue.

The runtime places every stream in one shared-memory region so that threads may run in
other processes; each class here is a handle over a slice of that region. The layout is
all in the buffer (headers included), so handles in different processes over the same
bytes see the same stream. A buffer must start zeroed (fresh shared memory is).

On the cycle path (`write`, `read_into`, `push`, `pop_into`) nothing blocks, no lock is
taken and no numpy array, list, dict or tuple is created: headers are read and written
through `memoryview` casts and payloads copied into views made once, at construction.
"""

from __future__ import annotations

from threading import get_ident
from typing import Literal

import numpy as np

from hapticop.blocks.interface import Port
from hapticop.runtime.byteviews import ByteViews

SAMPLE_ALIGN = 64
"""Every slot starts and ends on a cache line, so writers never share a line."""

MAX_RETRIES = 1000
"""Reads retried this often while a writer is busy, then give up: a reader never spins forever."""

Buffer = memoryview | np.ndarray

# One sample: header and payload; the payload starts right after the header.
ORIGINS = 5
"""Origin stamps per sample: one per end-to-end latency a composition measures."""

SLOT_HEADER = np.dtype(
    {
        "names": ["seq", "count", "stamp_ns", "origins_ns"],
        "formats": ["<u8", "<u8", "<i8", ("<i8", (ORIGINS,))],
        "offsets": [0, 8, 16, 24],
        "itemsize": 64,
    }
)
"""`seq` is odd while a write is in progress; `count` is the sample's number (1 = first);
`origins_ns` say when the data this sample derives from entered the system (0: unknown)."""

# A queue's indices: the producer's and the consumer's on separate cache lines.
QUEUE_HEADER = np.dtype(
    {
        "names": ["write_index", "dropped_newest", "read_index", "dropped_oldest"],
        "formats": ["<u8", "<u8", "<u8", "<u8"],
        "offsets": [0, 8, 64, 72],
        "itemsize": 128,
    }
)
"""Each field has one writer: the producer owns the first line, the consumer the second."""

_SEQ = SLOT_HEADER.fields["seq"][1] // 8
_COUNT = SLOT_HEADER.fields["count"][1] // 8
_STAMP = SLOT_HEADER.fields["stamp_ns"][1] // 8
COUNT = _COUNT  # the word of `LatestSlot.words` that counts the samples written
_ORIGINS = SLOT_HEADER.fields["origins_ns"][1]
_W = QUEUE_HEADER.fields["write_index"][1] // 8
_DROP_NEW = QUEUE_HEADER.fields["dropped_newest"][1] // 8
_R = QUEUE_HEADER.fields["read_index"][1] // 8
_DROP_OLD = QUEUE_HEADER.fields["dropped_oldest"][1] // 8


def _align(nbytes: int) -> int:
    return -(-nbytes // SAMPLE_ALIGN) * SAMPLE_ALIGN


def latest_nbytes(port: Port) -> int:
    """Bytes a `LatestSlot` for `port` needs."""
    return _align(SLOT_HEADER.itemsize + port.nbytes)


def queue_nbytes(port: Port, capacity: int) -> int:
    """Bytes an `SpscQueue` of `capacity` samples of `port` needs."""
    if capacity < 1:
        raise ValueError(f"queue capacity must be at least 1, not {capacity}")
    return QUEUE_HEADER.itemsize + capacity * latest_nbytes(port)


def sample_dtype(port: Port) -> np.dtype:
    """One queued sample as it lies in a ring: its header words and its payload's bytes.

    `SpscQueue.drain_into` fills arrays of it; `payload` viewed as the port's dtype is the value."""
    return np.dtype({
        "names": ["seq", "count", "stamp_ns", "payload"],
        "formats": ["<u8", "<u8", "<i8", ("u1", (port.nbytes,))],
        "offsets": [0, 8, 16, SLOT_HEADER.itemsize],
        "itemsize": latest_nbytes(port),
    })


def _raw(buffer: Buffer, nbytes: int) -> np.ndarray:
    """The first `nbytes` of `buffer` as writable uint8, checked once so cycles need not."""
    view = memoryview(buffer)
    if view.readonly:
        raise ValueError("stream buffer is read-only")
    raw = np.frombuffer(view.cast("B"), dtype=np.uint8)
    if raw.size < nbytes:
        raise ValueError(f"stream buffer holds {raw.size} bytes, needs {nbytes}")
    if raw.ctypes.data % 8:
        raise ValueError("stream buffer must be 8-byte aligned (headers are atomic words)")
    return raw[:nbytes]


class _Slot:
    """Views over one sample in the buffer: header words and the payload (typed and raw)."""

    __slots__ = ("words", "stamps", "origins", "origin_bytes", "payload", "payload_bytes")

    def __init__(self, raw: np.ndarray, port: Port) -> None:
        head = raw[: SLOT_HEADER.itemsize]
        body = raw[SLOT_HEADER.itemsize : SLOT_HEADER.itemsize + port.nbytes]
        self.words = memoryview(head).cast("Q")
        self.stamps = memoryview(head).cast("q")
        self.origins = head[_ORIGINS : _ORIGINS + 8 * ORIGINS].view("<i8")
        self.origin_bytes = memoryview(head[_ORIGINS : _ORIGINS + 8 * ORIGINS])
        self.payload = body.view(port.dtype).reshape(port.shape)
        self.payload_bytes = memoryview(body)

    def release(self) -> None:
        self.words.release()
        self.stamps.release()
        self.origin_bytes.release()
        self.payload_bytes.release()
        self.payload = self.origins = None


def _scratch(port: Port) -> tuple[np.ndarray, memoryview, np.ndarray, memoryview]:
    """A private copy target, so a torn copy is caught before it reaches the caller's array."""
    raw = np.zeros(port.nbytes, dtype=np.uint8)
    origins = np.zeros(ORIGINS, dtype=np.int64)
    return raw.view(port.dtype).reshape(port.shape), memoryview(raw), origins, memoryview(origins.view(np.uint8))


# Why the seqlock is sound here (x86-64, CPython): a writer makes the sequence odd, copies
# the payload and makes it even again; a reader reads the sequence, copies, and re-reads
# it, keeping the copy only if both reads are equal and even. Header fields are aligned
# 8-byte words read and written with single loads and stores (memoryview item access is a
# fixed-size memcpy). numpy copies are plain loads and stores, and x86-64 is TSO: stores
# become visible in program order and loads are not reordered with older loads, so a
# reader that saw any store of a write also sees that write's odd sequence on its re-read.
# (glibc's non-temporal stores, used only for multi-megabyte copies, end with an sfence.)
# The compiler cannot move accesses across the interpreter's opaque calls between
# bytecodes. The GIL orders threads within a process only; across processes the ordering
# comes from TSO plus the sequence re-check. Other architectures would need fences.


class LatestSlot:
    """The newest sample of a stream, seqlock-protected: readers never wait and never tear.

    One writer; any number of readers, in any threads and processes, sharing a handle or
    not. `synchronised=False` lets this handle's readers skip the protocol, for a writer and
    readers that run one after the other in one thread (on the virtual clock, every loop);
    the writer keeps the sequence all the same, so a reader elsewhere (a live view's tap)
    still reads the slot whole.
    """

    def __init__(self, buffer: Buffer, port: Port, synchronised: bool = True) -> None:
        self.port = port
        self.synchronised = synchronised
        self._slot = _Slot(_raw(buffer, latest_nbytes(port)), port)
        # One scratch per reading thread: threads sharing this handle must not share it.
        self._scratches: dict[int, tuple[np.ndarray, memoryview, np.ndarray, memoryview]] = {}
        self._written, self._written_origins, self._read = ByteViews(), ByteViews(), ByteViews()
        self._origins_like = np.zeros(ORIGINS, dtype=np.int64)
        self.words = self._slot.words  # the header's words: `words[COUNT]` is `count` without a call

    @property
    def count(self) -> int:
        """Samples written so far."""
        return self._slot.words[_COUNT]

    def write(self, value: np.ndarray, stamp_ns: int, origins: np.ndarray | None = None) -> None:
        """Publish `value` (cast like `np.copyto`) as the newest sample, taken at `stamp_ns`."""
        slot = self._slot
        words = slot.words
        seq = words[_SEQ]
        words[_SEQ] = seq + 1
        try:
            written = self._written  # the array written last, nearly always: its view without a call
            view = written.last_view if value is written.last else written.of(value, slot.payload)
            if view is None:
                np.copyto(slot.payload, value)
            else:
                slot.payload_bytes[:] = view
            slot.stamps[_STAMP] = stamp_ns
            if origins is not None:
                written = self._written_origins
                view = written.last_view if origins is written.last else written.of(origins, self._origins_like)
                if view is None:
                    np.copyto(slot.origins, origins)
                else:
                    slot.origin_bytes[:] = view
            words[_COUNT] = words[_COUNT] + 1
        finally:  # a failed copy must not leave the slot locked for ever
            words[_SEQ] = seq + 2

    push = write  # one name for what a port publishes to: a slot takes every sample

    def read_into(self, out: np.ndarray, meta: np.ndarray, origins: np.ndarray | None = None) -> int:
        """Copy the newest sample into `out`, its number and stamp into `meta[0:2]` (and its
        origins into `origins` when given); returns the sample's number.

        0 (false), with `out` and `meta` untouched, if nothing was written yet or the writer
        kept the slot busy for `MAX_RETRIES` attempts.
        """
        slot = self._slot
        words = slot.words
        if not self.synchronised:
            count = words[_COUNT]
            if count == 0:
                return 0
            self._copy_out(out, slot.payload, slot.payload_bytes)
            meta[0] = count
            meta[1] = slot.stamps[_STAMP]
            if origins is not None:
                self._copy_out(origins, slot.origins, slot.origin_bytes)
            return count
        scratch = self._scratches.get(get_ident())
        if scratch is None:  # this thread's first read
            scratch = self._scratches.setdefault(get_ident(), _scratch(self.port))
        scratch_array, scratch_bytes, scratch_origins, scratch_origin_bytes = scratch
        tries = MAX_RETRIES
        while tries:
            tries -= 1
            seq = words[_SEQ]
            if seq == 0:
                return 0
            if seq & 1:
                continue
            count = words[_COUNT]
            stamp = slot.stamps[_STAMP]
            scratch_bytes[:] = slot.payload_bytes
            if origins is not None:
                scratch_origin_bytes[:] = slot.origin_bytes
            if words[_SEQ] == seq:
                self._copy_out(out, scratch_array, scratch_bytes)
                meta[0] = count
                meta[1] = stamp
                if origins is not None:
                    self._copy_out(origins, scratch_origins, scratch_origin_bytes)
                return count
        return 0

    def _copy_out(self, out: np.ndarray, source: np.ndarray, source_bytes: memoryview) -> None:
        read = self._read
        view = read.last_view if out is read.last else read.of(out, source)
        if view is None:
            np.copyto(out, source)
        else:
            view[:] = source_bytes

    def close(self) -> None:
        """Let go of the buffer, so the shared memory can be closed."""
        self._slot.release()
        self._scratches.clear()

    def __repr__(self) -> str:
        words = self._slot.words
        kind = "synchronised" if self.synchronised else "plain"
        return (
            f"LatestSlot({self.port.describe()}, {kind}, count={words[_COUNT]}, "
            f"seq={words[_SEQ]}, stamp_ns={self._slot.stamps[_STAMP]})"
        )


class SpscQueue:
    """A bounded ring for one producer and one consumer (the runtime makes one per reader).

    The producer writes sample `w` into slot `w % capacity` under that slot's seqlock,
    stamping it with its number, then advances `w`. With `drop_oldest` it never waits:
    a consumer more than `capacity` behind skips to the oldest sample still in the ring,
    and one whose slot was overwritten while it copied skips that sample; both count the
    loss. With `drop_newest` the producer refuses a sample while the ring is full.
    """

    def __init__(
        self,
        buffer: Buffer,
        port: Port,
        capacity: int,
        overflow: Literal["drop_oldest", "drop_newest"] = "drop_oldest",
    ) -> None:
        if overflow not in ("drop_oldest", "drop_newest"):
            raise ValueError(f"overflow must be 'drop_oldest' or 'drop_newest', not {overflow!r}")
        raw = _raw(buffer, queue_nbytes(port, capacity))
        self.port = port
        self.capacity = capacity
        self.overflow = overflow
        self._drop_newest = overflow == "drop_newest"
        self._head = memoryview(raw[: QUEUE_HEADER.itemsize]).cast("Q")
        stride = latest_nbytes(port)
        start = QUEUE_HEADER.itemsize
        self._slots = [
            _Slot(raw[start + k * stride : start + (k + 1) * stride], port) for k in range(capacity)
        ]
        self._scratch, self._scratch_bytes, self._scratch_origins, _ = _scratch(port)
        self._samples = raw[start:].view(sample_dtype(port))  # the slots as one array, for `drain_into`

    @property
    def dropped(self) -> int:
        """Samples lost so far: refused by the producer or skipped by the consumer."""
        return self._head[_DROP_NEW] + self._head[_DROP_OLD]

    @property
    def written(self) -> int:
        """Samples the producer has pushed so far."""
        return self._head[_W]

    def pending(self) -> int:
        """Samples the consumer could still pop."""
        head = self._head
        return min(head[_W] - head[_R], self.capacity)

    def push(self, value: np.ndarray, stamp_ns: int, origins: np.ndarray | None = None) -> bool:
        """Append a sample (producer only); False if refused because the ring is full."""
        head = self._head
        w = head[_W]
        if self._drop_newest and w - head[_R] >= self.capacity:
            head[_DROP_NEW] = head[_DROP_NEW] + 1
            return False
        slot = self._slots[w % self.capacity]
        words = slot.words
        seq = words[_SEQ]
        words[_SEQ] = seq + 1
        try:
            np.copyto(slot.payload, value)
            slot.stamps[_STAMP] = stamp_ns
            if origins is not None:
                np.copyto(slot.origins, origins)
            words[_COUNT] = w + 1
        finally:
            words[_SEQ] = seq + 2
        head[_W] = w + 1
        return True

    def pop_into(self, out: np.ndarray, meta: np.ndarray, origins: np.ndarray | None = None) -> bool:
        """Take the oldest sample still held into `out`, its number and stamp into `meta`.

        Sample numbers start at 1 and have gaps where samples were dropped. False, with
        `out` and `meta` untouched, when the ring is empty (consumer only).
        """
        head = self._head
        capacity = self.capacity
        r = head[_R]
        tries = MAX_RETRIES
        while tries:
            tries -= 1
            w = head[_W]
            if r >= w:
                break
            if w - r > capacity:  # lapped: the oldest samples were overwritten
                head[_DROP_OLD] = head[_DROP_OLD] + (w - capacity - r)
                r = w - capacity
            slot = self._slots[r % capacity]
            words = slot.words
            seq = words[_SEQ]
            if seq & 1 or words[_COUNT] != r + 1:  # being or already overwritten
                head[_DROP_OLD] = head[_DROP_OLD] + 1
                r += 1
                continue
            stamp = slot.stamps[_STAMP]
            self._scratch_bytes[:] = slot.payload_bytes
            np.copyto(self._scratch_origins, slot.origins)
            if words[_SEQ] != seq:  # overwritten while we copied
                head[_DROP_OLD] = head[_DROP_OLD] + 1
                r += 1
                continue
            head[_R] = r + 1
            np.copyto(out, self._scratch)
            meta[0] = r + 1
            meta[1] = stamp
            if origins is not None:
                np.copyto(origins, self._scratch_origins)
            return True
        head[_R] = r
        return False

    def drain_into(self, out: np.ndarray) -> int:
        """Take up to `len(out)` of the oldest samples held, in order, into `out` (an array of
        `sample_dtype(port)`); returns how many (consumer only).

        For a consumer off the real-time path that reads many samples at a time (the recorder):
        the slots are copied in one go, between two reads of their sequence words, and a
        sample whose word changed, was odd, or whose number is not the one expected was
        overwritten meanwhile and is counted lost, as `pop_into` counts it. Allocates.
        """
        head = self._head
        capacity = self.capacity
        r, w = head[_R], head[_W]
        if w - r > capacity:  # lapped: the oldest samples were overwritten
            head[_DROP_OLD] = head[_DROP_OLD] + (w - capacity - r)
            r = w - capacity
        n = min(w - r, len(out))
        if n <= 0:
            head[_R] = r
            return 0
        first = r % capacity
        where = (slice(first, first + n) if first + n <= capacity  # one run of slots: copied as a block
                 else np.arange(first, first + n) % capacity)
        before = self._samples["seq"][where].copy()
        taken = self._samples[where].copy()
        after = self._samples["seq"][where]
        numbers = np.arange(r + 1, r + n + 1, dtype=np.uint64)
        good = (before == after) & (before % 2 == 0) & (taken["count"] == numbers)
        kept = int(np.count_nonzero(good))
        out[:kept] = taken[good]
        head[_DROP_OLD] = head[_DROP_OLD] + (n - kept)
        head[_R] = r + n
        return kept

    def close(self) -> None:
        """Let go of the buffer, so the shared memory can be closed."""
        self._samples = None
        self._head.release()
        for slot in self._slots:
            slot.release()

    def __repr__(self) -> str:
        head = self._head
        return (
            f"SpscQueue({self.port.describe()}, capacity={self.capacity}, {self.overflow}, "
            f"write_index={head[_W]}, read_index={head[_R]}, dropped={self.dropped})"
        )


class RecorderRing(SpscQueue):
    """The recorder's own ring of a stream: never refuses a sample (the oldest are overwritten and
    counted by the recorder), and leaves the origin stamps out, which are the loops' business
    (measured latencies), not the record's: a push costs the writing loop less."""

    def __init__(self, buffer: Buffer, port: Port, capacity: int, stream: str = "") -> None:
        super().__init__(buffer, port, capacity, "drop_oldest")
        self.stream = stream  # which stream's record it is: a stream removed live takes its ring off its writer

    def push(self, value: np.ndarray, stamp_ns: int, origins: np.ndarray | None = None) -> bool:
        return SpscQueue.push(self, value, stamp_ns)
