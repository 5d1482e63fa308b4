"""One host's bridge: its network streams and coordination flags to and from the other hosts, over Zenoh.

A composition with `hosts:` gives every host one bridge, on a thread of normal scheduling in a
process of its own (docs/teleop.md): the real-time loops read and write the shared region as for
any stream and never wait on the network. Each cycle the bridge sends the new samples of the
streams it reads, takes what arrived for the streams it writes (newest first: a late or duplicate
sample is dropped by its sequence number), stamps each with its send time on this host's clock
(through the estimated clock offset), so a reader's `max_age` counts the network too, and pings
the other hosts to estimate the offset, round trip, jitter and loss, which it publishes as ordinary
streams (with the link's `health`; each host's composition records them and `hapticop status` shows them)
and as the flags `link_up`, `link_lost` and `link_degraded`.

Nothing that arrives is trusted (docs/teleop.md, "What the link refuses"): a sample is delivered
only whole (its exact length), from the session of the host that owns its stream, in order and not
implausibly far ahead, sent at a plausible time, and, for a command, finite and inside the receiving
port's declared range; any other is dropped, counted (the output `refused`), logged once per burst,
and the next good one is delivered. A pong moves the clock estimate only if it answers a ping this
bridge sent (slot, send time and nonce) and agrees with the estimate it already has.
"""

from __future__ import annotations

import dataclasses
import math
import os
import time
import zlib
from typing import Literal, get_args

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, model_validator

from hapticop.blocks.base import Block
from hapticop.blocks.bounds import Bounds, Refusals
from hapticop.blocks.interface import Interface, Params, Port
from hapticop.composition.placement import HEALTH
from hapticop.network import wire
from hapticop.network.arrivals import Arrivals
from hapticop.network.clock import OffsetEstimator, round_trip_rows, table_row
from hapticop.network.link import EmulatedLink, LinkParams, MessageLink

WINDOW = 64  # pings the clock estimate looks back over (3.2 s at the default 50 ms)

LINK_OUTPUTS = {
    "rtt": Port("float64", (), "s", "round trip to the other host (median of the last pings)"),
    "jitter": Port("float64", (), "s", "smoothed change of the round trip between pings"),
    "loss": Port("float64", (), "1", "fraction of the last pings not answered"),
    "offset": Port("float64", (), "s", "the other host's clock minus this one's"),
    "offset_error": Port("float64", (), "s", "bound on the offset's error (half the shortest round trip); "
                         "infinite until the clocks are compared"),
    "health": Port("int64", (), "1", "the link: " + ", ".join(f"{i} {name}" for i, name in enumerate(HEALTH))
                   + " (the worst that holds; degraded: round trip or loss above the limits)"),
    "refused": Port("int64", (), "1", "samples, pongs and states refused so far (malformed, foreign, "
                    "out of order, out of range)"),
    "sessions": Port("int64", (), "1", "sessions of the other hosts seen so far (a restart is a new one)"),
}
FUTURE_NS = 1_000_000_000  # a send time later than this ahead of now (on this clock) is refused
PAST_NS = 3_600 * 1_000_000_000  # and one older than this (stale anyway; no time arithmetic overflows)
OFFSET_SLACK_NS = 2_000_000  # a pong's offset may disagree by this beyond both error bounds (drift, stamping)


Priority = Literal["real_time", "interactive", "data", "background"]
PRIORITY_ORDER: tuple[Priority, ...] = get_args(Priority)  # most urgent first


