"""An emulated network link on streams: each sample crosses delayed, jittered, maybe lost (docs/teleop.md).

Placed where a stream would cross between two hosts, it lets a single-host run (the virtual
clock's included) behave as the two hosts would over a bad link, with no network engine: each
new input sample is sent through a seeded ``EmulatedLink`` and published on the other side when
it arrives. The receiving side keeps the newest: a sample that arrives after a newer one (a
reordered packet) is dropped, and the last one is held, as a keep-newest network stream does.
Beside each stream it publishes how long the held sample took to cross, so a reader can tell the
age its data had when it arrived (model-mediated rendering predicts over it).
"""

from __future__ import annotations

import dataclasses
import zlib
from typing import Literal

import numpy as np
from pydantic import Field

from hapticop.blocks.base import Block
from hapticop.blocks.interface import Interface, Params, Port
from hapticop.network.link import EmulatedLink, LinkParams


class LinkedStream(Params):
    """What one stream through the link carries."""

    dtype: Literal["float64", "float32", "int64", "uint8"] = Field("float64", description="the samples' element type")
    shape: tuple[int, ...] = Field((), description="the samples' shape (() for a scalar)")
    unit: str = Field("1", description="the samples' unit")


class LinkBlockParams(Params):
    streams: dict[str, LinkedStream] = Field(
        default_factory=lambda: {"samples": LinkedStream()}, min_length=1,
        description="the streams through the link, by name: each gets an input <name>, and outputs "
        "<name>_received and <name>_delay (by default one scalar stream, 'samples')")
    link: LinkParams = Field(default_factory=LinkParams)
    stamp: Literal["arrival", "sent"] = Field(
        "arrival", description="a received sample's time stamp: when it arrived (its age starts at zero there), "
        "or when it was sent, as a network bridge stamps it, so that a reader's max_age also judges the crossing")


class Link(Block):
    """Samples of each stream sent through an emulated link (delay, jitter, loss, reordering, duplication)
    and published on arrival, the newest kept; `<name>_delay` says how long the held one took (s)."""

    Params = LinkBlockParams

    @classmethod
    def interface(cls, params: LinkBlockParams) -> Interface:
        inputs, outputs = {}, {}
        for name, stream in params.streams.items():
            port = Port(stream.dtype, stream.shape, stream.unit)
            inputs[name] = dataclasses.replace(port, doc="the samples sent")
            outputs[f"{name}_received"] = dataclasses.replace(port, doc="the newest sample that arrived")
            outputs[f"{name}_delay"] = Port("float64", (), "s", "how long the held sample took to cross")
        return Interface(inputs=inputs, outputs=outputs)

    def create(self) -> None:
        link = self.params.link
        self.lanes = []
        for name, stream in self.params.streams.items():
            # one generator per stream, from the link's seed and the stream's name: adding a stream
            # changes no other stream's luck
            seed = int(np.random.SeedSequence([link.seed, zlib.crc32(name.encode())]).generate_state(1)[0])
            width = int(np.prod(stream.shape, dtype=np.int64))
            emulated = EmulatedLink(dataclasses.replace(link, seed=seed), width, stream.dtype)
            source, received = getattr(self.inputs, name), getattr(self.outputs, f"{name}_received")
            self.lanes.append(_Lane(source, source.value.reshape(-1), received, received.value.reshape(-1),
                                    getattr(self.outputs, f"{name}_delay"), emulated, self.params.stamp == "sent"))

    def compute(self) -> None:
        now_s = self.clock.now_ns() / 1e9
        for lane in self.lanes:
            lane.step(now_s)

    def clean(self) -> None:
        for name, lane in zip(self.params.streams, self.lanes):
            link = lane.link
            self.log.info("link %s: %d sent, %d lost, %d duplicated, %d overflowed, %d delivered, %d late dropped",
                          name, link.sent, link.lost, link.duplicated, link.overflowed, link.delivered, lane.late)


@dataclasses.dataclass
class _Lane:
    """One stream's way through the link."""

    source: object  # the input port
    sent: np.ndarray  # its value, flat (a view)
    received: object  # the output port
    arrival: np.ndarray  # its value, flat (a view)
    delay: object
    link: EmulatedLink
    stamp_sent: bool = False  # stamp a received sample with its send time, as a bridge does
    newest: int = -1
    late: int = 0
    sent_ns: float = 0.0  # when the held sample was sent

    def step(self, now_s: float) -> None:
        source, link = self.source, self.link
        if source.queue:  # type: ignore[attr-defined]
            while source.pop():  # type: ignore[attr-defined]
                link.send(now_s, self.sent)
        elif source.fresh:  # type: ignore[attr-defined]
            link.send(now_s, self.sent)
        arrived = False
        while (slot := link.receive(now_s)) >= 0:
            sequence = link.sequence(slot)
            if sequence <= self.newest:  # older than what is held (reordered) or a duplicate
                self.late += sequence < self.newest
                continue
            self.newest = sequence
            self.arrival[:] = link.payload(slot)
            self.sent_ns = link.sent_s(slot) * 1e9
            self.delay.value[...] = now_s - link.sent_s(slot)  # type: ignore[attr-defined]
            arrived = True
        if arrived:
            if self.stamp_sent:
                self.received.stamp_ns = round(self.sent_ns)  # type: ignore[attr-defined]
            self.received.publish()  # type: ignore[attr-defined]
            self.delay.publish()  # type: ignore[attr-defined]
