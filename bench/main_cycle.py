"""Benchmark: where the main (1 kHz) loop's cycle goes, activity by activity, without the machine's noise.

    python bench/main_cycle.py systems/hallway.yaml --cycles 20000 [--thread main] [--profile FILE]

The composition is stepped on the virtual clock in this process, as `hapticop bench`'s overhead
figure is (hapticop/benchmark/overhead.py); each activity's compute and flush are timed in thread
CPU time (a busy machine's preemptions do not stretch it; its caches still do), and the rest of
the cycle is the framework's. With --profile, the thread's steady cycles are also run under cProfile into FILE.
"""

from __future__ import annotations

import argparse
import cProfile
import os
import tempfile
import time
from pathlib import Path

import numpy as np

WARM = 3_000


class _Timed:
    """A hook timed into one cell of the current cycle's row."""

    __slots__ = ("hook", "row", "col")

    def __init__(self, hook, row: np.ndarray, col: int):
        self.hook, self.row, self.col = hook, row, col

    def __call__(self):
        started = time.thread_time_ns()
        result = self.hook()
        self.row[self.col] += time.thread_time_ns() - started
        return result


def main() -> None:
    from hapticop.testing import stepped_system
    from hapticop.validation import validate_path

    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("file", type=Path, nargs="?", default=Path("systems/hallway.yaml"))
    parser.add_argument("--cycles", type=int, default=20_000)
    parser.add_argument("--thread", default="main")
    parser.add_argument("--profile", type=Path)
    args = parser.parse_args()
    validated = validate_path(args.file)
    assert validated.report.ok, validated.report.errors
    with tempfile.TemporaryDirectory() as run_dir, stepped_system(validated, Path(run_dir)) as (system, threads):
        names = list(threads)
        mine = threads[args.thread]
        columns = []
        row = np.zeros(2 * len(mine.runners), dtype=np.int64)
        for name, runner in mine.runners.items():
            runner.lifecycle.hooks.compute = _Timed(runner.lifecycle.hooks.compute, row, len(columns))
            columns.append(f"{name}.compute")
            runner.block.flush = _Timed(runner.block.flush, row, len(columns))
            columns.append(f"{name}.flush")
        hooks = np.zeros((args.cycles, len(columns)), dtype=np.int64)
        total = np.zeros(args.cycles, dtype=np.int64)
        due = dict.fromkeys(names, 0)
        profiler = cProfile.Profile() if args.profile else None
        system.start_threads()
        for i in range(WARM + args.cycles):
            now = i * 1_000_000
            system.clock.advance_to(now)
            for name in names:
                if now < due[name]:
                    continue
                due[name] = now + threads[name].period
                if name != args.thread:
                    threads[name].cycle()
                    continue
                row[:] = 0
                if profiler is not None and i >= WARM:
                    profiler.enable()
                started = time.thread_time_ns()
                mine.cycle()
                took = time.thread_time_ns() - started
                if profiler is not None and i >= WARM:
                    profiler.disable()
                if i >= WARM:
                    total[i - WARM], hooks[i - WARM] = took, row
    if profiler is not None:
        profiler.dump_stats(args.profile)
    us = hooks / 1000
    framework = total / 1000 - us.sum(axis=1)
    print(f"{args.file} thread {args.thread}: {args.cycles} cycles, load {os.getloadavg()[0]:.1f}")
    print("| part | p50 us | p99 us | max us | mean us |")
    print("|---|---|---|---|---|")
    for col, name in enumerate(columns):
        values = us[:, col]
        if values.max() > 0.5:
            print(f"| {name} | {np.percentile(values, 50):.1f} | {np.percentile(values, 99):.1f} | "
                  f"{values.max():.1f} | {values.mean():.1f} |")
    for name, values in (("framework", framework), ("cycle", total / 1000)):
        print(f"| {name} | {np.percentile(values, 50):.1f} | {np.percentile(values, 99):.1f} | "
              f"{values.max():.1f} | {values.mean():.1f} |")


if __name__ == "__main__":
    main()