class WireStream(BaseModel):
    """A network stream as one bridge sees it (written by the host split, docs/teleop.md)."""

    model_config = ConfigDict(extra="forbid", frozen=True)
    stream: str = Field(description="the stream's name in the composition")
    dtype: str = Field(description="its samples' element type")
    shape: tuple[int, ...] = Field((), description="its samples' shape")
    unit: str = Field("1", description="its samples' unit")
    priority: Priority = Field("data", description="the stream's network priority (NetworkQoS)")
    keep: Literal["newest", "queue"] = Field("newest", description="the newest sample only, or a queue (NetworkQoS)")
    depth: int | None = Field(None, ge=1, le=65536, description="a queue's depth (NetworkQoS)")
    reliability: Literal["best_effort", "reliable"] = Field("best_effort", description="Zenoh's reliability")
    congestion: Literal["drop", "block"] = Field("drop", description="what Zenoh does with a full queue")
    host: str | None = Field(None, description="the host that writes it: its samples come from that host's "
                             "session only (None: the only other host)")
    readers: list[str] | None = Field(None, description="the hosts that read it, the only ones its writer sends it "
                                      "to (None: every other host)")
    range: tuple[float, float] | None = Field(None, description="the receiving ports' declared range: a sample "
                                              "with an element outside it is refused")

    @model_validator(mode="after")
    def _ordered(self) -> WireStream:
        if self.range is not None and not self.range[0] <= self.range[1]:
            raise ValueError(f"range {list(self.range)}: low above high")
        return self

    def port(self) -> Port:
        return Port(self.dtype, self.shape, self.unit, f"stream '{self.stream}' across the network", range=self.range)


class TlsParams(BaseModel):
    """This host's credentials for the link (docs/security.md): PEM files, written by the host split."""

    model_config = ConfigDict(extra="forbid", frozen=True)
    ca: str = Field(description="the system's CA certificate: the only one this host trusts")
    certificate: str = Field(description="this host's certificate, its name as common name")
    key: str = Field(description="this host's private key (mode 0600)")


class BridgeParams(Params):
    host: str = Field(description="the host this bridge serves")
    system: str = Field("hapticop", description="the composition's name: the Zenoh keys' prefix")
    peers: list[str] = Field(default_factory=list, description="the other hosts' names")
    listen: list[str] = Field(description="this host's Zenoh endpoints")
    connect: list[str] = Field(default_factory=list, description="the other hosts' endpoints")
    send: list[WireStream] = Field(default_factory=list, description="streams written here, read elsewhere")
    receive: list[WireStream] = Field(default_factory=list, description="streams written elsewhere, read here")
    export_flags: list[str] = Field(default_factory=list, description="mediator places other hosts mirror")
    import_flags: list[str] = Field(default_factory=list, description="other hosts' places mirrored here")
    peer_end: bool = Field(False, description="raise 'peer_ended' when another host's run ends")
    hold_when_lost: list[str] = Field(default_factory=list, description="imported places held while the link is lost")
    low_latency: bool = Field(False, description="Zenoh's low-latency transport: no priority queues, a shorter "
                              "round trip; the other hosts must use it too")
    ping_period_ms: float = Field(50.0, gt=0, description="pings (and this host's state) this often")
    lost_after_ms: float = Field(250.0, gt=0, description="nothing heard for this long: 'link_lost'")
    degraded_rtt_ms: float = Field(300.0, gt=0, description="a round trip above this: 'link_degraded'")
    degraded_loss: float = Field(0.2, ge=0, le=1, description="a ping loss above this: 'link_degraded'")
    tls: TlsParams | None = Field(None, description="mutual TLS and access rules by certificate; none: an "
                                  "insecure link ('security: {insecure: true}')")
    emulate: LinkParams | None = Field(
        None, description="impair what arrives (delay, jitter, loss) with a seeded emulated link, for tests and "
        "experiments on a good network")


