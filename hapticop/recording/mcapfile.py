"""One run's MCAP file while it is written: a channel per stream, flushed often, renamed when done.

The file is written as `NAME.mcap.part` and renamed to `NAME.mcap` only once its summary is
written, so a `.part` left behind always means the run ended without finishing it. Each flush
closes the open chunk and hands it to the operating system: a process killed later loses only
what came after (`hapticop recover` rewrites the rest into a valid file).
"""

from __future__ import annotations

import json
import os
import struct
import zlib
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import zstandard
from mcap.data_stream import RecordBuilder
from mcap.opcode import Opcode
from mcap.records import (
    Attachment,
    AttachmentIndex,
    Channel,
    Chunk,
    ChunkIndex,
    DataEnd,
    Footer,
    Header,
    Message,
    Metadata,
    MetadataIndex,
    Schema,
    Statistics,
    SummaryOffset,
)

from hapticop.recording import arrays

MAGIC = b"\x89MCAP0\r\n"
PART = ".part"
CHUNK_BYTES = 4 << 20  # larger than a second of a busy run: chunks close at the flushes
STREAM_TOPIC = "/streams/{}"
TIMING_TOPIC = "/timing/{}"  # a loop's timing windows (hapticop.observe.timing_channels)
LOG_TOPIC = "/log"  # the run's log records (hapticop.observe.log_channel)
EVENT_TOPIC = "/events/{}"  # what happened to the run: modes, flags, life cycles (hapticop.observe.event_channels)


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


_MESSAGE_HEAD = 2 + 4 + 8 + 8  # channel id, sequence, log time, publish time


def _message_records(prefix_nbytes: int, nbytes: int) -> np.dtype:
    """Message records (opcode, length, header fields, data) of one channel, packed back to back."""
    return np.dtype([("opcode", "u1"), ("length", "<u8"), ("channel", "<u2"), ("sequence", "<u4"),
                     ("log_time", "<u8"), ("publish_time", "<u8"), ("data", "u1", (prefix_nbytes + nbytes,))])


