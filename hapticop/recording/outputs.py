"""Where the recorder's channels go: the MCAP file, the live view, or both at once.

An output registers schemas and channels and takes messages, either one at a time (a view's
LaserScan) or as a drained batch of a stream's samples. `RecordingFile` is one; the live view
(`recording.live.LiveServer`) is another; `Fanout` hands the same calls to several, so the
recorder and its views never know which are there.
"""

from __future__ import annotations

from typing import Protocol

import numpy as np

from hapticop.recording.mcapfile import StreamInfo


class Output(Protocol):
    def schema(self, name: str, encoding: str, data: bytes) -> int: ...

    def channel(self, topic: str, message_encoding: str, schema_id: int, metadata: dict[str, str]) -> int: ...

    def stream_channel(self, info: StreamInfo) -> int: ...

    def write(self, channel: int, log_time_ns: int, data: bytes, publish_time_ns: int, sequence: int) -> None: ...

    def write_samples(self, channel: int, samples: np.ndarray, log_time_ns: int) -> None: ...


class Fanout:
    """Several outputs behind one: each id it hands out stands for the outputs' own ids."""

    def __init__(self, outputs: list[Output]):
        self.outputs = outputs
        self._schemas: list[list[int]] = []
        self._channels: list[list[int]] = []

    def schema(self, name: str, encoding: str, data: bytes) -> int:
        self._schemas.append([out.schema(name, encoding, data) for out in self.outputs])
        return len(self._schemas)

    def channel(self, topic: str, message_encoding: str, schema_id: int, metadata: dict[str, str]) -> int:
        ids = self._schemas[schema_id - 1] if schema_id else [0] * len(self.outputs)
        self._channels.append([out.channel(topic, message_encoding, ids[k], metadata)
                               for k, out in enumerate(self.outputs)])
        return len(self._channels)

    def stream_channel(self, info: StreamInfo) -> int:
        self._channels.append([out.stream_channel(info) for out in self.outputs])
        return len(self._channels)

    def write(self, channel: int, log_time_ns: int, data: bytes, publish_time_ns: int, sequence: int) -> None:
        for out, id_ in zip(self.outputs, self._channels[channel - 1], strict=True):
            out.write(id_, log_time_ns, data, publish_time_ns, sequence)

    def write_samples(self, channel: int, samples: np.ndarray, log_time_ns: int) -> None:
        for out, id_ in zip(self.outputs, self._channels[channel - 1], strict=True):
            out.write_samples(id_, samples, log_time_ns)
