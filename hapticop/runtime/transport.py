"""One transport object per stream kind, made from the stream's connection policy.

OROCOS's ConnPolicy and ConnFactory are the model: the policy a composition writes (`latest`,
`queue`) chooses a class here, and only that class knows the stream's buffers: how many, how
large, what they become in the region, which one each reader takes, and how large the
recorder's ring of the stream is. Start-up (`region.Layout.build`), a stream added to a running
system (`live`), the recorder and its taps all ask the same object, so a buffer is never sized
twice in two ways: a live addition cannot write over another stream's shared memory because it
was measured differently. A new stream kind is a subclass here, its policy model and its schema.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from hapticop.blocks.interface import Port
from hapticop.composition.description import Stream
from hapticop.composition.loader import Loaded
from hapticop.runtime.streams import QUEUE_HEADER, LatestSlot, RecorderRing, SpscQueue, latest_nbytes, queue_nbytes


@dataclass(frozen=True)
class StreamTransport(ABC):
    """A stream's transport: its buffers in the region and the objects over them (one subclass per kind)."""

    name: str
    spec: Stream
    port: Port  # the writer's port: every sample's dtype and shape

    kind: ClassVar[str]

    @abstractmethod
    def buffers(self) -> list[tuple[int, str | None]]:
        """The stream's buffers in the region, in order: (bytes, the reader it is for, or None)."""

    @abstractmethod
    def objects(self, views: list[np.ndarray], synchronised: bool) -> list:
        """The transports over the region's `views` of `buffers()`, in the same order. `synchronised`:
        writer and reader may run at once (other threads), so a latest slot needs its seqlock."""

    @staticmethod
    @abstractmethod
    def reader_end(objects: list, index: int):
        """What the stream's `index`th reader reads from."""

    @classmethod
    def connect_reader(cls, spec: Stream, port_in, objects: list, index: int) -> None:
        """Wire the `index`th reader's input port to its end of the stream (start-up and live alike)."""
        port_in.connect(cls.reader_end(objects, index), cls.kind == "queue", spec.max_age or 0)

    def ring_nbytes(self, capacity: int) -> int:
        """The recorder's ring of this stream, `capacity` samples deep."""
        return queue_nbytes(self.port, capacity)

    def ring(self, view: np.ndarray) -> RecorderRing:
        """The writer's side of the recorder's ring over `view`: the loop never waits for it, and
        overwrites the oldest samples when the recorder falls a whole ring behind (it counts them)."""
        return RecorderRing(view, self.port, self.ring_capacity(len(view)), self.name)

    def ring_capacity(self, nbytes: int) -> int:
        return (nbytes - QUEUE_HEADER.itemsize) // latest_nbytes(self.port)


@dataclass(frozen=True)
class LatestTransport(StreamTransport):
    """One seqlock slot every reader reads, newest sample only (`policy: latest`)."""

    kind: ClassVar[str] = "latest"

    def buffers(self) -> list[tuple[int, str | None]]:
        return [(latest_nbytes(self.port), None)]

    def objects(self, views: list[np.ndarray], synchronised: bool) -> list:
        return [LatestSlot(views[0], self.port, synchronised=synchronised and self.spec.policy.sync == "lock_free")]

    @staticmethod
    def reader_end(objects: list, index: int):
        return objects[0]


@dataclass(frozen=True)
class QueueTransport(StreamTransport):
    """One single-producer single-consumer ring per reader (`policy: queue`)."""

    kind: ClassVar[str] = "queue"

    def buffers(self) -> list[tuple[int, str | None]]:
        return [(queue_nbytes(self.port, self.spec.policy.capacity), reader) for reader in self.spec.readers]

    def objects(self, views: list[np.ndarray], synchronised: bool) -> list:
        policy = self.spec.policy
        return [SpscQueue(view, self.port, policy.capacity, policy.overflow) for view in views]

    @staticmethod
    def reader_end(objects: list, index: int):
        return objects[index]


KINDS: dict[str, type[StreamTransport]] = {cls.kind: cls for cls in (LatestTransport, QueueTransport)}


def transport_of(loaded: Loaded, name: str) -> StreamTransport:
    """The transport object of stream `name`, chosen by its policy's kind."""
    spec = loaded.composition.streams[name]
    return transport_for(name, spec, writer_port(loaded.activities, spec))


def connect_reader(spec: Stream, port_in, objects: list, index: int) -> None:
    """Wire a stream's `index`th reader to the stream's `objects`, as its kind says."""
    KINDS[spec.policy.kind].connect_reader(spec, port_in, objects, index)


def transport_for(name: str, spec: Stream, port: Port) -> StreamTransport:
    return KINDS[spec.policy.kind](name, spec, port)


def writer_port(activities, spec: Stream) -> Port:
    """The port that writes the stream, from the resolved activities."""
    activity, port = spec.writer.split(".")
    return activities[activity].interface.outputs[port]