class RecordingFile:
    """The MCAP file of one run, with raw stream channels and room for derived ones.

    Written with the `mcap` package's records, but the messages of a drained batch are laid out
    as one numpy array of Message records and appended to the open chunk at once: the package's
    own writer spends about 4 µs a message in Python, which for twenty 1 kHz streams is a tenth of
    a core; this is a few per cent of that. Schemas and channels are written outside the chunks, as
    they are registered; a chunk is closed at every flush (or when it reaches `CHUNK_BYTES`),
    zstd-compressed and followed by its message indexes; the summary is written by `finish`.
    """

    def __init__(self, path: Path, library: str = "hapticop", profile: str = ""):
        self.path = Path(path)
        self.part = part_of(self.path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._out = open(self.part, "wb")  # noqa: SIM115 - closed by finish() or abandon()
        self._out.write(MAGIC)
        self._write(Header(profile=profile, library=library))  # "ros2": a rosbag2 bag's file (ros2channels)
        self._schemas: dict[tuple[str, str], Schema] = {}
        self._channels: dict[int, Channel] = {}
        self._batches: dict[int, tuple[np.dtype, np.ndarray]] = {}  # a stream channel's record layout, prefix
        self._chunk = bytearray()
        self._chunk_times: list[int] = []  # first and last log time in the open chunk
        self._index: dict[int, list[tuple[int, np.ndarray]]] = {}  # per channel: (log time, offsets) per batch
        self._templates: dict[int, np.ndarray] = {}
        self._chunk_indexes: list[ChunkIndex] = []
        self._attachment_indexes: list[AttachmentIndex] = []
        self._metadata_indexes: list[MetadataIndex] = []
        self.counts: dict[int, int] = {}
        self.first_ns: int | None = None
        self.last_ns = 0
        self.messages = 0

    def _write(self, record) -> tuple[int, int]:
        """A record outside the chunks; returns its offset and length."""
        builder = RecordBuilder()
        record.write(builder)
        data = builder.end()
        offset = self._out.tell()
        self._out.write(data)
        return offset, len(data)

    # -- channels ----------------------------------------------------------------------------
    def schema(self, name: str, encoding: str, data: bytes) -> int:
        """A schema's id, registered once."""
        key = (name, encoding)
        if key not in self._schemas:
            self._schemas[key] = Schema(id=len(self._schemas) + 1, name=name, encoding=encoding, data=data)
            self._write(self._schemas[key])
        return self._schemas[key].id

    def channel(self, topic: str, message_encoding: str, schema_id: int, metadata: dict[str, str]) -> int:
        """A channel of any kind (a derived view's, say); returns its id."""
        channel = Channel(id=len(self._channels) + 1, topic=topic, message_encoding=message_encoding,
                          schema_id=schema_id, metadata=dict(metadata))
        self._channels[channel.id] = channel
        self.counts[channel.id] = 0
        self._write(channel)
        return channel.id

    def stream_channel(self, info: StreamInfo) -> int:
        """The channel of a stream's raw samples, as protobuf arrays (`arrays`)."""
        schema = self.schema(arrays.schema_name(info.dtype), arrays.SCHEMA_ENCODING, arrays.schema_data(info.dtype))
        channel = self.channel(topic_of(info.name), arrays.MESSAGE_ENCODING, schema, info.metadata())
        prefix = arrays.prefix(info.nbytes)
        self._batches[channel] = (_message_records(len(prefix), info.nbytes), np.frombuffer(prefix, np.uint8))
        self._templates[channel] = np.zeros(0, self._batches[channel][0])
        return channel

    # -- messages ----------------------------------------------------------------------------
    def _added(self, channel: int, log_time_ns: int, offsets: np.ndarray) -> None:
        """Messages appended to the open chunk at `offsets`, all logged at `log_time_ns`."""
        n = len(offsets)
        self._index.setdefault(channel, []).append((log_time_ns, offsets))
        self.counts[channel] += n
        self.messages += n
        self.first_ns = log_time_ns if self.first_ns is None else min(self.first_ns, log_time_ns)
        self.last_ns = max(self.last_ns, log_time_ns)
        times = self._chunk_times
        self._chunk_times = [min(times[0], log_time_ns), max(times[1], log_time_ns)] if times else [log_time_ns] * 2
        if len(self._chunk) >= CHUNK_BYTES:
            self._close_chunk()

    def write(self, channel: int, log_time_ns: int, data: bytes, publish_time_ns: int, sequence: int) -> None:
        """One message (a view's)."""
        builder = RecordBuilder()
        Message(channel_id=channel, log_time=log_time_ns, data=data, publish_time=publish_time_ns,
                sequence=sequence & 0xFFFFFFFF).write(builder)
        offset = len(self._chunk)
        self._chunk += builder.end()
        self._added(channel, log_time_ns, np.array([offset], np.uint64))

    def write_samples(self, channel: int, samples: np.ndarray, log_time_ns: int) -> None:
        """Samples drained from a ring (`streams.sample_dtype`): each with its number as the
        sequence and its publication stamp as the publish time."""
        n = len(samples)
        if not n:
            return
        template = self._templates[channel]
        if len(template) < n:  # the constant fields (opcode, length, channel, the payload's prefix), laid out once
            layout, prefix = self._batches[channel]
            template = np.zeros(max(n, 2 * len(template), 64), layout)
            template["opcode"] = 0x05  # Message
            template["length"] = layout.itemsize - 9
            template["channel"] = channel
            template["data"][:, :len(prefix)] = prefix
            self._templates[channel] = template
        records = template[:n].copy()
        records["sequence"] = samples["count"] & np.uint64(0xFFFFFFFF)
        records["log_time"] = log_time_ns
        records["publish_time"] = samples["stamp_ns"]
        records["data"][:, -samples["payload"].shape[1]:] = samples["payload"]
        offsets = len(self._chunk) + np.arange(n, dtype=np.uint64) * np.uint64(template.itemsize)
        self._chunk += records.tobytes()
        self._added(channel, log_time_ns, offsets)

    def _close_chunk(self) -> None:
        if not self._chunk:
            return
        data = bytes(self._chunk)
        start, end = self._chunk_times
        compressed = zstandard.compress(data)
        chunk_offset, chunk_length = self._write(Chunk(
            compression="zstd", data=compressed, message_start_time=start, message_end_time=end,
            uncompressed_crc=zlib.crc32(data), uncompressed_size=len(data)))
        index_offsets, indexes = {}, bytearray()
        for channel, parts in self._index.items():
            pairs = np.empty((sum(len(o) for _, o in parts), 2), "<u8")
            pairs[:, 0] = np.concatenate([np.full(len(o), t, np.uint64) for t, o in parts])
            pairs[:, 1] = np.concatenate([o for _, o in parts])
            index_offsets[channel] = chunk_offset + chunk_length + len(indexes)
            body = pairs.tobytes()
            indexes += struct.pack("<BQHI", 0x07, 2 + 4 + len(body), channel, len(body)) + body  # MessageIndex
        self._out.write(indexes)
        self._chunk_indexes.append(ChunkIndex(
            message_start_time=start, message_end_time=end, chunk_start_offset=chunk_offset,
            chunk_length=chunk_length, message_index_offsets=index_offsets, message_index_length=len(indexes),
            compression="zstd", compressed_size=len(compressed), uncompressed_size=len(data)))  # the records' bytes
        self._chunk.clear()
        self._chunk_times = []
        self._index = {}

    # -- the rest of the file ----------------------------------------------------------------
    def attach(self, name: str, media_type: str, data: bytes, time_ns: int) -> None:
        offset, length = self._write(Attachment(create_time=time_ns, log_time=time_ns, name=name,
                                                media_type=media_type, data=data))
        self._attachment_indexes.append(AttachmentIndex(offset=offset, length=length, log_time=time_ns,
                                                        create_time=time_ns, data_size=len(data), name=name,
                                                        media_type=media_type))

    def metadata(self, name: str, values: dict[str, str]) -> None:
        offset, length = self._write(Metadata(name=name, metadata={k: str(v) for k, v in values.items()}))
        self._metadata_indexes.append(MetadataIndex(offset=offset, length=length, name=name))

    def flush(self) -> None:
        """Close the open chunk and hand it to the OS: a kill from now on cannot lose it."""
        self._close_chunk()
        self._out.flush()

    def finish(self) -> Path:
        """Write the summary (what readers seek by), close, and take the final name."""
        self._close_chunk()
        self._write(DataEnd(data_section_crc=0))
        summary_start = self._out.tell()
        builder = RecordBuilder()
        offsets = []
        statistics = Statistics(
            message_count=self.messages, schema_count=len(self._schemas), channel_count=len(self._channels),
            attachment_count=len(self._attachment_indexes), metadata_count=len(self._metadata_indexes),
            chunk_count=len(self._chunk_indexes), message_start_time=self.first_ns or 0,
            message_end_time=self.last_ns, channel_message_counts=dict(self.counts))
        for opcode, records in ((Opcode.SCHEMA, list(self._schemas.values())),
                                (Opcode.CHANNEL, list(self._channels.values())), (Opcode.STATISTICS, [statistics]),
                                (Opcode.CHUNK_INDEX, self._chunk_indexes),
                                (Opcode.ATTACHMENT_INDEX, self._attachment_indexes),
                                (Opcode.METADATA_INDEX, self._metadata_indexes)):
            group_start = builder.count
            for record in records:
                record.write(builder)
            offsets.append(SummaryOffset(group_opcode=opcode, group_start=summary_start + group_start,
                                         group_length=builder.count - group_start))
        summary_offset_start = summary_start + builder.count
        for offset in offsets:
            offset.write(builder)
        summary = builder.end()
        crc = zlib.crc32(struct.pack("<BQQQ", Opcode.FOOTER, 20, summary_start, summary_offset_start),
                         zlib.crc32(summary))
        self._out.write(summary)
        self._write(Footer(summary_start=summary_start, summary_offset_start=summary_offset_start, summary_crc=crc))
        self._out.write(MAGIC)
        self._out.close()
        os.replace(self.part, self.path)
        return self.path

    def abandon(self) -> None:
        """Close without a summary (the `.part` stays, for `hapticop recover`)."""
        self.flush()
        self._out.close()
