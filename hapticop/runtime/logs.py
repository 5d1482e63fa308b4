"""Logging with the thesis's five levels that never blocks a cyclic thread.

A log call below the owner's level costs one integer comparison. Otherwise it puts one
tuple on a lock-free queue (`SimpleQueue.put`) and returns; a writer thread per process
formats the lines and appends them to one file per thread or activity in the run
directory, which defaults to a tmpfs (`/dev/shm`) as the thesis advises (`rundirs`). Errors and
warnings are echoed to the console by the writer, not by the caller.
"""

from __future__ import annotations

import queue
import sys
import threading
from collections.abc import Callable
from enum import IntEnum
from pathlib import Path
from typing import TextIO


class Level(IntEnum):
    ALWAYS = 0
    ERROR = 1
    WARNING = 2
    INFO = 3
    DEBUG = 4


LEVEL_NAMES = [level.name.lower() for level in Level]


def format_line(stamp_ns: int, level: Level, text: str) -> str:
    """One record as its line in an owner's file: seconds on the run's clock, level, text."""
    return f"{stamp_ns / 1e9:.6f} {LEVEL_NAMES[level]:7s} {text}\n"


def parse_line(line: str) -> tuple[int, Level, str] | None:
    """A line `format_line` wrote, back as (stamp in ns, level, text); None for any other line
    (the second line of a message with a line break in it)."""
    stamp, _, rest = line.partition(" ")
    level = rest[:7].rstrip()
    if level not in LEVEL_NAMES or not stamp.replace(".", "", 1).isdigit():
        return None
    seconds, _, fraction = stamp.partition(".")
    return int(seconds) * 1_000_000_000 + int(fraction.ljust(9, "0")[:9]), Level(LEVEL_NAMES.index(level)), rest[8:]


class LogWriter:
    """Drains the queue of one process into per-owner files."""

    def __init__(self, run_dir: Path, echo: TextIO | None = sys.stderr, echo_level: Level = Level.WARNING):
        self.run_dir = run_dir
        self.queue: queue.SimpleQueue = queue.SimpleQueue()
        self.echo, self.echo_level = echo, echo_level
        self._files: dict[str, TextIO] = {}
        self._thread = threading.Thread(target=self._drain, name="hapticop-log", daemon=True)
        self._stopped = False

    def start(self) -> LogWriter:
        self.run_dir.mkdir(mode=0o700, parents=True, exist_ok=True)
        self._thread.start()
        return self

    def logger(self, owner: str, level: Level, clock_ns: Callable[[], int]) -> Logger:
        return Logger(owner, level, self.queue, clock_ns)

    def _file(self, owner: str) -> TextIO:
        handle = self._files.get(owner)
        if handle is None:
            handle = self._files[owner] = open(self.run_dir / f"{owner}.log", "a", buffering=1 << 16)
        return handle

    def _write(self, item: tuple) -> None:
        stamp_ns, owner, level, message, args = item
        try:
            text = message % args if args else message
        except (TypeError, ValueError):
            text = f"{message} {args!r}"
        self._file(owner).write(format_line(stamp_ns, level, text))
        if self.echo is not None and level <= self.echo_level:
            self.echo.write(f"[{owner}] {LEVEL_NAMES[level]}: {text}\n")

    def _drain(self) -> None:
        while True:
            item = self.queue.get()
            if item is None:
                break
            if isinstance(item, threading.Event):  # `flush`'s marker: everything before it is written
                self._flush_files()
                item.set()
                continue
            self._write(item)
            if self.queue.empty():
                self._flush_files()

    def _flush_files(self) -> None:
        for handle in self._files.values():
            handle.flush()

    def flush(self, timeout_s: float = 10.0) -> bool:
        """Wait until every line queued before this call is in its file (what follows the files, the
        recorder's last look, must not miss a line still in the queue); False if that took over `timeout_s`."""
        if self._stopped or not self._thread.is_alive():
            return True
        written = threading.Event()
        self.queue.put(written)
        return written.wait(timeout_s)

    def stop(self) -> None:
        if self._stopped:
            return
        self._stopped = True
        self.queue.put(None)
        if self._thread.is_alive():
            self._thread.join(timeout=5)
        for handle in self._files.values():
            handle.close()
        self._files.clear()


class Logger:
    """What a thread or an activity logs through."""

    __slots__ = ("owner", "level", "_queue", "_now")

    def __init__(self, owner: str, level: Level, sink: queue.SimpleQueue, clock_ns: Callable[[], int]):
        self.owner, self.level, self._queue, self._now = owner, level, sink, clock_ns

    def _log(self, level: Level, message: str, args: tuple) -> None:
        if level <= self.level:
            self._queue.put((self._now(), self.owner, level, message, args))

    def always(self, message: str, *args: object) -> None:
        self._log(Level.ALWAYS, message, args)

    def error(self, message: str, *args: object) -> None:
        self._log(Level.ERROR, message, args)

    def warning(self, message: str, *args: object) -> None:
        self._log(Level.WARNING, message, args)

    def info(self, message: str, *args: object) -> None:
        self._log(Level.INFO, message, args)

    def debug(self, message: str, *args: object) -> None:
        self._log(Level.DEBUG, message, args)
