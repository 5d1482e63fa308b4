"""What an activity sees of the world: its ports, its own flags, its clock and its log.

Ports hold preallocated numpy arrays. Before each step the runtime copies the newest
sample of every latest-policy input into its array (queue inputs are popped by the block);
a block fills an output's array and calls `publish()`, which stamps it and copies it into
the stream's transports. Nothing here allocates on the cycle path.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import numpy as np

from hapticop.blocks.interface import Params, Port
from hapticop.runtime.logs import Logger
from hapticop.runtime.streams import COUNT, ORIGINS

STALE_IN_A_ROW = 3  # stale arrivals in a row before a reader says so (one old sample at start-up is no news)
STALE_SAID_EVERY_NS = 10_000_000_000  # while it lasts, said again this often


class CycleClock:
    """The time the activity's current step began, set by its runner: what its input ports judge
    `valid` and `age_ns()` by, so that one cycle sees one time however long it is preempted, and a
    replay stepping the recorded cycles' times sees what the run saw."""

    __slots__ = ("now",)

    def __init__(self) -> None:
        self.now = 0

    def now_ns(self) -> int:
        return self.now


class InputPort:
    """The reader's side of a stream: `value`, and how fresh it is."""

    __slots__ = ("name", "spec", "value", "meta", "origins", "max_age_ns", "transport", "queue", "fresh", "_clock",
                 "_words", "_seen", "_number", "log", "_stale_run", "_stale_said_at")

    def __init__(self, name: str, spec: Port, clock: Callable[[], int], track_origins: bool = False):
        self.name, self.spec, self._clock = name, spec, clock
        self.value = np.zeros(spec.shape, dtype=spec.dtype)
        self.meta = np.zeros(2, dtype=np.int64)  # [sample sequence number, write time ns]
        # when the data behind the sample entered the system, per measured latency (None: not measured)
        self.origins = np.zeros(ORIGINS, dtype=np.int64) if track_origins else None
        self.max_age_ns = 0
        self.transport: Any = None  # a LatestSlot or SpscQueue; None while unconnected
        self._words: Any = None  # a latest slot's header words (its sample count at COUNT); None otherwise
        self.queue = False
        self.fresh = False  # a new sample arrived for this step
        self._seen = 0  # samples the transport had written when `value` was last copied
        self._number = 0  # meta[0] as a Python int: comparing numpy scalars costs more than the copy
        self.log: Logger | None = None  # where stale arrivals are said (the activity's log; None: nowhere)
        self._stale_run = 0  # samples in a row already older than max_age when they arrived
        self._stale_said_at = -STALE_SAID_EVERY_NS

    def connect(self, transport, queue: bool, max_age_ns: int) -> None:
        """Read from `transport` from now on (assembly, or a live patch rewiring the stream)."""
        self.transport, self.queue, self.max_age_ns = transport, queue, max_age_ns
        self._words = None if queue else transport.words
        self._seen = -1  # whatever the new transport holds is news
        self._stale_run = 0
        self._number = int(self.meta[0])

    def disconnect(self) -> None:
        self.transport = self._words = None

    def refresh(self) -> bool:
        """Copy the newest sample in (runtime, before the step); queue inputs are left to pop().
        True when a new sample arrived (`fresh`).

        An unchanged slot is not copied again: most inputs of a 1 kHz loop change at a lower
        rate (a scan of 811 ranges at 15 Hz), and the copy is most of what a read costs.
        """
        words = self._words
        if words is None or words[COUNT] == self._seen:  # a queue, unconnected, or nothing new
            self.fresh = False
            return False
        number = self.transport.read_into(self.value, self.meta, self.origins)
        fresh = self.fresh = number != 0 and number != self._number
        if number:
            self._number = number
        if fresh:
            self._seen = number
            if self.max_age_ns:
                self._judge_arrival()
        return fresh

    def _judge_arrival(self) -> None:
        """A stream whose every sample arrives older than its `max_age` (a link slower than the
        deadline) leaves its reader with no valid sample, ever: that is said, with the age and the
        deadline, at the third such sample in a row and every 10 s while it lasts. Between those
        lines this adds two integer operations to a fresh sample; the line itself is queued to
        the log's writer thread."""
        now = self._clock()
        age = now - int(self.meta[1])
        log = self.log
        if age <= self.max_age_ns:
            if self._stale_run >= STALE_IN_A_ROW and log is not None:
                log.info("input '%s': samples arrive within max_age again, after %d stale", self.name,
                         self._stale_run)
            self._stale_run = 0
            return
        self._stale_run += 1
        if (self._stale_run >= STALE_IN_A_ROW and now - self._stale_said_at >= STALE_SAID_EVERY_NS
                and log is not None):
            self._stale_said_at = now
            log.warning("input '%s': every sample arrives stale: %.1f ms old on arrival, max_age %.1f ms "
                        "(%d in a row); the block sees no valid sample", self.name, age / 1e6,
                        self.max_age_ns / 1e6, self._stale_run)

    def pop(self) -> bool:
        """Take the next queued sample into `value`; False when the queue is empty."""
        if self.transport is None or not self.transport.pop_into(self.value, self.meta, self.origins):
            return False
        if self.max_age_ns:
            self._judge_arrival()
        return True

    @property
    def seq(self) -> int:
        return int(self.meta[0])

    @property
    def stamp_ns(self) -> int:
        return int(self.meta[1])

    def age_ns(self) -> int:
        """How old the sample was when this step began (-1: none yet)."""
        return self._clock() - int(self.meta[1]) if self.meta[0] else -1

    @property
    def valid(self) -> bool:
        """A sample exists and was no older than the stream's `max_age` when this step began."""
        if not self.meta[0]:
            return False
        return self.max_age_ns == 0 or self._clock() - int(self.meta[1]) <= self.max_age_ns


