"""The mediator's engine: flag maps and Petri nets, stepped once per main-thread cycle.

Each step, for every net in declaration order: converting sources (a true flag is cleared
and adds a token), tracking sources (the place mirrors the flag), firing to a steady
state, converting sinks (a token is taken and sets the flag), tracking sinks (the flag
mirrors the place). Most cycles nothing has changed, so a step first compares the flags
with the copy it kept last time (one vectorised comparison) and returns at once.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from hapticop.composition.description import Coordination
from hapticop.coordination.petri import Livelock


@dataclass
class _Net:
    name: str
    places: list[str]
    transitions: list[tuple[str, list[tuple[int, int]], list[tuple[int, int]]]]
    marking: list[int]
    converting_sources: list[tuple[int, int]] = field(default_factory=list)  # (flag, place)
    tracking_sources: list[tuple[int, int]] = field(default_factory=list)
    converting_sinks: list[tuple[int, int]] = field(default_factory=list)
    tracking_sinks: list[tuple[int, int]] = field(default_factory=list)
    firings: int = 0


class Coordinator:
    MAX_FIRINGS = 10_000

    def __init__(self, coordination: Coordination, flags: np.ndarray, flag_index: dict[str, int]):
        self.flags = flags
        self.nets: list[_Net] = []
        by_name: dict[str, _Net] = {}
        for name, spec in coordination.nets.items():
            places = list(spec.places)
            index = {p: i for i, p in enumerate(places)}
            transitions = [(t, [(index[p], w) for p, w in ts.inputs.items()], [(index[p], w) for p, w in ts.outputs.items()])
                           for t, ts in spec.transitions.items()]
            net = _Net(name, places, transitions, [spec.marking.get(p, 0) for p in places])
            self.nets.append(net)
            by_name[name] = net
        for fmap in coordination.flag_maps.values():
            net = by_name[fmap.net]
            index = {p: i for i, p in enumerate(net.places)}
            for kind in ("converting_sources", "tracking_sources", "converting_sinks", "tracking_sinks"):
                getattr(net, kind).extend((flag_index[f], index[p]) for f, p in getattr(fmap, kind).items())
        self._seen = flags.copy()
        self._changed = np.zeros_like(flags, dtype=bool)
        self._pending = True  # step at least once: initial markings may enable transitions

    def step(self) -> bool:
        """One coordination step; True if any marking or flag changed."""
        if not self._pending:
            np.not_equal(self.flags, self._seen, out=self._changed)
            if not self._changed.any():
                return False
        flags = self.flags
        # Snapshot before reading: a flag another thread sets during this step is then
        # seen as a change next cycle instead of being lost.
        self._seen[:] = flags
        pending = False
        for net in self.nets:
            marking = net.marking
            for f, p in net.converting_sources:
                if flags[f]:
                    flags[f] = 0
                    marking[p] += 1
            for f, p in net.tracking_sources:
                marking[p] = 1 if flags[f] else 0
            self._fire(net)
            for f, p in net.converting_sinks:
                if marking[p] > 0:
                    marking[p] -= 1
                    flags[f] = 1
                    pending = pending or marking[p] > 0
            for f, p in net.tracking_sinks:
                flags[f] = 1 if marking[p] > 0 else 0
        self._pending = pending
        return True

    def _fire(self, net: _Net) -> None:
        marking = net.marking
        fired = 0
        progressed = True
        while progressed:
            progressed = False
            for _, inputs, outputs in net.transitions:
                if all(marking[p] >= w for p, w in inputs):
                    for p, w in inputs:
                        marking[p] -= w
                    for p, w in outputs:
                        marking[p] += w
                    fired += 1
                    progressed = True
                    if fired > self.MAX_FIRINGS:
                        raise Livelock(f"net '{net.name}' fired {fired} times without reaching a steady state")
        net.firings += fired

    def markings(self) -> dict[str, dict[str, int]]:
        return {net.name: {p: n for p, n in zip(net.places, net.marking) if n} for net in self.nets}
