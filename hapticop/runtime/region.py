"""The one shared-memory region that holds every piece of state crossing threads.

Flags, LCSM states, selected schedules, timing counters and every stream buffer live in a
single `multiprocessing.shared_memory` block laid out from the composition alone, so a
thread deployed in its own process attaches by name, computes the same layout and sees the
same arrays. Moving a thread into a process therefore changes nothing else.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from multiprocessing import shared_memory

import numpy as np

from hapticop.composition import lcsm
from hapticop.composition.description import ARENA_BYTES, SPARE_ACTIVITIES, SPARE_FLAGS, Composition
from hapticop.composition.loader import ResolvedActivity
from hapticop.runtime import cycle_log
from hapticop.runtime import streams as st
from hapticop.runtime.tallies import Histograms
from hapticop.runtime.timing import BINS
from hapticop.runtime.transport import StreamTransport, transport_for, writer_port

ALIGN = 64
WAITING_BYTES = 160  # what an activity's configuration waits for, as UTF-8 text `status` shows
# Room for what live patches add in the main process: activities with their flags and
# the buffers of their streams. Children never see additions, so layouts still agree.


def _align(n: int) -> int:
    return (n + ALIGN - 1) // ALIGN * ALIGN


@dataclass(frozen=True)
class Transport:
    """Where one stream transport lives: a latest slot, or one queue ring per reader."""

    stream: str
    kind: str  # "latest" or "queue"
    offset: int
    nbytes: int
    reader: str | None = None  # "activity.port" for queue rings


@dataclass
class Layout:
    """Offsets and indices, computed identically in every process from the composition."""

    threads: list[str]
    activities: list[str]
    flags: list[str]
    sections: dict[str, tuple[int, tuple[int, ...], str]] = field(default_factory=dict)
    transports: dict[str, list[Transport]] = field(default_factory=dict)
    recorded: dict[str, Transport] = field(default_factory=dict)  # the recorder's own ring per recorded stream
    rings: dict[str, int] = field(default_factory=dict)  # the observer's reservation: ring capacity per stream
    cycles: dict[str, Transport] = field(default_factory=dict)  # the ring of each activity's cycles (`cycle_log`)
    size: int = 0

    def __post_init__(self) -> None:
        self.thread_index = {n: i for i, n in enumerate(self.threads)}
        self.activity_index = {n: i for i, n in enumerate(self.activities)}
        self.owner_index = {**{f"threads.{n}": i for i, n in enumerate(self.threads)},
                            **{n: len(self.threads) + i for i, n in enumerate(self.activities)}}
        self.flag_index = {n: i for i, n in enumerate(self.flags)}
        self.arena_used = 0

    def add_activity(self, name: str, flags: list[str]) -> None:
        """Give an activity added by a live patch its indices in the spare room."""
        if len(self.activities) >= self.declared_activities + SPARE_ACTIVITIES:
            raise ValueError(f"no room for another activity ({SPARE_ACTIVITIES} may be added to a running system)")
        new_flags = [f for f in flags if f not in self.flag_index]
        if len(self.flags) + len(new_flags) > self.declared_flags + SPARE_FLAGS:
            raise ValueError("no room for more flags in the running system")
        self.activity_index[name] = len(self.activities)
        self.owner_index[name] = len(self.threads) + len(self.activities)
        self.activities.append(name)
        for flag in new_flags:
            self.flag_index[flag] = len(self.flags)
            self.flags.append(flag)

    def mark(self) -> tuple[int, int, int]:
        """Where the spare room's use stands, to give back what a failed live addition took (`rollback`)."""
        return len(self.activities), len(self.flags), self.arena_used

    def rollback(self, mark: tuple[int, int, int]) -> None:
        activities, flags, arena_used = mark
        for name in self.activities[activities:]:
            del self.activity_index[name], self.owner_index[name]
        del self.activities[activities:]
        for flag in self.flags[flags:]:
            del self.flag_index[flag]
        del self.flags[flags:]
        self.arena_used = arena_used

    def place(self, transport: StreamTransport, at) -> None:
        """Place a stream's buffers, each at `at(nbytes)`: the same sizes at start-up (one after
        the other) as for a stream added live (from the arena)."""
        self.transports[transport.name] = [Transport(transport.name, transport.kind, at(nbytes), nbytes, reader)
                                           for nbytes, reader in transport.buffers()]
        if transport.name in self.rings:
            nbytes = transport.ring_nbytes(self.rings[transport.name])
            self.recorded[transport.name] = Transport(transport.name, "queue", at(nbytes), nbytes, "recorder")
        else:  # a stream added again, now unrecorded: its earlier ring is not its own any more
            self.recorded.pop(transport.name, None)

    def room_for(self, flags_by_activity: dict[str, list[str]], buffers: list[int]) -> str | None:
        """What the spare room lacks for these live additions (None: they fit); changes nothing, so
        a patch that would not fit is refused before any of it is applied."""
        left = self.declared_activities + SPARE_ACTIVITIES - len(self.activities)
        if len(flags_by_activity) > left:
            return (f"no room for {len(flags_by_activity)} more activities: {left} of the {SPARE_ACTIVITIES} a "
                    "running system may add are left")
        new_flags = {f for flags in flags_by_activity.values() for f in flags if f not in self.flag_index}
        if len(self.flags) + len(new_flags) > self.declared_flags + SPARE_FLAGS:
            return f"no room for {len(new_flags)} more flags (at most {SPARE_FLAGS} may be added)"
        used = self.arena_used
        for nbytes in buffers:
            if used + nbytes > ARENA_BYTES:
                return f"no room for the new streams' buffers ({ARENA_BYTES} bytes for live additions)"
            used = _align(used + nbytes)
        return None

    def allocate(self, nbytes: int) -> int:
        """Offset of `nbytes` in the arena for a stream added live."""
        offset = self.sections["arena"][0] + self.arena_used
        if self.arena_used + nbytes > ARENA_BYTES:
            raise ValueError(f"no room for another stream buffer ({ARENA_BYTES} bytes for live additions)")
        self.arena_used = _align(self.arena_used + nbytes)
        return offset

    @classmethod
    def alone(cls, activity: str, flags: list[str]) -> Layout:
        """The layout of one activity on no thread, with no streams (a block harness, a replay)."""
        layout = cls([], [activity], sorted(flags))
        layout.size = max(layout._sections(), ALIGN)
        return layout

    @classmethod
    def build(cls, composition: Composition, activities: dict[str, ResolvedActivity], flags: list[str],
              rings: dict[str, int] | None = None) -> Layout:
        """`rings`: the recorder ring each stream gets, by capacity (what the run's observer reserves)."""
        layout = cls(list(composition.threads), list(activities), sorted(flags), rings=dict(rings or {}))
        offset = layout._sections()

        def at(nbytes: int) -> int:
            nonlocal offset
            start, offset = offset, _align(offset + nbytes)
            return start

        for name, spec in composition.streams.items():
            layout.place(transport_for(name, spec, writer_port(activities, spec)), at)
        for name, resolved in activities.items():  # each activity's cycles, where the observer reserved a ring
            capacity = layout.rings.get(cycle_log.stream_of(name))
            if capacity:
                nbytes = st.queue_nbytes(cycle_log.port_of(resolved.interface, resolved.block.implements_flush()),
                                         capacity)
                layout.cycles[name] = Transport(cycle_log.stream_of(name), "queue", at(nbytes), nbytes, "recorder")
        layout.size = max(offset, ALIGN)
        return layout

    def _sections(self) -> int:
        """Place the fixed sections; returns where the streams' buffers begin."""
        layout = self
        layout.declared_activities, layout.declared_flags = len(layout.activities), len(layout.flags)
        threads = len(layout.threads)
        owners = len(layout.owner_index) + SPARE_ACTIVITIES
        acts = len(layout.activities) + SPARE_ACTIVITIES
        offset = 0

        def section(name: str, shape: tuple[int, ...], dtype: str) -> None:
            nonlocal offset
            layout.sections[name] = (offset, shape, dtype)
            offset = _align(offset + int(np.prod(shape, dtype=np.int64)) * np.dtype(dtype).itemsize)

        section("system", (8,), "int64")
        section("flags", (len(layout.flags) + SPARE_FLAGS,), "uint8")
        section("state", (owners,), "uint8")
        section("failed", (owners,), "uint8")
        section("reached", (owners,), "uint8")  # a bit per LCSM state the owner has entered (1 << state)
        section("selected", (threads,), "int64")
        section("cycles", (threads,), "int64")
        section("missed", (threads,), "int64")
        section("heartbeat", (threads,), "int64")
        section("control", (threads,), "int64")
        section("go", (threads,), "int64")  # the mediator started this thread
        section("latency_max", (threads,), "int64")
        section("latency", (threads, BINS), "int64")
        section("busy_max", (threads,), "int64")  # a timed cycle's wake-up to its end: what the loop computes
        section("busy", (threads, BINS), "int64")
        section("compute_max", (acts,), "int64")
        section("compute", (acts, BINS), "int64")
        section("sim_ns", (acts,), "int64")  # time each activity spent in simulated devices
        section("waiting", (acts, WAITING_BYTES), "uint8")
        section("cpu_ns", (threads,), "int64")  # CPU time each thread's loop has used
        section("cpu_base", (threads,), "int64")  # ... and had used when timing started
        section("cycles_base", (threads,), "int64")  # cycles before timing started
        section("e2e_max", (st.ORIGINS,), "int64")  # end-to-end latencies, one per `latencies` entry
        section("e2e", (st.ORIGINS, BINS), "int64")
        section("arena", (ARENA_BYTES,), "uint8")
        return offset


