"""Zenoh, and only here: a peer session with explicit endpoints, publishers, and bounded subscribers.

The rest of hapticop never imports zenoh (an import-linter contract). The session is a peer that
listens on its host's endpoints and connects to the other hosts' ones, with multicast and gossip
scouting off, so two hosts find each other the same way every time, whichever starts first.
Subscribers are ring channels polled with `try_recv`: no Python callback shares the bridge's GIL,
and a reader that lags loses the oldest samples instead of falling behind without bound (Zenoh's
default handler is a FIFO that never drops).

A session is either Zenoh's default transport, whose per-priority queues and TX thread let a setpoint
overtake a queued scan, or its low-latency one, which writes each message on the link from the
caller's thread (less per round trip: docs/teleop.md has the figures) and has no priorities: both
ends must ask for it, or Zenoh falls back to the default without a word.
"""

from __future__ import annotations

import json

import zenoh

PRIORITIES = {"real_time": zenoh.Priority.REAL_TIME, "interactive": zenoh.Priority.INTERACTIVE_HIGH,
              "data": zenoh.Priority.DATA, "background": zenoh.Priority.BACKGROUND}
LEASE_MS = 1000  # Zenoh's default 10 s would notice a dead peer only after the robot has driven on blind


def session(listen: list[str], connect: list[str], low_latency: bool = False) -> zenoh.Session:
    """A peer session at these endpoints; no scouting."""
    config = zenoh.Config()
    config.insert_json5("mode", json.dumps("peer"))
    config.insert_json5("listen/endpoints", json.dumps(listen))
    config.insert_json5("connect/endpoints", json.dumps(connect))
    config.insert_json5("scouting/multicast/enabled", "false")
    config.insert_json5("scouting/gossip/enabled", "false")
    config.insert_json5("transport/link/tx/lease", str(LEASE_MS))
    config.insert_json5("transport/link/tx/keep_alive", "4")
    if low_latency:  # Zenoh refuses the low-latency transport with QoS on
        config.insert_json5("transport/unicast/lowlatency", "true")
        config.insert_json5("transport/unicast/qos/enabled", "false")
    return zenoh.open(config)


class Sender:
    def __init__(self, owner: zenoh.Session, key: str, priority: str = "data", reliable: bool = False,
                 block: bool = False) -> None:
        self._publisher = owner.declare_publisher(
            key, priority=PRIORITIES[priority], express=True,
            congestion_control=zenoh.CongestionControl.BLOCK if block else zenoh.CongestionControl.DROP,
            reliability=zenoh.Reliability.RELIABLE if reliable else zenoh.Reliability.BEST_EFFORT)

    def put(self, payload: bytes) -> None:
        self._publisher.put(payload)


class Receiver:
    """The newest `depth` samples of a key, taken without waiting."""

    def __init__(self, owner: zenoh.Session, key: str, depth: int = 1) -> None:
        self._subscriber = owner.declare_subscriber(key, zenoh.handlers.RingChannel(depth))

    def take(self) -> bytes | None:
        sample = self._subscriber.try_recv()
        return None if sample is None else sample.payload.to_bytes()
