"""Which streams a run records, at what rate each is written, and how deep its recorder ring is.

Worked out from the composition alone, so the main process and every child process place the
recorder's rings at the same offsets of the shared region.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from hapticop.composition.description import Composition

MIN_CAPACITY = 16
"""Even a slow stream's ring holds this many samples: a `wake: data` thread may publish in bursts."""


@dataclass(frozen=True)
class RecordedStream:
    name: str
    rate_hz: float  # its writer's thread rate
    every: int  # record every Nth sample
    capacity: int  # samples its recorder ring holds


def writer_thread(composition: Composition, stream: str) -> str | None:
    """The thread whose schedules hold the stream's writing activity (the first, in file order)."""
    activity = composition.streams[stream].writer.split(".")[0]
    for name, spec in composition.threads.items():
        if any(activity in members for members in spec.schedules.values()):
            return name
    return None


def recorded_streams(composition: Composition) -> dict[str, RecordedStream]:
    """The recorded streams, in file order; empty when the composition records nothing."""
    record = composition.record
    if record is None:
        return {}
    names = list(composition.streams) if record.streams == "all" else [
        s for s in record.streams if s in composition.streams]
    depth_s = _depth_s(composition)
    plan = {}
    for name in names:
        thread = writer_thread(composition, name)
        plan[name] = _ring(composition, name, thread, depth_s, record.decimate.get(name, 1))
    return plan


def _depth_s(composition: Composition) -> float:
    # the main thread's period bounds how often a virtual-clock run drains the rings
    main_period = min((t.period for t in composition.threads.values() if t.deploy == "main"), default=0)
    return max(composition.record.depth, 2 * main_period) / 1e9


def _ring(composition: Composition, name: str, thread: str | None, depth_s: float, every: int) -> RecordedStream:
    rate_hz = 1e9 / composition.threads[thread].period if thread else 0.0
    return RecordedStream(name, rate_hz, every, max(MIN_CAPACITY, math.ceil(rate_hz * depth_s)))


def recorded_cycles(composition: Composition) -> dict[str, RecordedStream]:
    """Each scheduled activity's cycles (`runtime.cycle_log`), by activity, when the run records:
    what a replay lines the recorded samples up with."""
    if composition.record is None:
        return {}
    depth_s = _depth_s(composition)
    plan = {}
    for thread, spec in composition.threads.items():
        for members in spec.schedules.values():
            for activity in members:
                if activity in composition.activities and activity not in plan:
                    plan[activity] = _ring(composition, "cycles/" + activity, thread, depth_s, 1)
    return plan
