"""Place/transition nets as numpy arrays: the coordination engine of the mediator.

A transition is enabled when every input place holds at least its arc weight; firing
subtracts the input weights and adds the output weights. `fire_to_steady_state` fires
enabled transitions in declaration order, round after round, until none is enabled,
which is what the mediator does once per coordination step.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hapticop.composition.description import PetriNet


class Livelock(RuntimeError):
    """The net kept firing without reaching a steady state."""


@dataclass(frozen=True)
class CompiledNet:
    places: tuple[str, ...]
    transitions: tuple[str, ...]
    pre: np.ndarray  # (transitions, places) tokens consumed
    post: np.ndarray  # (transitions, places) tokens produced
    initial: np.ndarray  # (places,)

    @classmethod
    def from_spec(cls, spec: PetriNet) -> "CompiledNet":
        places = tuple(spec.places)
        index = {name: i for i, name in enumerate(places)}
        transitions = tuple(spec.transitions)
        pre = np.zeros((len(transitions), len(places)), dtype=np.int64)
        post = np.zeros_like(pre)
        for t, name in enumerate(transitions):
            for pname, weight in spec.transitions[name].inputs.items():
                pre[t, index[pname]] = weight
            for pname, weight in spec.transitions[name].outputs.items():
                post[t, index[pname]] = weight
        initial = np.zeros(len(places), dtype=np.int64)
        for pname, tokens in spec.marking.items():
            initial[index[pname]] = tokens
        return cls(places, transitions, pre, post, initial)

    def index(self, place_name: str) -> int:
        return self.places.index(place_name)

    def enabled(self, marking: np.ndarray) -> np.ndarray:
        """Boolean mask of the transitions enabled in `marking`."""
        return np.all(marking >= self.pre, axis=1)

    def fire(self, marking: np.ndarray, t: int) -> None:
        """Fire transition `t` in place."""
        marking -= self.pre[t]
        marking += self.post[t]

    def fire_to_steady_state(self, marking: np.ndarray, max_firings: int = 10_000) -> int:
        """Fire in declaration order until no transition is enabled; returns the count."""
        fired = 0
        while True:
            progressed = False
            for t in range(len(self.transitions)):
                if np.all(marking >= self.pre[t]):
                    self.fire(marking, t)
                    fired += 1
                    progressed = True
                    if fired > max_firings:
                        raise Livelock(f"more than {max_firings} firings without a steady state")
            if not progressed:
                return fired
