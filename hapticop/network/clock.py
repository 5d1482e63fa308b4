"""The other host's clock seen from this one: offset and round trip from ping exchanges.

Each exchange gives the four NTP times: t1 ping sent (here), t2 ping received and t3 pong sent
(there), t4 pong received (here). Its round trip is (t4 - t1) - (t3 - t2) and its offset
estimate ((t2 - t1) + (t3 - t4)) / 2, exact when both directions take equally long; the error is
at most half the round trip. So of the last exchanges the one with the shortest round trip
gives the offset (the least queued, the most symmetric), and its half round trip bounds the error.

An exchange may also have been held on purpose in an emulated link (docs/teleop.md): that time counts
in the round trip, jitter and loss the link's figures report, as the samples feel it, but not in the
offset, whose four times are taken outside the emulation, so an emulated delay on one side does not
bias the clocks.
"""

from __future__ import annotations

import numpy as np


class OffsetEstimator:
    """Offset (remote minus local clock), round trip, jitter and loss over the last `window` pings."""

    def __init__(self, window: int = 64) -> None:
        self._rtt = np.full(window, np.inf)  # on the wire: chooses the offset and bounds its error
        self._trip = np.zeros(window)  # on the wire plus held in an emulated link: the link's figures
        self._offset = np.zeros(window)
        self._answered = np.zeros(window, dtype=bool)
        self._next = 0
        self._filled = 0
        self.last_rtt_ns = 0
        self.jitter_ns = 0.0  # smoothed |change of round trip|, as RFC 3550 smooths transit times

    def sent(self) -> int:
        """A ping leaves: returns its slot, to name it in the pong. Unanswered pings count as lost."""
        slot = self._next
        self._rtt[slot] = np.inf
        self._answered[slot] = False
        self._next = (slot + 1) % len(self._rtt)
        self._filled = min(self._filled + 1, len(self._rtt))
        return slot

    def answered(self, slot: int, t1: int, t2: int, t3: int, t4: int, held_ns: int = 0) -> None:
        """The pong of ping `slot` arrived: local times t1, t4, remote times t2, t3 (ns); `held_ns` the time
        the ping and the pong spent in emulated links besides."""
        if not 0 <= slot < len(self._rtt) or self._answered[slot]:
            return  # a stale or duplicated pong
        rtt = (t4 - t1) - (t3 - t2)
        if rtt < 0:
            return
        trip = rtt + max(0, held_ns)
        if self.last_rtt_ns:
            self.jitter_ns += (abs(trip - self.last_rtt_ns) - self.jitter_ns) / 16.0
        self.last_rtt_ns = trip
        self._rtt[slot] = rtt
        self._trip[slot] = trip
        self._offset[slot] = ((t2 - t1) + (t3 - t4)) / 2.0
        self._answered[slot] = True

    def echoed(self, slot: int, t1: int, t4: int) -> None:
        """Ping `slot`, sent at t1, came back at t4 from a far side on this same clock that only echoes it
        (an emulated link's other end): its round trip, and no offset (the far side's times are the midpoint)."""
        middle = (t1 + t4) // 2
        self.answered(slot, t1, middle, middle, t4)

    @property
    def synced(self) -> bool:
        return bool(self._answered.any())

    @property
    def offset_ns(self) -> float:
        """Remote clock minus local clock (0 before the first answer)."""
        return float(self._offset[int(np.argmin(self._rtt))]) if self.synced else 0.0

    @property
    def error_ns(self) -> float:
        """Bound on the offset's error: half the shortest round trip (infinity before an answer)."""
        return float(self._rtt.min()) / 2.0 if self.synced else float("inf")

    @property
    def rtt_ns(self) -> float:
        """The median round trip over the window, emulated holds included (0 before an answer)."""
        answered = self._trip[self._answered]
        return float(np.median(answered)) if answered.size else 0.0

    @property
    def loss(self) -> float:
        """The fraction of the window's pings not answered, the newest one (maybe in flight) left out."""
        counted = self._filled - 1
        if counted <= 0:
            return 0.0
        newest = (self._next - 1) % len(self._rtt)
        unanswered = int(self._filled - self._answered.sum()) - (0 if self._answered[newest] else 1)
        return max(0, unanswered) / counted

    def to_local(self, remote_ns: int) -> int:
        """A time of the remote clock on this host's clock."""
        return int(remote_ns - self.offset_ns)


def table_row(metric: str, value, unit: str = "") -> dict:
    """One row of a link's end-of-run table (a figure, no target)."""
    return {"metric": metric, "value": value, "unit": unit, "target": "", "ok": None}


def round_trip_rows(rtts_ms: np.ndarray, jitter_ns: float, answered: int, pinged: int) -> list[dict]:
    """The rows every link table starts with: the round trips measured over the run, the smoothed jitter
    and the share of pings never answered."""
    return [table_row("round trip p50", round(float(np.percentile(rtts_ms, 50)), 3), "ms"),
            table_row("round trip p99", round(float(np.percentile(rtts_ms, 99)), 3), "ms"),
            table_row("round trip max", round(float(rtts_ms.max()), 3), "ms"),
            table_row("jitter (smoothed)", round(jitter_ns / 1e6, 3), "ms"),
            table_row("pings unanswered", round(1 - answered / max(1, pinged), 4))]
