"""The framework's own work per cycle of each 1 kHz loop, measured on the virtual clock.

The composition runs in this process on the virtual clock (every thread stepped in file
order at its deadlines, as the virtual-clock scheduler does). Once every loop runs, each
thread's `cycle()` is timed, and so is every block hook it calls (compute, flush); the
framework's overhead is the cycle less its hooks: LCSM steps, input refreshes, origin
merges, compute-time records, the schedule walk, and the main thread's supervision. A block
publishes inside its hook, so a publish counts as the block's (`publish_us` times one). Both
are the thread's CPU time, which a busy machine's preemptions do not stretch (its caches
still do: compare figures of one run); each timed hook adds a clock read, under 1 us.
"""

from __future__ import annotations

import tempfile
import time
from pathlib import Path

import numpy as np

WARM_CYCLES = 3_000  # homed, driving, every loop running


class _HookTimer:
    """Wraps a hook and adds its duration to its thread's running total."""

    __slots__ = ("hook", "totals", "row")

    def __init__(self, hook, totals: np.ndarray, row: int):
        self.hook, self.totals, self.row = hook, totals, row

    def __call__(self):
        started = time.thread_time_ns()
        result = self.hook()
        self.totals[self.row] += time.thread_time_ns() - started
        return result


def measure(path: Path, cycles: int = 3_000, warm: int = WARM_CYCLES) -> dict[str, dict[str, float]]:
    """Per 1 kHz thread of the system (threads of simulators only, and empty ones, set aside):
    cycle and framework time (p50, p99, us) over `cycles` steady cycles."""
    from hapticop.testing import stepped_system
    from hapticop.validation import validate_path

    validated = validate_path(path)
    if not validated.report.ok:
        raise ValueError(f"{path} is not valid")
    with tempfile.TemporaryDirectory() as run_dir, stepped_system(validated, Path(run_dir)) as (system, threads):
        names = list(threads)
        periods = {name: threads[name].period for name in names}
        hooks = np.zeros(len(names), dtype=np.int64)
        for row, name in enumerate(names):
            for runner in threads[name].runners.values():
                runner.lifecycle.hooks.compute = _HookTimer(runner.lifecycle.hooks.compute, hooks, row)
                runner.block.flush = _HookTimer(runner.block.flush, hooks, row)
        total = np.zeros((cycles, len(names)), dtype=np.int64)
        inside = np.zeros((cycles, len(names)), dtype=np.int64)
        system.start_threads()
        due = dict.fromkeys(names, 0)
        for i in range(warm + cycles):
            now = i * 1_000_000
            system.clock.advance_to(now)
            for row, name in enumerate(names):
                if now < due[name]:
                    continue
                due[name] = now + periods[name]
                hooks[row] = 0
                started = time.thread_time_ns()
                threads[name].cycle()
                took = time.thread_time_ns() - started
                if i >= warm:
                    total[i - warm, row], inside[i - warm, row] = took, hooks[row]
    found = {}
    for row, name in enumerate(names):
        runners = threads[name].runners.values()
        if periods[name] != 1_000_000 or not runners or all(runner.simulator for runner in runners):
            continue
        framework = (total[:, row] - inside[:, row]) / 1000
        found[name] = {"activities": len(threads[name].runners),
                       "cycle_p50": float(np.percentile(total[:, row], 50) / 1000),
                       "cycle_p99": float(np.percentile(total[:, row], 99) / 1000),
                       "framework_p50": float(np.percentile(framework, 50)),
                       "framework_p99": float(np.percentile(framework, 99))}
    return found


def publish_us(repeat: int = 20_000) -> float:
    """One publish of a 3-vector to one latest slot (the commonest port), in us."""
    from hapticop.blocks.interface import Port
    from hapticop.runtime.context import OutputPort
    from hapticop.runtime.streams import LatestSlot, latest_nbytes

    spec = Port(shape=(3,), dtype="float64")
    port = OutputPort("force", spec, time.monotonic_ns)
    port.transports.append(LatestSlot(bytearray(latest_nbytes(spec)), spec))
    started = time.thread_time_ns()
    for _ in range(repeat):
        port.publish()
    return (time.thread_time_ns() - started) / repeat / 1000