class OutputPort:
    """The writer's side: fill `value`, then `publish()`.

    Where a measured latency starts at this port (`origin_slots`), each sample is stamped as
    an origin: at `origin_ns` if the block set it (e.g. when a telegram's last byte arrived),
    else at publication. A sample is stamped with the time of publication, or with `stamp_ns` when
    the block set it (a network bridge: the sample's send time on the writing host).
    """

    __slots__ = ("name", "spec", "value", "transports", "published", "origins", "origin_slots", "origin_ns",
                 "stamp_ns", "_clock")

    def __init__(self, name: str, spec: Port, clock: Callable[[], int], track_origins: bool = False):
        self.name, self.spec, self._clock = name, spec, clock
        self.value = np.zeros(spec.shape, dtype=spec.dtype)
        self.transports: list = []
        self.published = 0
        self.origins = np.zeros(ORIGINS, dtype=np.int64) if track_origins else None
        self.origin_slots: tuple[int, ...] = ()
        self.origin_ns = 0
        self.stamp_ns = 0

    def publish(self) -> None:
        now = self.stamp_ns or self._clock()
        self.stamp_ns = 0
        origins = self.origins
        if self.origin_slots:
            for slot in self.origin_slots:
                origins[slot] = self.origin_ns or now
            self.origin_ns = 0
        value = self.value
        for transport in self.transports:
            transport.push(value, now, origins)
        self.published += 1


class FlagView:
    """An activity's own declared flags, by name: `flags["new_scan"] = True`."""

    __slots__ = ("_flags", "_index", "_activity", "_run")

    def __init__(self, flags: np.ndarray, index: dict[str, int], activity: str, names: list[str]):
        self._flags, self._activity, self._run = flags, activity, index
        self._index = {name: index[f"{activity}.{name}"] for name in names}

    def run_flags(self) -> dict[str, bool]:
        """Every flag of the run, by its full name, read only: what a block reporting the run's state
        sends (the ROS 2 bridge's flags topic). Allocates: not for a 1 kHz compute."""
        return {name: bool(self._flags[i]) for name, i in self._run.items()}

    def __getitem__(self, name: str) -> bool:
        return bool(self._flags[self._index[name]])

    def __setitem__(self, name: str, value: bool) -> None:
        self._flags[self._index[name]] = 1 if value else 0


class SimulationTimer:
    """`with context.simulation:` around the simulated device inside a block, so reports can
    tell the system's own CPU from its simulators'. One object per activity: entering and
    leaving allocate nothing."""

    __slots__ = ("_totals", "_index", "_started")

    def __init__(self, totals: np.ndarray | None = None, index: int = 0):
        self._totals, self._index, self._started = totals, index, 0

    def __enter__(self) -> None:
        self._started = time.thread_time_ns()

    def __exit__(self, exc_type: object, exc: object, tb: object) -> None:
        if self._totals is not None:  # CPU time, as the loops' CPU it is subtracted from
            self._totals[self._index] += time.thread_time_ns() - self._started


@dataclass
class ActivityContext:
    name: str
    params: Params
    inputs: SimpleNamespace
    outputs: SimpleNamespace
    flags: FlagView
    clock: Any
    log: Logger
    rng: np.random.Generator
    run_dir: Path  # where the activity may leave results (logs live there too)
    simulation: SimulationTimer = field(default_factory=SimulationTimer)
    coordination: Any = None  # the mediator's handle in the main process: start_threads(), step()
    period_ns: int = 0  # the period of the thread that cycles it (0: not scheduled on a thread)
    waiting_slot: np.ndarray | None = None  # the region's text `status` shows (None: a harness, no region)
    waiting: str | None = None  # what the activity's configuration waits for now

    def waiting_for(self, what: str | None) -> None:
        """Say what a configuration hook is waiting for (None: nothing any more), so a wait is never
        silent: logged once per change and shown by `hapticop status`. Not for `compute`."""
        if what == self.waiting:
            return
        self.waiting = what
        if what is not None:
            self.log.info("waiting for %s", what)
        slot = self.waiting_slot
        if slot is not None:
            text = (what or "").encode()[: len(slot)]
            slot[:] = 0
            slot[: len(text)] = np.frombuffer(text, np.uint8)
