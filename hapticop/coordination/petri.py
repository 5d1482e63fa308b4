"""Place/transition nets, compiled once: fired by the mediator's coordinator, explored by validation.

A transition is enabled when every input place holds at least its arc weight and every
place of its inhibitor arcs (`unless:`) is empty; firing subtracts the input weights and adds
the output weights. `fire_to_steady_state` fires
enabled transitions in declaration order, round after round, until none is enabled: the
coordinator does that once per coordination step, on a marking it keeps as a Python list
(no allocation per cycle), and `validation/reachability` explores the same arcs through
the matrices `pre` and `post`.
"""

from __future__ import annotations

from collections.abc import MutableSequence
from dataclasses import dataclass

import numpy as np

from hapticop.composition.description import PetriNet

MAX_FIRINGS = 10_000
"""Firings within one step beyond which a net counts as livelocked."""

Arcs = tuple[tuple[int, int], ...]  # (place index, weight)


class Livelock(RuntimeError):
    """The net kept firing without reaching a steady state."""


@dataclass(frozen=True)
class Net:
    name: str
    places: tuple[str, ...]
    transitions: tuple[str, ...]
    arcs: tuple[tuple[Arcs, Arcs, tuple[int, ...]], ...]  # per transition: takes from, puts into, needs empty
    pre: np.ndarray  # (transitions, places) tokens consumed
    post: np.ndarray  # (transitions, places) tokens produced
    initial: np.ndarray  # (places,)
    inhibit: np.ndarray  # (transitions, places) True where the place must be empty

    @classmethod
    def from_spec(cls, spec: PetriNet, name: str = "") -> Net:
        places = tuple(spec.places)
        index = {place: i for i, place in enumerate(places)}
        transitions = tuple(spec.transitions)
        arcs = tuple((tuple((index[p], w) for p, w in spec.transitions[t].inputs.items()),
                      tuple((index[p], w) for p, w in spec.transitions[t].outputs.items()),
                      tuple(index[p] for p in spec.transitions[t].inhibitors)) for t in transitions)
        pre = np.zeros((len(transitions), len(places)), dtype=np.int64)
        post = np.zeros_like(pre)
        inhibit = np.zeros(pre.shape, dtype=bool)
        for t, (inputs, outputs, empty) in enumerate(arcs):
            for p, weight in inputs:
                pre[t, p] = weight
            for p, weight in outputs:
                post[t, p] = weight
            inhibit[t, list(empty)] = True
        initial = np.zeros(len(places), dtype=np.int64)
        for place, tokens in spec.marking.items():
            initial[index[place]] = tokens
        return cls(name, places, transitions, arcs, pre, post, initial, inhibit)

    def index(self, place_name: str) -> int:
        return self.places.index(place_name)

    def enabled(self, marking: np.ndarray) -> np.ndarray:
        """Boolean mask of the transitions enabled in `marking`."""
        return np.all(marking >= self.pre, axis=1) & ~np.any(self.inhibit & (marking > 0), axis=1)

    def fire_to_steady_state(self, marking: MutableSequence[int], max_firings: int = MAX_FIRINGS) -> int:
        """Fire in declaration order until no transition is enabled, changing `marking` in
        place (a list or an array); returns the count, or raises `Livelock`."""
        fired = 0
        progressed = True
        while progressed:
            progressed = False
            for inputs, outputs, empty in self.arcs:
                if all(marking[p] >= w for p, w in inputs) and not any(marking[p] for p in empty):
                    for p, w in inputs:
                        marking[p] -= w
                    for p, w in outputs:
                        marking[p] += w
                    fired += 1
                    progressed = True
                    if fired > max_firings:
                        raise Livelock(f"net '{self.name}' fired more than {max_firings} times without reaching "
                                       "a steady state")
        return fired