class ZenohBridge(Block):
    """Moves a host's network streams and coordination flags across Zenoh (docs/teleop.md)."""

    Params = BridgeParams

    @classmethod
    def interface(cls, params: BridgeParams) -> Interface:
        flags = {"link_up": "the other hosts answer", "link_lost": f"nothing heard for {params.lost_after_ms:g} ms",
                 "link_degraded": "round trip or loss above the limits",
                 "peer_ended": "another host's run ended"}
        flags.update({f"in_{p.lower()}": f"place {p} of another host's mediator" for p in params.import_flags})
        return Interface(
            inputs={f"out_{w.stream}": w.port() for w in params.send},
            outputs={**{f"in_{w.stream}": w.port() for w in params.receive}, **LINK_OUTPUTS},
            flags_written=flags,
            flags_read={f"out_{p.lower()}": f"place {p} of this host's mediator" for p in params.export_flags})

    @classmethod
    def preflight(cls, params: BridgeParams, timeout_s: float) -> str | None:
        """This host's keys: there, its own, valid today and private (they may have changed since `validate`)."""
        if params.tls is None:
            return None
        from pathlib import Path

        from hapticop.network.keys import problems_of

        found = problems_of(Path(params.tls.ca), Path(params.tls.certificate), Path(params.tls.key), params.host)
        return "; ".join(f"{path} {problem}" for path, problem in found) or None

    def create(self) -> None:
        p = self.params
        self.session_id = int.from_bytes(os.urandom(8), "little")
        self.sequence = {w.stream: 0 for w in p.send}
        # the most urgent streams leave first in every cycle: with the low-latency transport, which writes each
        # message straight on the link, this order is the only priority there is
        self.send_order = sorted(p.send, key=lambda w: PRIORITY_ORDER.index(w.priority))
        self.arrivals = {w.stream: Arrivals() for w in p.receive}
        self.owners = {w.stream: w.host or (p.peers[0] if len(p.peers) == 1 else None) for w in p.receive}
        self.bounds = {w.stream: Bounds(w.port(), f"stream '{w.stream}'") for w in p.receive}
        self.values = {w.stream: np.zeros(w.shape, w.dtype) for w in p.receive}  # a sample checked before delivery
        self.refusals = {w.stream: Refusals() for w in p.receive}
        self.pong_refusals = Refusals()
        self.peer_session: dict[str, int | None] = {peer: None for peer in p.peers}  # as each host announces it
        self.sessions_seen = 0
        self.clocks = {peer: OffsetEstimator(WINDOW) for peer in p.peers}
        self.pinged_at = {peer: np.zeros(WINDOW, dtype=np.int64) for peer in p.peers}
        self.nonces = np.zeros(WINDOW, dtype=np.uint64)  # each ping's nonce, by slot: its pong must return it
        self.heard_ns = {peer: 0 for peer in p.peers}
        self.next_ping_ns = 0
        self.links = ({w.stream: EmulatedLink(p.emulate, wire.SAMPLE.size + w.port().nbytes, np.uint8)
                       for w in p.receive} if p.emulate is not None else {})
        # pings and pongs cross the emulated link too, so the round trip measured is the one the samples feel;
        # the clocks are compared outside it (docs/teleop.md)
        self.ping_links = {peer: _impaired(p.emulate, f"ping {peer}") for peer in p.peers} if p.emulate else {}
        self.pong_link = _impaired(p.emulate, "pong") if p.emulate else None
        self.rtts = np.zeros(1 << 16, dtype=np.int64)  # every answered ping's round trip, for the run's table
        self.answered = 0
        self.pinged = 0
        self.offset_seen = (0.0, float("inf"))
        self.was_lost = False
        self.remote_holding: frozenset[str] = frozenset()  # the other host's exported places that hold a token
        self.net = None

    def configure_resources(self) -> bool:
        from hapticop.network import transport  # Zenoh only where a bridge runs

        p = self.params
        credentials = None
        if p.tls is not None:
            # each host may put only the streams it writes, and read only those it reads (a third host is no operator)
            rights = [transport.Rights(
                peer, puts=[wire.sample_key(p.system, w.stream) for w in p.receive if w.host in (None, peer)] + [
                    wire.ping_key(p.system, peer), wire.pong_key(p.system, p.host), wire.state_key(p.system, peer)],
                reads=[wire.sample_key(p.system, w.stream) for w in p.send
                       if w.readers is None or peer in w.readers] + [
                    wire.ping_key(p.system, p.host), wire.pong_key(p.system, peer), wire.state_key(p.system, p.host)])
                for peer in p.peers]
            credentials = transport.Credentials(p.tls.ca, p.tls.certificate, p.tls.key, rights)
        self.net = transport.session(p.listen, p.connect, p.low_latency, credentials)
        self.expires_ns = None if p.tls is None else _expiry_ns(p.tls)
        self.senders = {w.stream: transport.Sender(self.net, wire.sample_key(p.system, w.stream), w.priority,
                                                   w.reliability == "reliable", w.congestion == "block")
                        for w in p.send}
        # newest: a few, so a bad sample arriving after a good one in a cycle does not hide it
        self.receivers = {w.stream: transport.Receiver(self.net, wire.sample_key(p.system, w.stream),
                                                       w.depth if w.keep == "queue" and w.depth else 4)
                          for w in p.receive}
        self.ping_out = transport.Sender(self.net, wire.ping_key(p.system, p.host), "real_time")
        self.pong_out = {peer: transport.Sender(self.net, wire.pong_key(p.system, peer), "real_time")
                         for peer in p.peers}
        self.pings_in = {peer: transport.Receiver(self.net, wire.ping_key(p.system, peer), 8) for peer in p.peers}
        self.pongs_in = transport.Receiver(self.net, wire.pong_key(p.system, p.host), 64)
        self.state_out = transport.Sender(self.net, wire.state_key(p.system, p.host), "interactive", True)
        self.states_in = {peer: transport.Receiver(self.net, wire.state_key(p.system, peer), 1) for peer in p.peers}
        return True

    def configure_capabilities(self) -> bool:
        """Running once every other host has answered a ping: the link is up."""
        self._service()
        up = self.flags["link_up"]
        self.context.waiting_for(None if up else f"the other hosts ({', '.join(self.params.peers)}) to answer")
        return up

    def compute(self) -> None:
        self._service()

    def pausing(self) -> None:
        self._service()

    def clean(self) -> None:
        if self.net is not None:
            self.state_out.put(self._state(ended=True))
            self.net.close()
            self.net = None
        if self.answered:
            write_link_table(self.run_dir, self)

    # -- the cycle --------------------------------------------------------------------
    def _service(self) -> None:
        now = self.clock.now_ns()
        if self.expires_ns is not None and time.time_ns() >= self.expires_ns:
            self._expire()
        if self.net is None:  # its certificate ended: nothing crosses, the link is lost, the deadman stops
            due = now >= self.next_ping_ns
            if due:
                self.next_ping_ns = now + int(self.params.ping_period_ms * 1e6)
            self._judge_link(now, publish=due)
            return
        self._send_samples()
        self._answer_pings()
        due = now >= self.next_ping_ns
        if due:
            self.next_ping_ns = now + int(self.params.ping_period_ms * 1e6)
            self._ping(now)
        self._take_pongs()
        self._take_states(now)
        self._take_samples(now)
        self._judge_link(now, publish=due)

    def _expire(self) -> None:
        """This host's certificate (or its CA's) has ended: close the session, as Zenoh would not without
        panicking (docs/security.md); the other hosts hear nothing more and their deadmen stop the robot."""
        self.expires_ns = None
        self.log.error("this host's certificate has expired: the link is closed until the run restarts with new keys")
        net, self.net = self.net, None
        if net is not None:
            try:
                net.close()
            except Exception as error:  # noqa: BLE001 - Zenoh's close may time out; the link is gone either way
                self.log.warning("closing the expired link: %s", error)

    def _send_samples(self) -> None:
        for w in self.send_order:
            port = getattr(self.inputs, f"out_{w.stream}")
            if port.queue:
                while port.pop():
                    self._send(w.stream, port)
            elif port.fresh:
                self._send(w.stream, port)

    def _send(self, stream: str, port) -> None:
        self.sequence[stream] += 1
        header = wire.SAMPLE.pack(self.session_id, self.sequence[stream], port.stamp_ns)
        self.senders[stream].put(header + port.value.tobytes())

    def _ping(self, now: int) -> None:
        """One ping to every other host; each answers with its name, so each has its own estimate."""
        t1 = self.clock.now_ns()  # as it leaves, not the cycle's start
        slot = 0
        for peer, clock in self.clocks.items():  # they advance together: one slot for all
            slot = clock.sent()
            self.pinged_at[peer][slot] = t1
        if self.clocks:
            self.pinged += 1
            nonce = int.from_bytes(os.urandom(8), "little")
            self.nonces[slot] = nonce
            self.ping_out.put(wire.PING.pack(self.session_id, slot, nonce, t1))
        self.state_out.put(self._state(ended=False))

    def _answer_pings(self) -> None:
        for peer, receiver in self.pings_in.items():
            # t2 when taken, not the cycle's start: a ping sent after the cycle began would otherwise
            # look received before it was sent, and pass for the best (shortest) exchange
            while (taken := _take(receiver, self.ping_links.get(peer), self.clock)) is not None:
                data, t2 = taken
                if len(data) != wire.PING.size:
                    self.pong_refusals.count("malformed ping")
                    continue
                session, slot, nonce, t1 = wire.PING.unpack(data)
                self._announced(peer, session)
                t3 = self.clock.now_ns()  # held since t2 in the emulated link, if any: said apart
                held = t3 - t2 if self.ping_links else 0
                pong = wire.PONG.pack(session, slot, nonce, t1, t2, t3, held, self.session_id)
                self.pong_out[peer].put(pong + self.params.host.encode())

    def _take_pongs(self) -> None:
        while (taken := _take(self.pongs_in, self.pong_link, self.clock)) is not None:
            data, t4 = taken
            heard = self.clock.now_ns()
            why = self._pong_refused(data, t4)
            if why is not None:
                self.pong_refusals.count(why)
                self.pong_refusals.said(self.log, "pongs", why)
                continue
            self.pong_refusals.said(self.log, "pongs", None)
            _, slot, _, t1, t2, t3, held, _ = wire.PONG.unpack_from(data)
            peer = data[wire.PONG.size:].decode()
            clock = self.clocks[peer]
            clock.answered(slot, t1, t2, t3, t4, held + (heard - t4))
            self.heard_ns[peer] = heard
            self.rtts[self.answered % len(self.rtts)] = clock.last_rtt_ns
            self.answered += 1
            self.offset_seen = (clock.offset_ns, clock.error_ns)  # the last estimate, for the run's table

    def _pong_refused(self, data: bytes, t4: int) -> str | None:
        """Why a pong may not move the clock estimate, or None: it must answer a ping this bridge sent
        (session, slot, send time, nonce), come from the session its host announced, and agree with the
        estimate so far (both offsets' error bounds overlap); its times must be in order."""
        if len(data) < wire.PONG.size:
            return "malformed pong"
        asker, slot, nonce, t1, t2, t3, _, session = wire.PONG.unpack_from(data)
        try:
            peer = data[wire.PONG.size:].decode()
        except UnicodeDecodeError:
            return "malformed pong"
        clock = self.clocks.get(peer)
        if clock is None or asker != self.session_id:
            return "pong to no ping of ours"
        if not (0 <= slot < WINDOW and self.pinged_at[peer][slot] == t1 and int(self.nonces[slot]) == nonce):
            return "pong to no ping of ours"
        if self.peer_session[peer] is not None and session != self.peer_session[peer]:
            return "pong from another session"
        rtt = (t4 - t1) - (t3 - t2)
        if not (0 <= t3 - t2 <= t4 - t1 <= WINDOW * self.params.ping_period_ms * 1e6):
            return "pong with implausible times"
        if clock.synced:
            offset = ((t2 - t1) + (t3 - t4)) / 2.0
            if abs(offset - clock.offset_ns) > rtt / 2.0 + clock.error_ns + OFFSET_SLACK_NS:
                return "pong contradicting the clock offset"
        self._announced(peer, session)
        return None

    def _announced(self, peer: str, session: int) -> None:
        """The session `peer` says it runs (in its pings, pongs and state): a new one is a restart, announced,
        and its streams' order starts again."""
        known = self.peer_session[peer]
        if session == known:
            return
        self.peer_session[peer] = session
        self.sessions_seen += 1
        if known is not None:
            # the clock estimate stays: the host's clock did not restart with its bridge, and a fresh estimate
            # would take its first pong unchecked
            self.log.warning("host '%s' started a new session: its streams' sequence numbers begin again", peer)
        for stream, owner in self.owners.items():
            if owner == peer:
                self.arrivals[stream].restart()
        self.outputs.sessions.value[...] = self.sessions_seen
        self.outputs.sessions.publish()

    def _take_states(self, now: int) -> None:
        for peer, receiver in self.states_in.items():
            data = receiver.take()
            if data is None:
                continue
            try:
                if len(data) < wire.STATE.size:
                    raise ValueError
                session, ended = wire.STATE.unpack_from(data)
                holding = frozenset(data[wire.STATE.size:].decode().split(","))
            except (ValueError, UnicodeDecodeError):
                self.pong_refusals.count("malformed state")
                self.pong_refusals.said(self.log, "states", "malformed state")
                continue
            self._announced(peer, session)
            self.remote_holding = holding
            if ended and self.params.peer_end:
                self.flags["peer_ended"] = True
            self.heard_ns[peer] = now

    def _take_samples(self, now: int) -> None:
        for w in self.params.receive:
            receiver, link = self.receivers[w.stream], self.links.get(w.stream)
            while (data := receiver.take()) is not None:
                if link is None:
                    self._deliver(w.stream, data, now)
                elif len(data) == wire.SAMPLE.size + self.values[w.stream].nbytes:
                    # delayed from when it arrived, not from the cycle's start (the bridge may have stalled since)
                    link.send(self.clock.now_ns() / 1e9, np.frombuffer(data, np.uint8))
                else:
                    self.refusals[w.stream].count("malformed")
            while link is not None and (slot := link.receive(self.clock.now_ns() / 1e9)) >= 0:
                self._deliver(w.stream, link.payload(slot).tobytes(), now)

    def _deliver(self, stream: str, data: bytes, now: int) -> None:
        refusals = self.refusals[stream]
        why = self._refused(stream, data, now)
        if why is not None:
            refusals.count(why)
        refusals.said(self.log, f"stream '{stream}'", why)
        if why is not None:
            return
        port = getattr(self.outputs, f"in_{stream}")
        np.copyto(port.value, self.values[stream])
        # the send time on this host's clock, never in the future: a reader's max_age counts the network
        port.stamp_ns = min(now, self.clocks[self.owners[stream]].to_local(wire.SAMPLE.unpack_from(data)[2]))
        port.publish()

    def _refused(self, stream: str, data: bytes, now: int) -> str | None:
        """Why a sample is not delivered, or None (its value is then in `self.values[stream]`)."""
        owner = self.owners[stream]
        clock = self.clocks.get(owner) if owner is not None else None
        if clock is None or not clock.synced:  # its age cannot be told yet: a sample of unknown age is none
            return "before the clocks are compared"
        value = self.values[stream]
        if len(data) != wire.SAMPLE.size + value.nbytes:
            return "malformed"
        session, sequence, sent = wire.SAMPLE.unpack_from(data)
        if session != self.peer_session[owner]:
            return "not from its owner's session"
        local = clock.to_local(sent)
        if not now - PAST_NS <= local <= now + FUTURE_NS:
            return "implausible send time"
        value.reshape(-1).view(np.uint8)[:] = np.frombuffer(data, np.uint8, offset=wire.SAMPLE.size)
        bounds = self.bounds[stream]
        if bounds.checks and not bounds.admits(value):
            return "not finite or out of range"
        arrivals = self.arrivals[stream]
        if not arrivals.accept(sequence, now):
            return "late or duplicate" if sequence <= arrivals.last else "implausibly far ahead"
        return None

    def _judge_link(self, now: int, publish: bool) -> None:
        p = self.params
        lost_ns = int(p.lost_after_ms * 1e6)
        lost = any(now - heard > lost_ns for heard in self.heard_ns.values())
        synced = all(clock.synced for clock in self.clocks.values())
        rtt = max((c.rtt_ns for c in self.clocks.values()), default=0.0)
        loss = max((c.loss for c in self.clocks.values()), default=0.0)
        self.flags["link_up"] = synced and not lost
        self.flags["link_lost"] = synced and lost
        if synced and lost != self.was_lost:
            self.was_lost = lost
            if lost:
                self.log.warning("link lost: nothing heard for %g ms", p.lost_after_ms)
            else:
                self.log.info("link up again")
        self.flags["link_degraded"] = rtt > p.degraded_rtt_ms * 1e6 or loss > p.degraded_loss
        for place in p.import_flags:  # the other host's places, or the safe side of them while it is out of reach
            self.flags[f"in_{place.lower()}"] = place in self.remote_holding or (lost and place in p.hold_when_lost)
        if publish and self.clocks:
            clock = next(iter(self.clocks.values()))
            refused = self.pong_refusals.total + sum(r.total for r in self.refusals.values())
            flags = self.flags
            health = HEALTH.index("lost" if flags["link_lost"] else "degraded" if flags["link_degraded"]
                                  else "up" if flags["link_up"] else "waiting")
            for name, value in (("rtt", rtt / 1e9), ("jitter", clock.jitter_ns / 1e9), ("loss", loss),
                                ("offset", clock.offset_ns / 1e9),
                                ("offset_error", clock.error_ns / 1e9 if clock.synced else math.inf),
                                ("health", health), ("refused", refused), ("sessions", self.sessions_seen)):
                port = getattr(self.outputs, name)
                port.value[...] = value
                port.publish()

    def _state(self, ended: bool) -> bytes:
        """This host's session, whether its run ended, and the exported places that hold a token."""
        holding = ",".join(p for p in self.params.export_flags if self.flags[f"out_{p.lower()}"])
        return wire.STATE.pack(self.session_id, ended) + holding.encode()



