"""Reading a finished recording: what it holds (`hapticop info`) and a stream's samples as arrays.

Only finished files are read here; a `.part` left by a crash is first rewritten by `recover`.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from mcap.reader import SeekingReader
from mcap.records import Channel as ChannelRecord
from mcap.records import Message

from hapticop.recording import arrays
from hapticop.recording.bounded import BROKEN, Clamped, RecordingError, check_chunks, open_recording, records
from hapticop.recording.mcapfile import PART, StreamInfo, topic_of

__all__ = ["Channel", "Contents", "RecordingError", "Series", "contents", "resolve_topic", "series", "series_of"]


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


def _open(path: Path) -> Clamped:
    path = Path(path)
    if path.name.endswith(PART):
        raise RecordingError(f"{path} is a recording its run never finished: `hapticop recover {path}` first")
    return open_recording(path)


def _broken(path: Path, error: BaseException) -> RecordingError:
    said = str(error).splitlines()[0][:200] if str(error) else ""
    return RecordingError(f"{path} is not a finished MCAP recording ({type(error).__name__}{': ' if said else ''}"
                          f"{said}); if its run was killed, try `hapticop recover`")


def contents(path: Path) -> Contents:
    """What the file's summary says it holds; every length it declares checked against its size."""
    with _open(path) as stream:
        try:
            reader = SeekingReader(stream, record_size_limit=stream.size)
            summary = reader.get_summary()
            if summary is not None:
                check_chunks(stream, summary.chunk_indexes, path)
            metadata = {record.name: dict(record.metadata) for record in reader.iter_metadata()}
            attachments = {record.name: bytes(record.data) for record in reader.iter_attachments()}
        except RecordingError:
            raise
        except (*BROKEN, OSError) as error:
            raise _broken(path, error) from None
    if summary is None or summary.statistics is None:
        raise RecordingError(f"{path} has no summary: try `hapticop recover`")
    counts = summary.statistics.channel_message_counts
    channels = []
    for channel in summary.channels.values():
        schema = summary.schemas.get(channel.schema_id)
        try:
            info = StreamInfo.from_metadata(channel.metadata) if "stream" in channel.metadata else None
        except (*BROKEN, OSError) as error:
            raise RecordingError(f"{path}: channel '{channel.topic}' describes its stream wrongly "
                                 f"({type(error).__name__}: {error})") from None
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
    return series_of(path, [stream])[stream]


def series_of(path: Path, streams: list[str]) -> dict[str, Series]:
    """Every recorded sample of each of these raw streams, read in one pass over the file."""
    found = contents(path)
    channels = {}
    for stream in streams:
        channel = resolve_topic(found, stream)
        if channel.stream is None:
            raise RecordingError(f"'{channel.topic}' is a derived channel, not a stream's samples")
        channels[channel.topic] = (stream, channel.stream)
    taken: dict[str, tuple[list, list, list, list]] = {topic: ([], [], [], []) for topic in channels}
    if channels:
        with _open(path) as handle:
            topics: dict[int, str] = {}  # channel id to a chosen topic
            try:
                for record in records(handle, path, handle.size):
                    if isinstance(record, ChannelRecord) and record.topic in taken:
                        topics[record.id] = record.topic
                    elif isinstance(record, Message) and record.channel_id in topics:
                        sequence, publish, log, data = taken[topics[record.channel_id]]
                        sequence.append(record.sequence)
                        publish.append(record.publish_time)
                        log.append(record.log_time)
                        data.append(record.data)
            except RecordingError:
                raise
            except (*BROKEN, OSError) as error:
                raise _broken(path, error) from None
    result = {}
    for topic, (stream, info) in channels.items():
        sequence, publish, log, data = taken[topic]
        order = np.argsort(np.asarray(publish, dtype=np.int64), kind="stable")
        try:
            values = (np.stack([arrays.decode(d, info.dtype, info.shape) for d in data]) if data
                      else np.zeros((0, *info.shape), info.dtype))
        except (*BROKEN, OSError) as error:
            raise RecordingError(f"{path}: a sample of '{stream}' does not decode as {info.dtype}{list(info.shape)} "
                                 f"({type(error).__name__})") from None
        result[stream] = Series(info, np.asarray(sequence, dtype=np.int64)[order],
                                np.asarray(publish, dtype=np.int64)[order], np.asarray(log, dtype=np.int64)[order],
                                values[order])
    return result
