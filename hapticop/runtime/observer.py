"""What a run tells whoever watches it: the one small interface between the runtime and observation.

The runtime records nothing and serves nothing itself. A run hands an `Observer` the few moments
observation needs, and nothing else: what to reserve in the shared region before it is laid out,
the start, the gaps between two main-thread cycles, a stream added live, the events of the run
(mode switches, flag changes, life-cycle transitions, parameter changes) and the stop. The
recorder, its taps, the timing and log channels and the live view live in `hapticop.observe`,
above the runtime; the runtime imports none of them, and a run without an observer gives its
loops nothing more to do.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Protocol

from hapticop.composition.loader import Loaded
from hapticop.runtime.logs import Logger
from hapticop.runtime.region import Region, Transport


@dataclass(frozen=True)
class ObservedRun:
    """What an observer sees of the run it watches, once the region is made."""

    loaded: Loaded
    tree: Any  # the composition as it runs (`extends` resolved), for the record
    file: str
    name: str
    region: Region
    clock: Callable[[], int]
    virtual: bool
    seed: int
    run_dir: Path
    log: Logger  # the run's `system` log


class Observer(Protocol):
    """Called by the main process's run, never by a real-time loop but the main thread between cycles.

    `event(kind, payload, time_ns)` is the generic hook for what happens to a run rather than in a
    stream: `kind` names it ("mode", "flag", "lifecycle", "parameters", ...), `payload` is JSON-able
    data (a dict of plain values), `time_ns` the run's clock when it happened. An observer turns
    each kind into a channel of its own (as ROS 2 publishes /parameter_events); kinds it does not
    know it records the same way, so a new kind needs no change here.
    """

    def composition(self, tree: Any, loaded: Loaded) -> tuple[Any, Loaded]:
        """The composition as the run should be observed (unchanged, or recording every stream)."""

    def rings(self, loaded: Loaded) -> dict[str, int]:
        """The recorder ring each stream gets in the region, by capacity (none: `{}`); asked at
        start-up for the layout and again for each stream added live."""

    def start(self, run: ObservedRun) -> None:
        """The region is laid out and made; nothing runs yet. Starts what may take a while."""

    def ready(self) -> list[str]:
        """Just before the loops run, once started: what went wrong, for the run's reasons (the run
        goes on unobserved)."""

    def between_cycles(self) -> None:
        """Between two main-thread cycles (the virtual clock drains here)."""

    def stream_added(self, loaded: Loaded, stream: str, ring: Transport) -> None:
        """A stream added live got the recorder ring `rings` asked for, at `ring`."""

    def event(self, kind: str, payload: dict, time_ns: int) -> None:
        """Something happened to the run (see the class's docstring); on the main thread, never on a loop."""

    def stop(self) -> tuple[dict | None, str | None]:
        """The loops are done: (what was observed, what went wrong)."""


STANDARD = "hapticop.observe.observation:Observation"
"""The observer a run gets unless it is given one: named, not imported, so that the runtime stays below
the observation wing in the import graph (the block registry finds blocks the same way)."""


def standard_observer(record: str | None, view: Any) -> Observer:
    """What the composition's `record:` and the run's `--record` and `--view` ask for."""
    module, _, name = STANDARD.partition(":")
    return getattr(importlib.import_module(module), name)(record, view)
