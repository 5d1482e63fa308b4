"""Timing statistics read off microsecond histograms.

A 1 kHz loop cannot keep a list of its latencies, so every thread and activity counts them
in a fixed histogram of 1 us bins (the last bin holds everything longer) and keeps the exact
maximum (`tallies.Histograms`, one array increment per count). Percentiles are read off the
histogram when someone asks: exact to 1 us.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

BINS = 20_000  # 0 .. 19.999 ms in 1 us bins; the last bin collects longer ones


def percentile_us(histogram: np.ndarray, q: float) -> float:
    """The q-th percentile (0-100) in microseconds, to the 1 us bin; NaN when empty."""
    total = int(histogram.sum())
    if total == 0:
        return float("nan")
    rank = max(1, int(np.ceil(q / 100.0 * total)))
    return float(np.searchsorted(np.cumsum(histogram), rank))


@dataclass(frozen=True)
class Summary:
    count: int
    p50_us: float
    p99_us: float
    p999_us: float
    max_us: float

    @classmethod
    def of(cls, histogram: np.ndarray, maximum_ns: int) -> Summary:
        return cls(
            count=int(histogram.sum()),
            p50_us=percentile_us(histogram, 50),
            p99_us=percentile_us(histogram, 99),
            p999_us=percentile_us(histogram, 99.9),
            max_us=maximum_ns / 1000.0 if histogram.sum() else float("nan"),
        )
