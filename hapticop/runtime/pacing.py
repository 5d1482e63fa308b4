"""When a thread cycles under the virtual clock, if not every period: a replay's recorded cycles.

A replay runs its rewritten composition on the ordinary runtime (`observe.rewrite`); only the
times differ. A wall-clock run missed cycles and was woken late, so the replayed activity's thread
cycles at the recorded times instead, and just before each cycle the pacing puts back what that
cycle started from (requests, flags, parameters handed over). Nothing else of the run knows.
"""

from __future__ import annotations

from typing import Protocol


class Pacing(Protocol):
    """Told by the virtual-clock scheduler about the threads it paces (`RunOptions.pacing`)."""

    def next_ns(self, thread: str, deadline_ns: int, period_ns: int, running: bool) -> int:
        """The thread's next cycle after the one at `deadline_ns` (`running`: it runs its schedule)."""

    def before(self, thread: str, now_ns: int) -> None:
        """Just before the thread's cycle at `now_ns`."""
