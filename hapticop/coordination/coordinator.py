"""The mediator's engine: flag maps and Petri nets, stepped once per main-thread cycle.

Each step, for every net in declaration order: converting sources (a true flag is cleared
and adds a token), tracking sources (the place mirrors the flag), firing to a steady
state (`Net.fire_to_steady_state`, the rule validation explores), converting sinks (a
token is taken and sets the flag), tracking sinks (the flag mirrors the place). Most
cycles nothing has changed, so a step first compares the flags with the copy it kept last
time (one vectorised comparison) and returns at once.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from hapticop.composition.description import Coordination
from hapticop.coordination.petri import Net

Bindings = list[tuple[int, int]]  # (flag index, place index)


@dataclass
class _Running:
    """One net as the coordinator runs it: its marking, and the flags bound to its places."""

    net: Net
    marking: list[int]  # a Python list: reading and writing small ints allocates nothing
    converting_sources: Bindings = field(default_factory=list)
    tracking_sources: Bindings = field(default_factory=list)
    converting_sinks: Bindings = field(default_factory=list)
    tracking_sinks: Bindings = field(default_factory=list)
    firings: int = 0


class Coordinator:
    def __init__(self, coordination: Coordination, flags: np.ndarray, flag_index: dict[str, int]):
        self.flags = flags
        self.nets: list[_Running] = []
        by_name: dict[str, _Running] = {}
        for name, spec in coordination.nets.items():
            net = Net.from_spec(spec, name)
            running = _Running(net, [int(tokens) for tokens in net.initial])
            self.nets.append(running)
            by_name[name] = running
        for fmap in coordination.flag_maps.values():
            running = by_name[fmap.net]
            index = {p: i for i, p in enumerate(running.net.places)}
            for kind in ("converting_sources", "tracking_sources", "converting_sinks", "tracking_sinks"):
                getattr(running, kind).extend((flag_index[f], index[p]) for f, p in getattr(fmap, kind).items())
        self._seen = flags.copy()
        self._changed = np.zeros_like(flags, dtype=bool)
        self._pending = True  # step at least once: initial markings may enable transitions

    def step(self) -> bool:
        """One coordination step; True if any marking or flag changed."""
        if not self._pending:
            np.not_equal(self.flags, self._seen, out=self._changed)
            if not np.count_nonzero(self._changed):  # a quarter of what `any()` costs here
                return False
        flags = self.flags
        # Snapshot before reading: a flag another thread sets during this step is then
        # seen as a change next cycle instead of being lost.
        self._seen[:] = flags
        pending = False
        for running in self.nets:
            marking = running.marking
            for f, p in running.converting_sources:
                if flags[f]:
                    flags[f] = 0
                    marking[p] += 1
            for f, p in running.tracking_sources:
                marking[p] = 1 if flags[f] else 0
            running.firings += running.net.fire_to_steady_state(marking)
            for f, p in running.converting_sinks:
                if marking[p] > 0:
                    marking[p] -= 1
                    flags[f] = 1
                    pending = pending or marking[p] > 0
            for f, p in running.tracking_sinks:
                flags[f] = 1 if marking[p] > 0 else 0
        self._pending = pending
        return True

    def markings(self) -> dict[str, dict[str, int]]:
        return {r.net.name: {p: n for p, n in zip(r.net.places, r.marking) if n} for r in self.nets}
