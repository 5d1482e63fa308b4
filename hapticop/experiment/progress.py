"""What a study has done so far: runs done, failed, the rate and the time left. A bar on a terminal, a
plain line every few seconds otherwise (CI logs, `nohup`)."""

from __future__ import annotations

import sys
import time
from typing import TextIO


class Progress:
    def __init__(self, total: int, skipped: int, stream: TextIO | None = None, every_s: float = 5.0):
        self.total, self.skipped = total, skipped
        self.done = self.failed = 0
        self.stream = stream or sys.stderr
        self.tty = self.stream.isatty()
        self.every_s = every_s
        self.started = time.monotonic()
        self.last = 0.0

    def update(self, failed: bool) -> None:
        self.done += 1
        self.failed += int(failed)
        now = time.monotonic()
        if self.tty or now - self.last >= self.every_s or self.done + self.skipped == self.total:
            self.last = now
            self.stream.write(("\r" if self.tty else "") + self.line() + ("" if self.tty else "\n"))
            self.stream.flush()

    def line(self) -> str:
        elapsed = max(time.monotonic() - self.started, 1e-9)
        rate = self.done / elapsed * 60
        left = self.total - self.skipped - self.done
        eta = left / (self.done / elapsed) if self.done else float("nan")
        finished = self.skipped + self.done
        width = 30
        filled = int(width * finished / self.total) if self.total else width
        bar = f"[{'#' * filled}{'.' * (width - filled)}] " if self.tty else ""
        return (f"{bar}{finished}/{self.total} runs ({self.skipped} from before), {self.failed} failed, "
                f"{rate:.1f} runs/min, {_clock(eta)} left")

    def close(self) -> None:
        if self.tty:
            self.stream.write("\n")


def _clock(seconds: float) -> str:
    if seconds != seconds:
        return "?"
    minutes, s = divmod(int(seconds), 60)
    hours, minutes = divmod(minutes, 60)
    return f"{hours}:{minutes:02d}:{s:02d}"
