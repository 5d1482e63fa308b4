"""Each loop's timing as a plottable series: one `/timing/THREAD` JSON message per window.

The loops count wake-up latencies and compute times in histograms of 1 us bins in the shared
region (`timing`); the recorder reads them every `WINDOW_NS` and writes what changed since the
last window: the cycles run and deadlines missed in it, the wake-up latency's median, 99th
percentile and maximum, the largest compute time of each of the thread's activities and the
loop's share of a core. Only the bins up to the largest value yet counted can have changed,
so a window reads a few hundred bins, not the whole histograms. Plain JSON with a JSON Schema:
Foxglove plots `/timing/main.latency_p99_us` and the like, and no extra is needed.
"""

from __future__ import annotations

import json
from dataclasses import dataclass

import numpy as np

from hapticop.composition.description import Composition
from hapticop.recording.mcapfile import TIMING_TOPIC
from hapticop.recording.outputs import Output
from hapticop.runtime.region import Layout
from hapticop.runtime.timing import BINS

WINDOW_NS = 250_000_000  # four points a second per loop: a window costs a pass over each histogram's used bins
SECTIONS = ("cycles", "missed", "cpu_ns", "latency", "latency_max", "compute", "compute_max")
_NUMBER = {"type": "number"}
SCHEMA = {
    "title": "hapticop.LoopTiming", "type": "object",
    "description": "one loop's timing over the last window (the figures of `hapticop compose`'s table, per window)",
    "properties": {
        "window_s": _NUMBER, "cycles": {"type": "integer"}, "missed": {"type": "integer"},
        "missed_total": {"type": "integer", "description": "since timing started (after start-up)"},
        "latency_p50_us": _NUMBER, "latency_p99_us": _NUMBER, "latency_max_us": _NUMBER,
        "cpu_percent": {**_NUMBER, "description": "of one core, over the window"},
        "compute_max_us": {"type": "object", "additionalProperties": _NUMBER,
                           "description": "each activity's longest step in the window"},
    },
}


@dataclass(frozen=True)
class TimingPlan:
    """Where the region's timing counters lie, and each thread's activities (picklable)."""

    threads: dict[str, int]  # name -> index
    activities: dict[str, dict[str, int]]  # thread -> {activity: index}
    sections: dict[str, tuple[int, tuple[int, ...], str]]

    @classmethod
    def of(cls, composition: Composition, layout: Layout) -> TimingPlan:
        activities = {}
        for name, thread in composition.threads.items():
            scheduled = dict.fromkeys(a for schedule in thread.schedules.values() for a in schedule)
            activities[name] = {a: layout.activity_index[a] for a in scheduled if a in layout.activity_index}
        return cls(dict(layout.thread_index), activities, {s: layout.sections[s] for s in SECTIONS})


class _Window:
    """One histogram row's counts at the last window, to take differences from."""

    def __init__(self) -> None:
        self.seen = np.zeros(BINS, np.int64)
        self.now = np.zeros(BINS, np.int64)
        self.added = np.zeros(BINS, np.int64)

    def change(self, row: np.ndarray, maximum_ns: int) -> np.ndarray:
        """The counts added since the last call (a counter cleared meanwhile starts again from zero);
        valid until the next call."""
        top = min(BINS, int(maximum_ns) // 1000 + 1)
        now, seen, added = self.now[:top], self.seen[:top], self.added[:top]
        np.copyto(now, row[:top])  # the loop goes on counting while we read
        np.subtract(now, seen, out=added)
        if added.min(initial=0) < 0:  # cleared when the system started operating
            self.seen[:] = 0
            np.copyto(added, now)
        np.copyto(seen, now)
        return added


def _percentile_us(counts: np.ndarray, q: float) -> float:
    total = int(counts.sum())
    return float(np.searchsorted(np.cumsum(counts), max(1, int(np.ceil(q / 100 * total)))))


def _latency(counts: np.ndarray) -> dict[str, float]:
    """The window's wake-up latencies (none under the virtual clock, where loops wake on time: 0)."""
    if not counts.any():
        return {"latency_p50_us": 0.0, "latency_p99_us": 0.0, "latency_max_us": 0.0}
    return {"latency_p50_us": _percentile_us(counts, 50), "latency_p99_us": _percentile_us(counts, 99),
            "latency_max_us": float(np.flatnonzero(counts)[-1])}


class LoopTiming:
    """A recorder source reading the region's timing counters every `WINDOW_NS`."""

    def __init__(self, plan: TimingPlan, buffer):
        self.plan = plan
        for name, (offset, shape, dtype) in plan.sections.items():
            setattr(self, name, np.ndarray(shape, dtype=dtype, buffer=buffer, offset=offset))
        self.latency_windows = {t: _Window() for t in plan.threads}
        self.compute_windows = {a: _Window() for acts in plan.activities.values() for a in acts}
        self.last = {t: (0, 0, 0) for t in plan.threads}  # cycles, missed, cpu_ns at the last window
        self.next_ns = 0
        self.last_ns: int | None = None  # the last window's end
        self.sequence = 0

    def start(self, out: Output) -> None:
        self.out = out
        schema = out.schema("hapticop.LoopTiming", "jsonschema", json.dumps(SCHEMA).encode())
        self.channels = {t: out.channel(TIMING_TOPIC.format(t), "json", schema, {"thread": t})
                         for t in self.plan.threads}

    def poll(self, now_ns: int) -> None:
        if now_ns < self.next_ns:
            return
        window_ns = now_ns - self.last_ns if self.last_ns is not None else 0
        self.next_ns, self.last_ns = now_ns + WINDOW_NS, now_ns
        for thread, index in self.plan.threads.items():
            counters = (int(self.cycles[index]), int(self.missed[index]), int(self.cpu_ns[index]))
            cycles, missed, cpu_ns = (max(0, now - then) if now >= then else now
                                      for now, then in zip(counters, self.last[thread], strict=True))
            self.last[thread] = counters
            latency = self.latency_windows[thread].change(self.latency[index], self.latency_max[index])
            if not window_ns or not (cycles or latency.any()):
                continue  # the first window, or a loop that did not run in it
            compute = {}
            for activity, a in self.plan.activities[thread].items():
                added = self.compute_windows[activity].change(self.compute[a], self.compute_max[a])
                compute[activity] = float(np.flatnonzero(added)[-1]) if added.any() else 0.0
            record = {"window_s": window_ns / 1e9, "cycles": cycles, "missed": missed, "missed_total": counters[1],
                      **_latency(latency),
                      "cpu_percent": round(100 * cpu_ns / window_ns, 2), "compute_max_us": compute}
            self.sequence += 1
            self.out.write(self.channels[thread], now_ns, json.dumps(record).encode(), now_ns, self.sequence)

    def finish(self, now_ns: int) -> None:
        """The last, shorter window."""
        self.next_ns = 0
        self.poll(now_ns)
