"""Rewriting what a killed run left (`RUN.mcap.part`) into a valid MCAP file, and saying what was lost.

A killed recorder leaves every chunk it flushed, complete, and at most one chunk cut short
after them; the summary and the drop counts written at close are missing. The records are
read in order, as far as they are whole, and written again by a new writer, which adds the
indexes and the summary.
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path

from mcap.records import Attachment, Channel, DataEnd, Footer, Message, Metadata, Schema
from mcap.writer import CompressionType, Writer

from hapticop.recording.bounded import RecordingError, open_recording, records
from hapticop.recording.mcapfile import CHUNK_BYTES, PART


class _Counting:
    """A binary file that knows how far it was read: where the last whole record ended."""

    def __init__(self, stream):
        self.stream, self.offset = stream, 0

    def read(self, n: int = -1) -> bytes:
        data = self.stream.read(n)
        self.offset += len(data)
        return data


@dataclass
class Recovered:
    source: Path
    target: Path
    size: int  # bytes of the damaged file
    kept_bytes: int  # up to the end of the last whole record
    complete: bool  # the file had its footer: nothing was lost
    messages: Counter = field(default_factory=Counter)  # per topic
    first_ns: int | None = None
    last_ns: int | None = None
    problem: str = ""  # why reading stopped

    @property
    def lost_bytes(self) -> int:
        return self.size - self.kept_bytes

    def describe(self) -> list[str]:
        span = (self.last_ns - self.first_ns) / 1e9 if self.messages else 0.0
        lines = [f"recovered {sum(self.messages.values())} messages on {len(self.messages)} channels, "
                 f"{span:.3f} s of log time, into {self.target}"]
        for topic, count in sorted(self.messages.items()):
            lines.append(f"  {topic}: {count}")
        if self.complete:
            lines.append("nothing was lost: the file was finished")
        else:
            lines.append(f"lost: the last {self.lost_bytes} of {self.size} bytes ({self.problem}): what the "
                         "recorder had not flushed (at most about a second of samples), and the drop counts "
                         "written when a recording finishes")
        return lines


def target_of(source: Path) -> Path:
    name = source.name[: -len(PART)] if source.name.endswith(PART) else f"{source.stem}.recovered{source.suffix}"
    return source.with_name(name)


def recover(source: Path, target: Path | None = None) -> Recovered:
    """Rewrite `source` into `target` (default: its name without `.part`); never overwrites.

    A special file is refused (`RecordingError`) before anything is written; what the file
    declares is bounded as every reading is (`bounded`), and a record that breaks a bound ends
    the recovery there, as a cut-off one does."""
    target = target or target_of(source)
    raw = open_recording(source)
    if target.exists():
        raw.close()
        raise FileExistsError(f"{target} exists; say where to write with -o")
    found = Recovered(source, target, raw.size, 0, False)
    schemas: dict[int, int] = {}
    channels: dict[int, tuple[int, str]] = {}
    with raw, open(target, "wb") as out:
        counting = _Counting(raw)
        writer = Writer(out, chunk_size=CHUNK_BYTES, compression=CompressionType.ZSTD)
        writer.start(profile="", library="hapticop recover")
        try:
            for record in records(counting, source, found.size):
                found.kept_bytes = counting.offset
                if isinstance(record, Schema) and record.id not in schemas:
                    schemas[record.id] = writer.register_schema(record.name, record.encoding, record.data)
                elif isinstance(record, Channel) and record.id not in channels:
                    channels[record.id] = (writer.register_channel(record.topic, record.message_encoding,
                                                                   schemas.get(record.schema_id, 0),
                                                                   dict(record.metadata)), record.topic)
                elif isinstance(record, Message) and record.channel_id in channels:
                    channel, topic = channels[record.channel_id]
                    writer.add_message(channel, record.log_time, record.data, record.publish_time, record.sequence)
                    found.messages[topic] += 1
                    found.first_ns = min(found.first_ns or record.log_time, record.log_time)
                    found.last_ns = max(found.last_ns or record.log_time, record.log_time)
                elif isinstance(record, Attachment):
                    writer.add_attachment(record.create_time, record.log_time, record.name, record.media_type,
                                          record.data)
                elif isinstance(record, Metadata):
                    writer.add_metadata(record.name, dict(record.metadata))
                elif isinstance(record, (DataEnd, Footer)):
                    found.complete = True
                    break
            else:
                found.problem = "the file ends after its last whole record"
        except RecordingError as error:
            found.problem = str(error).removeprefix(f"{source}: ")
        except Exception as error:  # noqa: BLE001 - a cut-off tail breaks a record in many ways
            found.problem = f"an unfinished record: {type(error).__name__}"
        writer.finish()
    found.kept_bytes = found.size if found.complete else found.kept_bytes
    return found
