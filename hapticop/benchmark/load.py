"""Load on every core, bounded in time: the bench's 'loaded' condition without stress-ng.

Each worker is a plain (SCHED_OTHER) process that alternates numpy arithmetic on a few
megabytes (cache and memory traffic) with short sleeps and file-system calls (kernel entries),
and leaves by itself at its deadline, so a killed parent never leaves load behind.
"""

from __future__ import annotations

import multiprocessing
import os
import time


def _work(deadline: float) -> None:
    import numpy as np

    a = np.random.default_rng(os.getpid()).random((512, 512))
    b = np.empty_like(a)
    big = np.zeros(4_000_000 // 8)
    while time.monotonic() < deadline:
        np.matmul(a, a, out=b)
        big += 1.0  # stream through memory
        os.stat("/")
        if int(time.monotonic() * 1000) % 7 == 0:
            time.sleep(0.0002)


class Load:
    """`with Load(seconds):` keeps every CPU busy for at most `seconds`."""

    def __init__(self, seconds: float, workers: int | None = None):
        self.seconds = seconds
        self.workers = workers or os.cpu_count() or 1
        self.processes: list = []

    def __enter__(self) -> Load:
        context = multiprocessing.get_context("spawn")
        deadline = time.monotonic() + self.seconds
        self.processes = [context.Process(target=_work, args=(deadline,), daemon=True) for _ in range(self.workers)]
        for process in self.processes:
            process.start()
        return self

    def __exit__(self, *exc: object) -> None:
        for process in self.processes:
            process.terminate()
        for process in self.processes:
            process.join(5)
