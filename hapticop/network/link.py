"""A network link made bad on purpose, in user space: delay, jitter, loss, reordering, duplication.

The kernels hapticop runs on may lack ``netem``, and a simulation under the virtual clock needs
the same impairments with bit-identical reruns. So the link is a plain object that is told the
time (``send(now_s, ...)``, ``receive(now_s)``): it reads no clock and so works under the virtual
clock and in real time alike, and all its randomness comes from one seeded generator.

Every packet draws the same four numbers (loss, jitter, duplication, the copy's jitter) whatever
the settings, so two links with the same seed and different loss or jitter see the same sequence
of chances: an experiment's cells differ by their settings, not by their luck.

Without ``reorder`` the link is a FIFO, as a real queue is: a packet is never delivered before
one sent earlier (it waits behind it), which keeps every delay within delay ± jitter when packets
are sent in time order. With ``reorder`` each packet leaves at its own time, so jitter larger
than the sending interval reorders them, as netem's time-based reordering does.

Packets are rows of a preallocated array, copied in on ``send`` and read in place after
``receive``; only a small heap entry per packet orders them.
"""

from __future__ import annotations

import heapq
from typing import Annotated

import numpy as np
from annotated_types import Ge, Gt, Le
from numpy.typing import DTypeLike, NDArray

from hapticop.parameters import parameters

NOT_IN_FLIGHT = float("inf")


@parameters
class LinkParams:
    """One direction of an emulated link (docs/teleop.md): each packet is delayed, jittered, lost or
    duplicated by chances drawn from a seeded generator."""

    delay_s: Annotated[float, Ge(0)] = 0.0
    """Mean one-way delay; a round trip is two links' delays."""
    jitter_s: Annotated[float, Ge(0)] = 0.0
    """Each packet's delay is uniform within delay ± jitter (never below zero)."""
    loss: Annotated[float, Ge(0), Le(1)] = 0.0
    """Probability that a packet is lost (Bernoulli, independent)."""
    duplicate: Annotated[float, Ge(0), Le(1)] = 0.0
    """Probability that a packet that is not lost arrives twice (the copy with its own jitter)."""
    reorder: bool = False
    """Let packets overtake each other when jitter exceeds the sending interval; otherwise first in, first out."""
    seed: Annotated[int, Ge(0)] = 0
    """The generator's seed: the same seed and the same sends give the same deliveries."""
    capacity: Annotated[int, Gt(0)] = 4096
    """Packets in flight at most; a packet sent to a full link is lost and counted as overflowed."""


class EmulatedLink:
    """One direction of a link: packets of ``width`` values go in with ``send`` and come out of
    ``receive`` once their time has come."""

    def __init__(self, params: LinkParams, width: int, dtype: DTypeLike = np.float64) -> None:
        self.params = params
        self._rng = np.random.Generator(np.random.PCG64(params.seed))
        self._draws = np.zeros(4)
        capacity = params.capacity
        self._payloads = np.zeros((capacity, width), dtype=dtype)
        self._queue: list[tuple[float, int, int]] = []
        self._sent_s = np.zeros(capacity)
        self._sequence = np.zeros(capacity, dtype=np.int64)
        self._free = list(range(capacity - 1, -1, -1))
        self._last_due_s = -np.inf
        self._next_sequence = 0
        self._enqueued = 0
        self.sent = 0
        """Packets handed to ``send``."""
        self.lost = 0
        """Packets the link lost on purpose."""
        self.duplicated = 0
        """Extra copies the link made."""
        self.overflowed = 0
        """Packets (or copies) refused because ``capacity`` were in flight."""
        self.delivered = 0
        """Packets (copies included) that ``receive`` handed out."""

    @property
    def in_flight(self) -> int:
        """Packets sent and not yet delivered."""
        return self.params.capacity - len(self._free)

    def send(self, now_s: float, payload: NDArray | float) -> int:
        """Put one packet on the link at ``now_s``; returns its sequence number (lost packets get one too)."""
        sequence = self._next_sequence
        self._next_sequence += 1
        self.sent += 1
        p = self.params
        loss_u, jitter_u, duplicate_u, copy_jitter_u = self._rng.random(out=self._draws)
        if loss_u < p.loss:
            self.lost += 1
            return sequence
        self._enqueue(now_s, payload, sequence, jitter_u)
        if duplicate_u < p.duplicate:
            self.duplicated += 1
            self._enqueue(now_s, payload, sequence, copy_jitter_u)
        return sequence

    def _enqueue(self, now_s: float, payload: NDArray | float, sequence: int, jitter_u: float) -> None:
        if not self._free:
            self.overflowed += 1
            return
        p = self.params
        due_s = now_s + max(0.0, p.delay_s + p.jitter_s * (2.0 * jitter_u - 1.0))
        if not p.reorder:
            due_s = max(due_s, self._last_due_s)
            self._last_due_s = due_s
        slot = self._free.pop()
        self._payloads[slot] = payload
        self._sent_s[slot] = now_s
        self._sequence[slot] = sequence
        heapq.heappush(self._queue, (due_s, self._enqueued, slot))
        self._enqueued += 1

    def receive(self, now_s: float) -> int:
        """The slot of the next packet due by ``now_s`` (the earliest due, ties in sending order), or -1.

        The packet's data stay readable through ``payload``, ``sent_s`` and ``sequence`` until the
        next ``send``; call ``receive`` again until it returns -1 to take everything due."""
        if not self._queue or self._queue[0][0] > now_s:
            return -1
        slot = heapq.heappop(self._queue)[2]
        self._free.append(slot)
        self.delivered += 1
        return slot

    def payload(self, slot: int) -> NDArray:
        """The values of the packet ``receive`` returned (a view: copy it to keep it)."""
        return self._payloads[slot]

    def sent_s(self, slot: int) -> float:
        """When the packet was sent."""
        return float(self._sent_s[slot])

    def sequence(self, slot: int) -> int:
        """The packet's sequence number (a duplicate has its original's)."""
        return int(self._sequence[slot])

    def next_due_s(self) -> float:
        """When the next packet is due (infinity when none is in flight)."""
        return self._queue[0][0] if self._queue else NOT_IN_FLIGHT


class MessageLink:
    """Messages of any length (a bridge's pings and pongs) through an emulated link: the link decides when
    each arrives, or whether, and the bytes wait beside it with the time they were handed over."""

    def __init__(self, params: LinkParams) -> None:
        self.link = EmulatedLink(params, 1, np.int64)
        self._waiting: dict[int, tuple[bytes, int]] = {}

    def send(self, now_ns: int, data: bytes) -> None:
        link = self.link
        dropped = link.lost + link.overflowed
        sequence = link.send(now_ns / 1e9, 0)
        if link.lost + link.overflowed == dropped:  # on its way (a lost one never comes: nothing kept)
            self._waiting[sequence] = (data, now_ns)

    def receive(self, now_ns: int) -> tuple[bytes, int] | None:
        """The next message due by ``now_ns`` and when it was sent, or None; a duplicate comes once."""
        while (slot := self.link.receive(now_ns / 1e9)) >= 0:
            message = self._waiting.pop(self.link.sequence(slot), None)
            if message is not None:
                return message
        return None

    @property
    def waiting(self) -> int:
        """Messages on their way."""
        return len(self._waiting)
