"""What a receiving bridge does with each sample of a network stream, by its sequence number.

Samples may arrive late, twice or out of order. A stream keeps only samples newer than the last
one it delivered: a late one (an older sequence number) is dropped, a duplicate too, and the
sequence numbers skipped are counted as lost (a reordered sample arriving after them is late, not
lost, so the count is an upper bound of the link's loss).
"""

from __future__ import annotations


class Arrivals:
    """The order check of one received stream."""

    def __init__(self) -> None:
        self.last = -1  # the newest sequence number delivered
        self.delivered = 0
        self.late = 0  # older than one delivered, or a duplicate: dropped
        self.skipped = 0  # sequence numbers never delivered

    def accept(self, sequence: int) -> bool:
        """True when the sample is newer than every one delivered (deliver it), else False."""
        if sequence <= self.last:
            self.late += 1
            return False
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
