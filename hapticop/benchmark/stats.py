"""Statistics of recorded timing: percentiles from 1 us histograms, and the bench's goals.

Runs leave their histograms sparse in timing.json (`{"bin_us": count}`); cyclictest prints
them as `bin count` lines. Both become a `Distribution`, so every figure in a report is
computed one way, exactly to the bin.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from hapticop.runtime.timing import percentile_us


@dataclass(frozen=True)
class Distribution:
    """A latency histogram in 1 us bins, and the exact maximum when it is known."""

    counts: np.ndarray  # counts[k] = samples in [k, k+1) us
    max_us: float | None = None

    @classmethod
    def from_sparse(cls, sparse: dict[str, int], max_us: float | None = None) -> Distribution:
        if not sparse:
            return cls(np.zeros(1, dtype=np.int64), max_us)
        bins = np.fromiter((int(k) for k in sparse), dtype=np.int64, count=len(sparse))
        counts = np.zeros(int(bins.max()) + 1, dtype=np.int64)
        np.add.at(counts, bins, np.fromiter(sparse.values(), dtype=np.int64, count=len(sparse)))
        return cls(counts, max_us)

    @property
    def count(self) -> int:
        return int(self.counts.sum())

    def percentile(self, q: float) -> float:
        """The smallest bin holding the ceil(q % of n)-th sample; NaN when empty (as the runtime reads its own)."""
        return percentile_us(self.counts, q)

    @property
    def maximum(self) -> float:
        if self.max_us is not None:
            return self.max_us
        nonzero = np.flatnonzero(self.counts)
        return float(nonzero[-1]) if nonzero.size else math.nan

    def summary(self) -> dict[str, float]:
        return {"p50": self.percentile(50), "p99": self.percentile(99), "p99.9": self.percentile(99.9),
                "max": self.maximum}

    def __add__(self, other: Distribution) -> Distribution:
        size = max(self.counts.size, other.counts.size)
        counts = np.zeros(size, dtype=np.int64)
        counts[: self.counts.size] += self.counts
        counts[: other.counts.size] += other.counts
        maxima = [m for m in (self.max_us, other.max_us) if m is not None]
        return Distribution(counts, max(maxima) if maxima else None)


def missed_percent(cycles: int, missed: int) -> float:
    """Share of periods that had no cycle on time: a missed period is one that was skipped."""
    periods = cycles + missed
    return 100.0 * missed / periods if periods else math.nan


@dataclass(frozen=True)
class Goal:
    """One line of the bench's goals: a figure, its limit, and whether it holds."""

    what: str
    value: float
    limit: float

    @property
    def met(self) -> bool:
        return not math.isnan(self.value) and self.value <= self.limit

    @property
    def by(self) -> float:
        """How far over the limit, as a ratio (1.3: 30 % over); NaN when there is no value."""
        return self.value / self.limit if self.limit else math.inf


def thread_goals(name: str, latency: dict[str, float], missed_pct: float,
                 baseline: dict[str, float] | None) -> list[Goal]:
    """A 1 kHz thread against cyclictest: p99 ≤ 1.5×, p99.9 ≤ 2×, missed ≤ 0.05 %."""
    goals = [Goal(f"{name}: missed deadlines %", missed_pct, 0.05)]
    if baseline:
        goals.insert(0, Goal(f"{name}: wake-up p99 (us)", latency["p99"], 1.5 * baseline["p99"]))
        goals.insert(1, Goal(f"{name}: wake-up p99.9 (us)", latency["p99.9"], 2.0 * baseline["p99.9"]))
    return goals
