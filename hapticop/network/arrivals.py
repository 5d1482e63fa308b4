"""What a receiving bridge does with each sample of a network stream, by its sequence number.

Samples may arrive late, twice or out of order. A stream keeps only samples newer than the last
one it delivered: a late one (an older sequence number) is dropped, a duplicate too, and the
sequence numbers skipped are counted as lost (a reordered sample arriving after them is late, not
lost, so the count is an upper bound of the link's loss).

A sample too far ahead is refused too: no sender's sequence runs faster than `MAX_RATE_HZ` since the
last one delivered (plus `JUMP` for a burst), so a jump beyond that is not the owner's stream going on
(a forged sample 10^7 ahead would otherwise make every true one after it look old). A restart of the
sender is a new session (a new session number, `restart`), not a jump.
"""

from __future__ import annotations

JUMP = 1024  # sequence numbers a burst may skip at once
MAX_RATE_HZ = 10_000  # faster than any loop writes: the most a sequence can advance per second


class Arrivals:
    """The order check of one received stream."""

    def __init__(self) -> None:
        self.last = -1  # the newest sequence number delivered
        self.delivered = 0
        self.late = 0  # older than one delivered, or a duplicate: dropped
        self.skipped = 0  # sequence numbers never delivered
        self.ahead = 0  # too far ahead of the last one delivered: refused
        self.last_ns = 0  # when the last one was delivered

    def accept(self, sequence: int, now_ns: int = 0) -> bool:
        """True when the sample is newer than every one delivered (deliver it), else False."""
        if sequence <= self.last:
            self.late += 1
            return False
        if self.last >= 0 and sequence - self.last > JUMP + max(0, now_ns - self.last_ns) * MAX_RATE_HZ // 10**9:
            self.ahead += 1
            return False
        self.last_ns = now_ns
        if self.last >= 0:
            self.skipped += sequence - self.last - 1
        self.last = sequence
        self.delivered += 1
        return True

    def restart(self) -> None:
        """The sender restarted (its sequence numbers begin again): forget the order seen."""
        self.last = -1

    @property
    def loss(self) -> float:
        total = self.delivered + self.skipped
        return self.skipped / total if total else 0.0
