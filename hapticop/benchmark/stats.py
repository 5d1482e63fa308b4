"""Statistics of recorded timing: percentiles from 1 us histograms, and the bench's goals.

Runs leave their histograms sparse in timing.json (`{"bin_us": count}`); cyclictest prints
them as `bin count` lines. Both become a `Distribution`, so every figure in a report is
computed one way, exactly to the bin.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from statistics import median

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
    """One line of the bench's goals: a figure, its limit, and whether it holds; `machine` is the
    same run's figure of the machine itself (cyclictest, the empty probe loop) where the limit
    is a multiple of it."""

    what: str
    value: float
    limit: float
    machine: float | None = None
    at_least: bool = False  # a floor (a speed), not a ceiling

    @property
    def ratio(self) -> float | None:
        """The figure as a multiple of the machine's own (None: an absolute goal)."""
        if self.machine is None:
            return None
        return self.value / self.machine if self.machine else math.inf

    @property
    def met(self) -> bool:
        if math.isnan(self.value):
            return False
        return self.value >= self.limit if self.at_least else self.value <= self.limit

    @property
    def by(self) -> float:
        """How far over the limit, as a ratio (1.3: 30 % over); NaN when there is no value."""
        return self.value / self.limit if self.limit else math.inf


MISSED_LIMIT_PERCENT = 0.1


def thread_goals(name: str, latency: dict[str, float], missed_pct: float,
                 baseline: dict[str, float] | None, probe_missed_pct: float | None = None,
                 probe_periods: int = 0) -> list[Goal]:
    """A 1 kHz thread against the same run's limits: wake-up p99 ≤ 1.5× and p99.9 ≤ 2× cyclictest's;
    missed deadlines ≤ 0.1 % and ≤ 2× the empty probe loop's (one missed period of the probe's
    at least, so a probe that missed nothing is not a limit of zero)."""
    goals = [Goal(f"{name}: missed deadlines %", missed_pct, MISSED_LIMIT_PERCENT)]
    if probe_missed_pct is not None and not math.isnan(probe_missed_pct):
        floor = 100.0 / probe_periods if probe_periods else 0.0
        machine = max(probe_missed_pct, floor)
        goals.append(Goal(f"{name}: missed deadlines % against the empty probe loop's", missed_pct, 2.0 * machine,
                          machine))
    if baseline:
        goals.insert(0, Goal(f"{name}: wake-up p99 (us)", latency["p99"], 1.5 * baseline["p99"], baseline["p99"]))
        goals.insert(1, Goal(f"{name}: wake-up p99.9 (us)", latency["p99.9"], 2.0 * baseline["p99.9"],
                             baseline["p99.9"]))
    return goals


def spread_text(values: list[float | None]) -> str:
    """A figure over several runs as 'median (min-max)', the one run's value, or '-' for none."""
    values = [v for v in values if v is not None]
    if not values:
        return "-"
    if len(values) == 1:
        return f"{values[0]:.3g}"
    return f"{median(values):.3g} ({min(values):.3g}-{max(values):.3g})"