def _expiry_ns(tls: TlsParams) -> int:
    """When this host's link must close (wall clock, ns): the end of its certificate or of its CA's."""
    from pathlib import Path

    from hapticop.network.keys import expiry

    end = expiry(Path(tls.ca), Path(tls.certificate))
    return 0 if end is None else int(end.timestamp()) * 1_000_000_000


def _impaired(params: LinkParams, name: str) -> MessageLink:
    """An emulated link for pings or pongs, with luck of its own (from the emulation's seed and its name)."""
    seed = int(np.random.SeedSequence([params.seed, zlib.crc32(name.encode())]).generate_state(1)[0])
    return MessageLink(dataclasses.replace(params, seed=seed))


def _take(receiver, impaired: MessageLink | None, clock) -> tuple[bytes, int] | None:
    """The next message that arrived and when it was taken off the network (before any emulated hold)."""
    if impaired is None:
        data = receiver.take()
        return None if data is None else (data, clock.now_ns())
    while (data := receiver.take()) is not None:
        impaired.send(clock.now_ns(), data)
    return impaired.receive(clock.now_ns())


def write_link_table(run_dir, bridge: ZenohBridge) -> None:
    """The link's figures over the run, as a results table (printed at the end, kept in the run directory)."""
    import json

    rtts = bridge.rtts[: min(bridge.answered, len(bridge.rtts))] / 1e6
    clock = next(iter(bridge.clocks.values()))

    row = table_row
    rows = round_trip_rows(rtts, clock.jitter_ns, bridge.answered, bridge.pinged) + [
        row("clock offset (last estimate)", round(bridge.offset_seen[0] / 1e6, 3), "ms"),
        row("offset error bound", round(bridge.offset_seen[1] / 1e6, 3), "ms")]
    for stream, count in bridge.sequence.items():
        rows.append(row(f"{stream}: sent", count))
    for stream, arrivals in bridge.arrivals.items():
        rows.append(row(f"{stream}: received", arrivals.delivered))
        rows.append(row(f"{stream}: late or duplicate, dropped", arrivals.late))
        rows.append(row(f"{stream}: superseded or lost", arrivals.skipped))
        for why, count in sorted(bridge.refusals[stream].by_reason.items()):
            rows.append(row(f"{stream}: refused, {why}", count))
    for why, count in sorted(bridge.pong_refusals.by_reason.items()):
        rows.append(row(f"refused, {why}", count))
    data = {"title": f"link of host '{bridge.params.host}' to {', '.join(bridge.params.peers)}", "rows": rows}
    (run_dir / "results-link.json").write_text(json.dumps(data, indent=1))