class Region:
    """Numpy views of the layout's sections over one shared-memory block."""

    # system[] slots
    TERMINATE = 0  # set by the main process: every loop leaves at once (forced exit)
    STARTED_NS = 1
    EPOCH_NS = 2  # every real-time loop's deadlines are counted from here (deadlines.py)
    OPERATING_NS = 3  # every thread had cycled: timing statistics count from here (0: not yet)
    ENDING = 4  # the run has started ending: the loops' histograms no longer count (the shutdown is not the run)

    def histograms(self, name: str) -> Histograms:
        """The `name` histograms (`latency`, `busy`, `compute`, `e2e`) and their maxima, as a counter that
        stops counting when the run starts ending."""
        return Histograms(getattr(self, name), getattr(self, f"{name}_max"), self.system[self.ENDING:self.ENDING + 1])

    def __init__(self, layout: Layout, memory: shared_memory.SharedMemory, owner: bool):
        self.layout = layout
        self.memory = memory
        self.owner = owner
        buffer = memory.buf
        for name, (offset, shape, dtype) in layout.sections.items():
            setattr(self, name, np.ndarray(shape, dtype=dtype, buffer=buffer, offset=offset))

    @classmethod
    def create(cls, layout: Layout) -> Region:
        memory = shared_memory.SharedMemory(create=True, size=layout.size)
        memory.buf[: layout.size] = bytes(layout.size)
        region = cls(layout, memory, owner=True)
        region.state[:] = lcsm.State.CREATION
        return region

    @classmethod
    def attach(cls, layout: Layout, name: str) -> Region:
        """Attach from a thread's own process. Children are started with 'spawn', so they
        share the parent's resource tracker: the block stays registered once, and only the
        creating process unlinks it."""
        memory = shared_memory.SharedMemory(name=name, create=False)
        return cls(layout, memory, owner=False)

    @property
    def name(self) -> str:
        return self.memory.name

    def flag(self, name: str) -> bool:
        return bool(self.flags[self.layout.flag_index[name]])

    def set_flag(self, name: str, value: bool = True) -> None:
        self.flags[self.layout.flag_index[name]] = 1 if value else 0

    def state_of(self, owner: str) -> lcsm.State:
        """The LCSM state of an activity or of a thread ('threads.NAME')."""
        return lcsm.State(int(self.state[self.layout.owner_index[owner]]))

    def buffer_at(self, offset: int, nbytes: int) -> np.ndarray:
        return np.ndarray((nbytes,), dtype=np.uint8, buffer=self.memory.buf, offset=offset)

    def waiting_for(self, activity: str) -> str | None:
        """What the activity last said its configuration waits for (None: nothing)."""
        raw = bytes(self.waiting[self.layout.activity_index[activity]]).rstrip(b"\0")
        return raw.decode("utf-8", "replace") if raw else None

    def close(self) -> None:
        for name in self.layout.sections:
            if hasattr(self, name):
                delattr(self, name)
        if self.owner:  # the name goes first: it must go even if a view below keeps the mapping
            try:
                self.memory.unlink()
            except FileNotFoundError:
                pass
        try:
            self.memory.close()
        except BufferError:
            pass  # a view is still referenced somewhere (an exception's frames): the mapping goes at exit
