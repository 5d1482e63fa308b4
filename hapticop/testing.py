"""Measuring small calls: microseconds per call, and what they leave allocated.

Shared by the benchmark scripts in bench/ (which report figures) and by tests (which
check allocations, never times).
"""

from __future__ import annotations

import time
import tracemalloc
from collections.abc import Callable

import numpy as np


def allocation_stats(fn: Callable[[], object], calls: int = 1000, warmup: int = 10) -> tuple[int, int]:
    """(bytes still allocated after `calls` calls, peak bytes during them), by tracemalloc."""
    for _ in range(warmup):
        fn()
    tracemalloc.start()
    try:
        before, _ = tracemalloc.get_traced_memory()
        tracemalloc.reset_peak()
        for _ in range(calls):
            fn()
        after, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    return after - before, peak - before


def time_per_call(fn: Callable[[], object], calls: int = 5000) -> tuple[float, float]:
    """(median, p99) microseconds per call, after a warm-up."""
    for _ in range(200):
        fn()
    samples = np.empty(calls)
    clock = time.perf_counter_ns
    for i in range(calls):
        started = clock()
        fn()
        samples[i] = clock() - started
    return float(np.median(samples)) / 1e3, float(np.percentile(samples, 99)) / 1e3


def grown_bytes(run: Callable[[], object]) -> int:
    """Bytes one call of `run` left allocated, summed over the files where allocation grew
    (tracemalloc snapshots before and after; warm up before calling this)."""
    tracemalloc.start()
    try:
        before = tracemalloc.take_snapshot()
        run()
        after = tracemalloc.take_snapshot()
    finally:
        tracemalloc.stop()
    return sum(stat.size_diff for stat in after.compare_to(before, "filename") if stat.size_diff > 0)
