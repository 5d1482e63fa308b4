"""One run's MCAP file while it is written: a channel per stream, flushed often, renamed when done.

The file is written as `NAME.mcap.part` and renamed to `NAME.mcap` only once its summary is
written, so a `.part` left behind always means the run ended without finishing it. Each flush
closes the open chunk and hands it to the operating system: a process killed later loses only
what came after (`hapticop recover` rewrites the rest into a valid file).
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from mcap.writer import CompressionType, Writer

from hapticop.recording import arrays

PART = ".part"
CHUNK_BYTES = 4 << 20  # larger than a second of a busy run: chunks close at the flushes
STREAM_TOPIC = "/streams/{}"


def topic_of(stream: str) -> str:
    return STREAM_TOPIC.format(stream)


def part_of(path: Path) -> Path:
    return path.with_name(path.name + PART)


@dataclass(frozen=True)
class StreamInfo:
    """What a recorded stream's channel says of its samples (its MCAP channel metadata)."""

    name: str
    dtype: str
    shape: tuple[int, ...]
    unit: str
    rate_hz: float
    every: int = 1  # every Nth sample is recorded
    writer: str = ""  # 'activity.port'
    readers: tuple[str, ...] = ()
    doc: str = ""

    @property
    def nbytes(self) -> int:
        return np.dtype(self.dtype).itemsize * int(np.prod(self.shape, dtype=np.int64))

    def metadata(self) -> dict[str, str]:
        return {"stream": self.name, "dtype": self.dtype, "shape": json.dumps(list(self.shape)), "unit": self.unit,
                "rate_hz": f"{self.rate_hz:g}", "decimate": str(self.every), "writer": self.writer,
                "readers": ",".join(self.readers), "doc": self.doc, "encoding": "hapticop.array/v1"}

    @classmethod
    def from_metadata(cls, metadata: dict[str, str]) -> StreamInfo:
        return cls(metadata["stream"], metadata["dtype"], tuple(json.loads(metadata["shape"])), metadata["unit"],
                   float(metadata["rate_hz"]), int(metadata.get("decimate", "1")), metadata.get("writer", ""),
                   tuple(r for r in metadata.get("readers", "").split(",") if r), metadata.get("doc", ""))


class RecordingFile:
    """The MCAP writer of one run, with raw stream channels and room for derived ones."""

    def __init__(self, path: Path, library: str = "hapticop"):
        self.path = Path(path)
        self.part = part_of(self.path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._stream = open(self.part, "wb")  # noqa: SIM115 - closed by finish()
        self.writer = Writer(self._stream, chunk_size=CHUNK_BYTES, compression=CompressionType.ZSTD)
        self.writer.start(profile="", library=library)
        self._schemas: dict[tuple[str, str], int] = {}
        self._prefixes: dict[int, bytes] = {}
        self.messages = 0

    def schema(self, name: str, encoding: str, data: bytes) -> int:
        """A schema's id, registered once."""
        key = (name, encoding)
        if key not in self._schemas:
            self._schemas[key] = self.writer.register_schema(name, encoding, data)
        return self._schemas[key]

    def channel(self, topic: str, message_encoding: str, schema_id: int, metadata: dict[str, str]) -> int:
        """A channel of any kind (a derived view's, say); returns its id."""
        return self.writer.register_channel(topic, message_encoding, schema_id, metadata)

    def stream_channel(self, info: StreamInfo) -> int:
        """The channel of a stream's raw samples, as protobuf arrays (`arrays`)."""
        schema = self.schema(arrays.schema_name(info.dtype), arrays.SCHEMA_ENCODING, arrays.schema_data(info.dtype))
        channel = self.channel(topic_of(info.name), arrays.MESSAGE_ENCODING, schema, info.metadata())
        self._prefixes[channel] = arrays.prefix(info.nbytes)
        return channel

    def write(self, channel: int, log_time_ns: int, data: bytes, publish_time_ns: int, sequence: int) -> None:
        self.writer.add_message(channel, log_time_ns, data, publish_time_ns, sequence & 0xFFFFFFFF)
        self.messages += 1

    def write_samples(self, channel: int, samples: np.ndarray, log_time_ns: int) -> None:
        """Samples drained from a ring (`streams.sample_dtype`): each with its number as the
        sequence and its publication stamp as the publish time."""
        n = len(samples)
        if not n:
            return
        prefix = self._prefixes[channel]
        payload = samples["payload"]
        width = payload.shape[1]
        raw = payload.tobytes()
        add = self.writer.add_message
        for i, count, stamp in zip(range(n), samples["count"].tolist(), samples["stamp_ns"].tolist(), strict=True):
            add(channel, log_time_ns, prefix + raw[i * width:(i + 1) * width], stamp, count & 0xFFFFFFFF)
        self.messages += n

    def attach(self, name: str, media_type: str, data: bytes, time_ns: int) -> None:
        self.writer.add_attachment(time_ns, time_ns, name, media_type, data)

    def metadata(self, name: str, values: dict[str, str]) -> None:
        self.writer.add_metadata(name, {k: str(v) for k, v in values.items()})

    def flush(self) -> None:
        """Close the open chunk and hand it to the OS: a kill from now on cannot lose it."""
        self.writer.flush()

    def finish(self) -> Path:
        """Write the summary, close, and take the final name."""
        self.writer.finish()
        self._stream.close()
        os.replace(self.part, self.path)
        return self.path

    def abandon(self) -> None:
        """Close without a summary (the `.part` stays, for `hapticop recover`)."""
        self.flush()
        self._stream.close()
