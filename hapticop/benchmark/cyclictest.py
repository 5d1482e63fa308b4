"""cyclictest (Debian rt-tests) beside a run: the machine's own wake-up latency, measured the standard way."""

from __future__ import annotations

import shutil
import subprocess

import numpy as np

from hapticop.benchmark.stats import Distribution

HISTOGRAM_US = 20_000


def available() -> bool:
    return shutil.which("cyclictest") is not None


def command(seconds: float, priority: int = 80) -> list[str]:
    """One 1 kHz measuring thread per CPU at `priority`, memory locked, histogram in 1 us bins."""
    return ["cyclictest", "--mlockall", "--smp", f"--priority={priority}", "--interval=1000",
            f"--duration={max(1, round(seconds))}", "--quiet", f"--histogram={HISTOGRAM_US}"]


def parse(output: str) -> Distribution:
    """All threads' histograms summed; overflows land in the last bin; the maximum is cyclictest's own."""
    counts = np.zeros(HISTOGRAM_US + 1, dtype=np.int64)
    maximum = None
    for line in output.splitlines():
        if line.startswith("#"):
            label, _, values = line[1:].partition(":")
            numbers = [int(v) for v in values.split() if v.lstrip("-").isdigit()]
            if label.strip() == "Max Latencies" and numbers:
                maximum = float(max(numbers))
            elif label.strip() == "Histogram Overflows" and numbers:
                counts[-1] += sum(numbers)
            continue
        parts = line.split()
        if len(parts) >= 2 and parts[0].isdigit() and int(parts[0]) <= HISTOGRAM_US:
            counts[int(parts[0])] += sum(int(v) for v in parts[1:] if v.isdigit())
    return Distribution(counts, maximum)


class Cyclictest:
    """Started beside a run, collected after it; no timing of its own is asserted anywhere."""

    def __init__(self, seconds: float, priority: int = 80):
        self.process = subprocess.Popen(command(seconds, priority), stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                                        text=True)

    def result(self) -> Distribution:
        out, err = self.process.communicate()
        if self.process.returncode != 0:
            raise RuntimeError(f"cyclictest failed ({self.process.returncode}): {err.strip()[:300]}")
        return parse(out)
