"""What happens to a run, as channels beside its streams: `/events/KIND`, one JSON message per event.

Two ways in, one way out:

- the run tells its observer (`runtime.observer.Observer.event`) what it decides on the main
  thread: a mode entered or left (`/events/mode`), and whatever kind a caller names later (a
  parameter change): each kind gets a channel of its own the first time it comes;
- flag changes (`/events/flags`) and life-cycle transitions (`/events/lifecycle`) happen on the
  loops, which must not call anyone: the recorder reads them from the shared region at each
  drain, as it reads the loops' timing. A state entered and left between two drains is still
  reported: the region keeps a bit per state each owner has reached.

Plain JSON with a JSON Schema, like `/timing/THREAD`: Foxglove's State Transitions panel plots
`/events/lifecycle.state` and the like, and no extra is needed.
"""

from __future__ import annotations

import json
from dataclasses import dataclass

import numpy as np

from hapticop.composition.lcsm import State
from hapticop.recording.mcapfile import EVENT_TOPIC
from hapticop.recording.outputs import Output
from hapticop.runtime.region import Layout

SCHEMA = {
    "title": "hapticop.RunEvent", "type": "object",
    "description": "something that happened to the run: `kind` names it, the other fields depend on the kind",
    "properties": {"kind": {"type": "string"}, "time_s": {"type": "number", "description": "on the run's clock"}},
    "additionalProperties": True,
}


@dataclass(frozen=True)
class EventPlan:
    """Where the region's flags and states lie, and whose they are (picklable)."""

    flags: dict[str, int]  # the flags declared at start -> index (flags added live are not followed)
    owners: dict[str, int]  # activity or 'threads.NAME' -> index
    sections: dict[str, tuple[int, tuple[int, ...], str]]

    @classmethod
    def of(cls, layout: Layout) -> EventPlan:
        return cls(dict(layout.flag_index), dict(layout.owner_index),
                   {s: layout.sections[s] for s in ("flags", "state", "reached")})


class RunEvents:
    """A recorder source: the region's flag and state changes at each drain, and the run's own events."""

    def __init__(self, plan: EventPlan, buffer):
        self.plan = plan
        for name, (offset, shape, dtype) in plan.sections.items():
            setattr(self, name, np.ndarray(shape, dtype=dtype, buffer=buffer, offset=offset))
        self.seen_flags: dict[str, bool] | None = None
        self.seen_states: dict[str, tuple[int, int]] = {}  # owner -> (state, reached bits)
        self.out: Output | None = None
        self.schema = 0
        self.channels: dict[str, int] = {}
        self.sequence = 0

    def start(self, out: Output) -> None:
        self.out = out
        self.schema = out.schema("hapticop.RunEvent", "jsonschema", json.dumps(SCHEMA).encode())
        for kind in ("flags", "lifecycle"):  # written at the first drain; others when their first event comes
            self._channel(kind)

    def _channel(self, kind: str) -> int:
        if kind not in self.channels:
            self.channels[kind] = self.out.channel(EVENT_TOPIC.format(kind), "json", self.schema, {"kind": kind})
        return self.channels[kind]

    def event(self, kind: str, payload: dict, time_ns: int) -> None:
        """One event the run told its observer."""
        if self.out is None:
            return
        self.sequence += 1
        record = {"kind": kind, "time_s": time_ns / 1e9, **payload}
        self.out.write(self._channel(kind), time_ns, json.dumps(record).encode(), time_ns, self.sequence)

    def poll(self, now_ns: int) -> None:
        flags = {name: bool(self.flags[i]) for name, i in self.plan.flags.items()}
        changed = flags if self.seen_flags is None else {
            name: value for name, value in flags.items() if self.seen_flags[name] != value}
        self.seen_flags = flags
        if changed:
            self.event("flags", {"changed": changed, "set": sorted(n for n, v in flags.items() if v)}, now_ns)
        for owner, index in self.plan.owners.items():
            state, reached = int(self.state[index]), int(self.reached[index])
            before = self.seen_states.get(owner)
            if before == (state, reached):
                continue
            self.seen_states[owner] = (state, reached)
            new = reached & ~(before[1] if before else 0)
            passed = [s.flag_name for s in State if new >> s & 1 and s != state]
            self.event("lifecycle", {"owner": owner, "state": State(state).flag_name, "passed": passed,
                                     "from": State(before[0]).flag_name if before else None}, now_ns)

    def finish(self, now_ns: int) -> None:
        self.poll(now_ns)
