"""Where each loop's deadlines fall: one grid for the whole system, loops staggered on it.

Every real-time loop, in whatever process, counts its deadlines from one epoch the main
process writes into the region, so their relative phases hold for the whole run. With
`phase: auto` the threads of equal period are spread evenly over it (real-time threads
first, highest priority first): two 1 kHz loops on a 2-core machine then wake 0.5 ms apart
instead of competing for the same instant, and data written by the first is fresh when the
second reads it.
"""

from __future__ import annotations

from collections import defaultdict

from hapticop.composition.description import Composition

START_MARGIN_NS = 2_000_000
"""The first deadline is at least this far ahead: time to finish setting up."""


def phases(composition: Composition) -> dict[str, int]:
    """Offset of each thread's deadlines from the epoch, in ns, within its period."""
    result: dict[str, int] = {}
    by_period: dict[int, list[str]] = defaultdict(list)
    for name, spec in composition.threads.items():
        if spec.phase == "auto":
            by_period[spec.period].append(name)
        else:
            result[name] = spec.phase
    order = list(composition.threads)
    for period, names in by_period.items():
        names.sort(key=lambda n: (composition.threads[n].priority is None, -(composition.threads[n].priority or 0),
                                  order.index(n)))
        for rank, name in enumerate(names):
            result[name] = rank * period // len(names)
    return result


def first_deadline(epoch_ns: int, period_ns: int, phase_ns: int, now_ns: int) -> int:
    """The first deadline on the thread's grid at least `START_MARGIN_NS` after `now_ns`."""
    earliest = now_ns + START_MARGIN_NS
    base = epoch_ns + phase_ns
    if earliest <= base:
        return base
    return base + -(-(earliest - base) // period_ns) * period_ns


def thread_start(composition: Composition, thread: str, epoch_ns: int, now_ns: int) -> int:
    """When a real-time thread, in whatever process, first runs: its first deadline on its grid."""
    return first_deadline(epoch_ns, composition.threads[thread].period, phases(composition)[thread], now_ns)
