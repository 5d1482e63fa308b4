"""The time a virtual USB Falcon lives in: simulated seconds, or the monotonic clock.

The virtual device asks its clock for `now()` and calls `sleep(s)` when a read waits for the
chip. `VirtualClock` only moves on those sleeps, so tests run deterministic and instant;
`WallClock` really sleeps, so a benchmark sees the loop rate the latency timer allows.
"""

from __future__ import annotations

import time

__all__ = ["VirtualClock", "WallClock"]


class VirtualClock:
    """Simulated seconds that advance only when someone sleeps."""

    def __init__(self, start: float = 0.0) -> None:
        self.t = float(start)

    def now(self) -> float:
        return self.t

    def sleep(self, seconds: float) -> None:
        if seconds > 0:
            self.t += seconds


class WallClock:
    """The monotonic clock, with real sleeps (for benchmarks)."""

    now = staticmethod(time.monotonic)

    @staticmethod
    def sleep(seconds: float) -> None:
        if seconds > 0:
            time.sleep(seconds)
