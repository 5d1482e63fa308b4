"""ROS 2 topics as streams: ports published and subscribed over Zenoh as rmw_zenoh does (docs/ros2.md).

The activity is a ROS 2 node (named in YAML) on a thread of normal scheduling in a process of its own,
like the two-host bridge: Zenoh's threads and its Python calls never share a process or a GIL with the
1 kHz loops, which only read and write the shared region. Each publication is sent at its own rate
(50 Hz by default, ROS 2 bases taking 20 to 100 Hz) with the newest sample of its input, or, when that
sample is missing or older than the stream's `max_age`, with zeros (a stale command is no motion) or
nothing (`stale: skip`). Each sample carries rmw_zenoh's attachment (sequence number, source time,
this publisher's GID) on the key `<domain>/<topic>/<type>/<hash>`, and the node, its publishers and its
subscriptions hold liveliness tokens, so `ros2 node list` and `ros2 topic list` see them. With `flags:`,
the run's flags (every one, by its full name, as a JSON object) are a `std_msgs/msg/String` topic too,
sent at its rate and at once when one changes.

Nothing that arrives is trusted: a sample on the topic with another type or hash, malformed CDR, a
length or values that do not fit the port (not finite; a scan may say infinity), a missing attachment,
a source time in the future or older than the subscription's `max_age`, or older than the last one
delivered, is refused, counted (the output `refused`, by reason in the run's log), and the next good one
is delivered. A delivered sample is stamped with its source time on this host's clock, so a reader's
`max_age` counts its age in ROS 2 too: stale is absent.
"""

from __future__ import annotations

import hashlib
import json
import time

import numpy as np
from pydantic import Field, model_validator
from pydantic_core import PydanticCustomError

from hapticop.blocks.base import Block
from hapticop.blocks.bounds import Refusals
from hapticop.blocks.interface import Interface, Params, Port
from hapticop.ros2 import attachment, names
from hapticop.ros2.messages import LAYOUTS, STRING, encode_string, layout_of
from hapticop.ros2.topics import Ros2Node, Ros2Topic

FUTURE_NS = 1_000_000_000  # a source time this far ahead of this host's clock is refused

class Ros2BridgeParams(Params, Ros2Node):
    publish: dict[str, Ros2Topic] = Field(default_factory=dict, description="input ports sent as ROS 2 topics")
    subscribe: dict[str, Ros2Topic] = Field(default_factory=dict, description="ROS 2 topics received into "
                                            "output ports (a LaserScan's angles also, as NAME_angles)")

    @model_validator(mode="after")
    def _port_names(self) -> Ros2BridgeParams:
        both = sorted(set(self.publish) & (set(self.subscribe) | {f"{n}_angles" for n in self.subscribe}))
        if both or "refused" in self.subscribe:
            raise PydanticCustomError("ros2_port_names", "port names used twice: {names}",
                                      {"names": ", ".join(both or ["refused"])})
        return self


def _port(t: Ros2Topic, doc: str) -> Port:
    """The port that carries a topic, in the layout its shape chooses."""
    layout = layout_of(t.type, LAYOUTS[t.type][0].dtype, t.port_shape)
    return Port(layout.dtype, t.port_shape, layout.unit, f"{doc} {t.topic} ({t.type}: {layout.doc})")


