"""Reading a finished recording: what it holds (`hapticop info`) and a stream's samples as arrays.

Only finished files are read here; a `.part` left by a crash is first rewritten by `recover`.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from mcap.exceptions import McapError
from mcap.reader import make_reader

from hapticop.recording import arrays
from hapticop.recording.mcapfile import PART, StreamInfo, topic_of


class RecordingError(Exception):
    """A file that is not a readable recording, said in words."""


@dataclass
class Channel:
    topic: str
    count: int
    metadata: dict[str, str]
    schema: str
    stream: StreamInfo | None = None  # a raw stream's channel


@dataclass
class Contents:
    """What `hapticop info` shows of a recording."""

    path: Path
    start_ns: int
    end_ns: int
    channels: list[Channel]
    metadata: dict[str, dict[str, str]] = field(default_factory=dict)
    attachments: dict[str, bytes] = field(default_factory=dict)

    @property
    def duration_s(self) -> float:
        return (self.end_ns - self.start_ns) / 1e9

    def drops(self) -> dict[str, int]:
        return {k: int(v) for k, v in self.metadata.get("hapticop.drops", {}).items()}


def _open(path: Path):
    path = Path(path)
    if path.name.endswith(PART):
        raise RecordingError(f"{path} is a recording its run never finished: `hapticop recover {path}` first")
    try:
        return open(path, "rb")
    except OSError as error:
        raise RecordingError(f"cannot read {path}: {error.strerror}") from None


def contents(path: Path) -> Contents:
    with _open(path) as stream:
        try:
            reader = make_reader(stream)
            summary = reader.get_summary()
            metadata = {record.name: dict(record.metadata) for record in reader.iter_metadata()}
            attachments = {record.name: bytes(record.data) for record in reader.iter_attachments()}
        except (McapError, ValueError, EOFError, struct.error) as error:
            raise RecordingError(f"{path} is not a finished MCAP recording ({type(error).__name__}: {error}); "
                                 "if its run was killed, try `hapticop recover`") from None
    if summary is None or summary.statistics is None:
        raise RecordingError(f"{path} has no summary: try `hapticop recover`")
    counts = summary.statistics.channel_message_counts
    channels = []
    for channel in summary.channels.values():
        schema = summary.schemas.get(channel.schema_id)
        info = StreamInfo.from_metadata(channel.metadata) if "stream" in channel.metadata else None
        channels.append(Channel(channel.topic, counts.get(channel.id, 0), dict(channel.metadata),
                                schema.name if schema else "", info))
    stats = summary.statistics
    return Contents(path, stats.message_start_time, stats.message_end_time, channels, metadata, attachments)


def resolve_topic(found: Contents, name: str) -> Channel:
    """A channel by stream name or topic."""
    for channel in found.channels:
        if channel.topic in (name, topic_of(name)):
            return channel
    known = ", ".join(c.stream.name if c.stream else c.topic for c in found.channels)
    raise RecordingError(f"{found.path} has no stream or topic '{name}' (it has: {known})")


@dataclass
class Series:
    """One stream's recorded samples, in order."""

    info: StreamInfo
    sequence: np.ndarray  # each sample's number (modulo 2^32)
    publish_ns: np.ndarray
    log_ns: np.ndarray
    values: np.ndarray  # (samples, *shape)


def series(path: Path, stream: str) -> Series:
    """Every recorded sample of a raw stream."""
    found = contents(path)
    channel = resolve_topic(found, stream)
    if channel.stream is None:
        raise RecordingError(f"'{channel.topic}' is a derived channel, not a stream's samples")
    info = channel.stream
    sequence, publish, log, data = [], [], [], []
    with _open(path) as handle:
        for _, _, message in make_reader(handle).iter_messages(topics=[channel.topic], log_time_order=False):
            sequence.append(message.sequence)
            publish.append(message.publish_time)
            log.append(message.log_time)
            data.append(message.data)
    order = np.argsort(np.asarray(publish, dtype=np.int64), kind="stable")
    values = (np.stack([arrays.decode(d, info.dtype, info.shape) for d in data]) if data
              else np.zeros((0, *info.shape), info.dtype))
    return Series(info, np.asarray(sequence, dtype=np.int64)[order], np.asarray(publish, dtype=np.int64)[order],
                  np.asarray(log, dtype=np.int64)[order], values[order])
