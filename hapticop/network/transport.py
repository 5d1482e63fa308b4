"""Zenoh, and only here: a session with explicit endpoints, publishers, bounded subscribers, liveliness tokens.

The rest of hapticop never imports zenoh (an import-linter contract): the two-host bridge and the ROS 2
bridge (hapticop.blocks.ros2_bridge, docs/ros2.md) both reach it through this module. The session is a peer that
listens on its host's endpoints and connects to the other hosts' ones, with multicast and gossip
scouting off, so two hosts find each other the same way every time, whichever starts first.
Subscribers are ring channels polled with `try_recv`: no Python callback shares the bridge's GIL,
and a reader that lags loses the oldest samples instead of falling behind without bound (Zenoh's
default handler is a FIFO that never drops).

A session is either Zenoh's default transport, whose per-priority queues and TX thread let a setpoint
overtake a queued scan, or its low-latency one, which writes each message on the link from the
caller's thread (less per round trip: docs/teleop.md has the figures) and has no priorities: both
ends must ask for it, or Zenoh falls back to the default without a word.

With credentials the session speaks TLS with mutual authentication: a host proves who it is by a
certificate its system's CA signed, whose common name is the host's name, and its access rules deny
everything but what `Rights` allows each other host by that name (put the keys it writes, subscribe to
the keys it is sent). Zenoh's shared-memory transport is off: two hosts share no memory, and its
segments in /dev/shm would outlive a run (docs/security.md).
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field

import zenoh
import zenoh.ext

PRIORITIES = {"real_time": zenoh.Priority.REAL_TIME, "interactive": zenoh.Priority.INTERACTIVE_HIGH,
              "data": zenoh.Priority.DATA, "background": zenoh.Priority.BACKGROUND}
LEASE_MS = 1000  # Zenoh's default 10 s would notice a dead peer only after the robot has driven on blind


@dataclass(frozen=True)
class Rights:
    """What the host whose certificate names `peer` may do here: put these keys, subscribe to those."""

    peer: str
    puts: list[str]
    reads: list[str]


@dataclass(frozen=True)
class Credentials:
    """This host's certificate and key, its CA, and every other host's rights (PEM file paths)."""

    ca: str
    certificate: str
    key: str
    rights: list[Rights] = field(default_factory=list)


def access_rules(rights: list[Rights]) -> dict:
    """Zenoh's access control: deny by default; each peer, told by its certificate's common name, may put
    the keys it writes and subscribe to the keys it reads, and this host sends it only those."""
    rules, subjects, policies = [], [], []
    for n, right in enumerate(rights):
        allowed = [("put", "ingress", right.puts), ("declare_subscriber", "egress", right.puts),
                   ("put", "egress", right.reads), ("declare_subscriber", "ingress", right.reads)]
        ids = []
        for message, flow, keys in allowed:
            if keys:
                ids.append(f"{message}_{flow}_{n}")
                rules.append({"id": ids[-1], "messages": [message], "flows": [flow], "permission": "allow",
                              "key_exprs": list(keys)})
        subjects.append({"id": f"host_{n}", "cert_common_names": [right.peer], "link_protocols": ["tls", "quic"]})
        policies.append({"id": f"policy_{n}", "rules": ids, "subjects": [f"host_{n}"]})
    return {"enabled": True, "default_permission": "deny", "rules": rules, "subjects": subjects,
            "policies": policies}


def session(listen: list[str], connect: list[str], low_latency: bool = False,
            credentials: Credentials | None = None, mode: str = "peer") -> zenoh.Session:
    """A peer session at these endpoints (or a client of the routers `connect` names); no scouting; mutual
    TLS and access rules with `credentials`."""
    config = zenoh.Config()
    config.insert_json5("mode", json.dumps(mode))
    config.insert_json5("listen/endpoints", json.dumps(listen))
    config.insert_json5("connect/endpoints", json.dumps(connect))
    config.insert_json5("scouting/multicast/enabled", "false")
    config.insert_json5("scouting/gossip/enabled", "false")
    config.insert_json5("transport/link/tx/lease", str(LEASE_MS))
    config.insert_json5("transport/link/tx/keep_alive", "4")
    config.insert_json5("transport/shared_memory/enabled", "false")
    if credentials is not None:
        c = credentials
        config.insert_json5("transport/link/tls", json.dumps({
            "root_ca_certificate": c.ca, "enable_mtls": True, "verify_name_on_connect": True,
            "listen_certificate": c.certificate, "listen_private_key": c.key,
            "connect_certificate": c.certificate, "connect_private_key": c.key}))
        config.insert_json5("access_control", json.dumps(access_rules(c.rights)))
    if low_latency:  # Zenoh refuses the low-latency transport with QoS on
        config.insert_json5("transport/unicast/lowlatency", "true")
        config.insert_json5("transport/unicast/qos/enabled", "false")
    return zenoh.open(config)


def session_id(owner: zenoh.Session) -> str:
    """The session's Zenoh id, as hex (what ROS 2's liveliness tokens name a participant by)."""
    return str(owner.info.zid())


class Sender:
    """Puts on one key; with `cache`, the last `cache` samples are kept for late subscribers that ask for
    history (Zenoh's advanced publisher: ROS 2's transient-local durability as rmw_zenoh maps it)."""

    def __init__(self, owner: zenoh.Session, key: str, priority: str = "data", reliable: bool = False,
                 block: bool = False, cache: int = 0) -> None:
        options = dict(priority=PRIORITIES[priority], express=True,
                       congestion_control=zenoh.CongestionControl.BLOCK if block else zenoh.CongestionControl.DROP,
                       reliability=zenoh.Reliability.RELIABLE if reliable else zenoh.Reliability.BEST_EFFORT)
        if cache:
            self._publisher = zenoh.ext.declare_advanced_publisher(
                owner, key, cache=zenoh.ext.CacheConfig(max_samples=cache), publisher_detection=True, **options)
        else:
            self._publisher = owner.declare_publisher(key, **options)

    def put(self, payload: bytes, attachment: bytes | None = None) -> None:
        self._publisher.put(payload, attachment=attachment)


class Receiver:
    """The newest `depth` samples of a key (or key expression), taken without waiting; with `history`, a
    late subscriber first asks the publishers' caches for their last samples (transient local)."""

    def __init__(self, owner: zenoh.Session, key: str, depth: int = 1, history: bool = False) -> None:
        if history:
            self._subscriber = zenoh.ext.declare_advanced_subscriber(
                owner, key, zenoh.handlers.RingChannel(depth),
                history=zenoh.ext.HistoryConfig(detect_late_publishers=True, max_samples=depth))
        else:
            self._subscriber = owner.declare_subscriber(key, zenoh.handlers.RingChannel(depth))

    def take(self) -> bytes | None:
        sample = self._subscriber.try_recv()
        return None if sample is None else sample.payload.to_bytes()

    def take_sample(self) -> tuple[str, bytes, bytes | None] | None:
        """The next sample's key, payload and attachment (None: nothing waiting)."""
        sample = self._subscriber.try_recv()
        if sample is None:
            return None
        attachment = sample.attachment
        return str(sample.key_expr), sample.payload.to_bytes(), None if attachment is None else attachment.to_bytes()


class Token:
    """A liveliness token: declared while this session lives (ROS 2's graph is made of them)."""

    def __init__(self, owner: zenoh.Session, key: str) -> None:
        self._token = owner.liveliness().declare_token(key)

    def undeclare(self) -> None:
        self._token.undeclare()