class Ros2Bridge(Block):
    """A ROS 2 node over Zenoh as rmw_zenoh speaks it: ports published and subscribed as topics (docs/ros2.md)."""

    Params = Ros2BridgeParams
    own_process = "Zenoh's session and its threads must not share a process or a GIL with the loops"

    @classmethod
    def interface(cls, params: Ros2BridgeParams) -> Interface:
        outputs = {}
        for name, t in params.subscribe.items():
            outputs[name] = _port(t, "from")
            if t.type == "sensor_msgs/msg/LaserScan":
                outputs[f"{name}_angles"] = Port("float32", t.port_shape, "rad", f"the beams' angles of {t.topic}")
        outputs["refused"] = Port("int64", (), "1", "samples refused so far (another type, malformed, not "
                                  "fitting, not finite, stale, late)")
        return Interface(inputs={name: _port(t, "sent as") for name, t in params.publish.items()}, outputs=outputs)

    def create(self) -> None:
        p = self.params
        self.codecs = {name: t.codec(p.distro) for name, t in {**p.publish, **p.subscribe}.items()}
        self.keys = {name: names.data_key(p.domain, t.fully_qualified(p.namespace), t.type, p.distro)
                     for name, t in {**p.publish, **p.subscribe}.items()}
        self.sequence = dict.fromkeys(p.publish, 0)
        self.next_ns = dict.fromkeys(p.publish, 0)
        self.sent_seq = dict.fromkeys(p.publish, 0)  # the input sample last sent, and its stamp on the wall clock
        self.sent_stamp = dict.fromkeys(p.publish, 0)
        self.zeros = {name: np.zeros(t.port_shape, LAYOUTS[t.type][0].dtype) for name, t in p.publish.items()}
        self.values = {name: np.zeros(t.port_shape, LAYOUTS[t.type][0].dtype) for name, t in p.subscribe.items()}
        self.angles = {name: np.zeros(t.port_shape, np.float32) for name, t in p.subscribe.items()
                       if t.type == "sensor_msgs/msg/LaserScan"}
        self.last_source = dict.fromkeys(p.subscribe, 0)
        self.refusals = {name: Refusals() for name in p.subscribe}
        self.published_refused = -1
        self.flags_next_ns, self.flags_sent, self.flags_sequence = 0, "", 0
        self.net = None
        self.tokens: list = []

    def configure_resources(self) -> bool:
        from hapticop.network import transport  # Zenoh only in this activity's own process

        p = self.params
        self.net = transport.session(p.listen, p.connect, mode=p.mode)
        zid = transport.session_id(self.net)
        node = names.Node(p.domain, p.node, p.namespace)
        self.tokens = [transport.Token(self.net, node.token(zid, 0))]
        self.gids, self.senders, self.receivers = {}, {}, {}
        for entity, (name, t) in enumerate([*p.publish.items(), *p.subscribe.items()], start=1):
            publisher = name in p.publish
            qos = t.qos.names()
            token = node.endpoint_token(zid, 0, entity, publisher, t.fully_qualified(p.namespace), t.type, p.distro,
                                        qos)
            self.gids[name] = hashlib.sha256(token.encode()).digest()[: attachment.GID_SIZE]  # opaque, stable
            depth = qos.depth or names.DEFAULT_DEPTH
            transient = t.qos.durability == "transient_local"
            if publisher:
                self.senders[name] = transport.Sender(self.net, self.keys[name], "data", qos.reliability == "reliable",
                                                      qos.blocks, depth if transient else 0)
            else:
                # every type on the topic: one that is not ours is told apart and counted, not silently unmatched
                topic_keys = self.keys[name].rsplit("/", 2)[0] + "/*/*"
                self.receivers[name] = transport.Receiver(self.net, topic_keys, max(4, min(depth, 64)), transient)
            self.tokens.append(transport.Token(self.net, token))
        if p.flags is not None:  # the run's flags: a publisher like the others, of std_msgs/msg/String
            topic, qos = p.flags.fully_qualified(p.namespace), p.flags.qos.names()
            entity = 1 + len(p.publish) + len(p.subscribe)
            token = node.endpoint_token(zid, 0, entity, True, topic, STRING, p.distro, qos)
            self.flags_gid = hashlib.sha256(token.encode()).digest()[: attachment.GID_SIZE]
            transient = p.flags.qos.durability == "transient_local"
            self.flags_sender = transport.Sender(
                self.net, names.data_key(p.domain, topic, STRING, p.distro), "data", qos.reliability == "reliable",
                qos.blocks, (qos.depth or names.DEFAULT_DEPTH) if transient else 0)
            self.tokens.append(transport.Token(self.net, token))
        return True

    def compute(self) -> None:
        now = self.clock.now_ns()
        wall = time.time_ns()
        self._publish(now, wall)
        if self.params.flags is not None:
            self._publish_flags(now, wall)
        self._take(now, wall)

    def pausing(self) -> None:
        self._take(self.clock.now_ns(), time.time_ns())

    def clean(self) -> None:
        for token in self.tokens:
            token.undeclare()
        self.tokens = []
        if self.net is not None:
            self.net.close()
            self.net = None

    # -- out ----------------------------------------------------------------------------
    def _publish(self, now: int, wall: int) -> None:
        for name, t in self.params.publish.items():
            if now < self.next_ns[name]:
                continue
            self.next_ns[name] = max(self.next_ns[name] + t.rate, now)
            port = getattr(self.inputs, name)
            if port.valid:
                if port.seq != self.sent_seq[name]:  # a sample sent again keeps its stamp, to the nanosecond
                    self.sent_seq[name], self.sent_stamp[name] = port.seq, wall - (now - port.stamp_ns)
                value, source = port.value, self.sent_stamp[name]
            elif t.stale == "zero":
                value, source = self.zeros[name], wall
            else:
                continue
            self.sequence[name] += 1
            payload = self.codecs[name].encode(value, source)
            self.senders[name].put(payload, attachment.pack(self.sequence[name], wall, self.gids[name]))

    def _publish_flags(self, now: int, wall: int) -> None:
        """Every flag of the run as JSON, at the topic's rate and at once when one changed."""
        text = json.dumps(self.context.flags.run_flags(), sort_keys=True)
        if now < self.flags_next_ns and text == self.flags_sent:
            return
        self.flags_next_ns, self.flags_sent = now + self.params.flags.rate, text
        self.flags_sequence += 1
        self.flags_sender.put(encode_string(self.params.distro, text),
                              attachment.pack(self.flags_sequence, wall, self.flags_gid))

    # -- in -----------------------------------------------------------------------------
    def _take(self, now: int, wall: int) -> None:
        for name, t in self.params.subscribe.items():
            receiver, refusals = self.receivers[name], self.refusals[name]
            while (sample := receiver.take_sample()) is not None:
                why = self._refused(name, t, *sample, wall)
                if why is not None:
                    refusals.count(why)
                refusals.said(self.log, f"topic {t.topic}", why)
                if why is None:
                    self._deliver(name, now, wall)
        refused = sum(r.total for r in self.refusals.values())
        if refused != self.published_refused:
            self.published_refused = refused
            self.outputs.refused.value[...] = refused
            self.outputs.refused.publish()

    def _refused(self, name: str, t: Ros2Topic, key: str, payload: bytes, extra: bytes | None, wall: int) -> str | None:
        """Why a sample is not delivered, or None (its value is then in `self.values[name]`)."""
        if key != self.keys[name]:
            return "another type or type hash: " + "/".join(key.rsplit("/", 2)[1:])
        meta = attachment.unpack(extra) if extra is not None else None
        if meta is None:
            return "no rmw_zenoh attachment"
        source = meta[1]
        if source > wall + FUTURE_NS:
            return "source time in the future"
        if wall - source > t.max_age:
            return "stale"
        if source < self.last_source[name]:
            return "older than the last one delivered"
        why = self.codecs[name].decode(payload, self.values[name], self.angles.get(name))
        if why is None:
            self.last_source[name] = source
        return why

    def _deliver(self, name: str, now: int, wall: int) -> None:
        stamp = now - max(0, wall - self.last_source[name])  # its source time on this host's clock
        port = getattr(self.outputs, name)
        np.copyto(port.value, self.values[name])
        port.stamp_ns = stamp
        port.publish()
        if name in self.angles:
            angles = getattr(self.outputs, f"{name}_angles")
            np.copyto(angles.value, self.angles[name])
            angles.stamp_ns = stamp
            angles.publish()
