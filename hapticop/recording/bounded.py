"""Reading an MCAP file that may be hostile: recordings are files people mail each other.

Every command that reads a recording opens it here. What a file declares is never trusted
with memory or time: only a regular file is opened, without blocking (a FIFO or a device is
refused, not waited on); no read asks for more than the file still holds (a length field of
3 GiB in a 1 kB file reads 1 kB and fails as a short record); a chunk is inflated to at most
`MAX_CHUNK_BYTES` and the whole file to at most `MAX_RATIO` times its size (a 100 kB chunk that
inflates to 1 GiB is refused after 64 MiB). Whatever else a damaged file breaks in the MCAP
library ends as a `RecordingError`, one line naming the file.
"""

from __future__ import annotations

import os
import stat
import struct
from collections.abc import Iterator
from pathlib import Path
from typing import BinaryIO

from mcap.exceptions import McapError
from mcap.records import Chunk, McapRecord
from mcap.stream_reader import StreamReader, breakup_chunk

MAX_CHUNK_BYTES = 64 << 20  # a chunk inflated: the recorder closes its chunks at 4 MiB
MAX_RATIO = 100  # the whole file inflated, past MAX_CHUNK_BYTES: a recording compresses about 3 to 10 times

# What the MCAP library and the decompressors raise on bytes that are not what they declare.
BROKEN = (McapError, ValueError, EOFError, struct.error, KeyError, IndexError, OverflowError, UnicodeDecodeError,
          RuntimeError, RecursionError)


class RecordingError(Exception):
    """A file that is not a readable recording, said in words."""


def _kind(mode: int) -> str:
    for test, name in ((stat.S_ISDIR, "a directory"), (stat.S_ISFIFO, "a FIFO"), (stat.S_ISCHR, "a character device"),
                       (stat.S_ISBLK, "a block device"), (stat.S_ISSOCK, "a socket")):
        if test(mode):
            return name
    return "a special file"


class Clamped:
    """A regular file whose reads never ask for more than it holds from where they start."""

    def __init__(self, handle: BinaryIO, size: int):
        self.handle, self.size = handle, size

    def read(self, n: int = -1) -> bytes:
        left = max(self.size - self.handle.tell(), 0)
        return self.handle.read(left if n is None or n < 0 else min(n, left))

    def seek(self, offset: int, whence: int = os.SEEK_SET) -> int:
        return self.handle.seek(offset, whence)

    def tell(self) -> int:
        return self.handle.tell()

    def seekable(self) -> bool:
        return True

    def close(self) -> None:
        self.handle.close()

    def __enter__(self) -> Clamped:
        return self

    def __exit__(self, *_) -> None:
        self.close()


def open_recording(path: str | Path) -> Clamped:
    """`path` opened for reading if it is a regular file, without ever blocking on it."""
    path = Path(path)
    try:
        mode = os.stat(path).st_mode
        if not stat.S_ISREG(mode):
            raise RecordingError(f"cannot read {path}: it is {_kind(mode)}, not a recording")
        descriptor = os.open(path, os.O_RDONLY | os.O_NONBLOCK | os.O_NOCTTY)
        handle = os.fdopen(descriptor, "rb")
    except OSError as error:
        raise RecordingError(f"cannot read {path}: {error.strerror or error}") from None
    except ValueError as error:  # a NUL byte in the name
        raise RecordingError(f"cannot read {path}: {error}") from None
    status = os.fstat(handle.fileno())
    if not stat.S_ISREG(status.st_mode):  # replaced between the two looks
        handle.close()
        raise RecordingError(f"cannot read {path}: it is {_kind(status.st_mode)}, not a recording")
    return Clamped(handle, status.st_size)


class Inflater:
    """Chunks inflated within the file's budget: `MAX_CHUNK_BYTES` each, `MAX_RATIO` times the file in all."""

    def __init__(self, path: Path, size: int):
        self.path, self.left = path, max(MAX_CHUNK_BYTES, MAX_RATIO * size)

    def __call__(self, chunk: Chunk) -> bytes:
        limit = min(MAX_CHUNK_BYTES, self.left)
        if chunk.uncompressed_size > limit:
            raise RecordingError(self._too_large(chunk.uncompressed_size))
        if chunk.compression in ("zstd", "lz4"):
            try:
                data = _inflated(chunk, limit + 1)
            except Exception as error:  # noqa: BLE001 - each decompressor has its own error types
                raise RecordingError(f"{self.path}: a chunk does not inflate ({type(error).__name__}: "
                                     f"{str(error)[:120]}): the file is damaged") from None
        elif chunk.compression == "":
            data = chunk.data
        else:
            raise RecordingError(f"{self.path}: a chunk is compressed as '{chunk.compression}', which hapticop "
                                 "does not read")
        if len(data) > limit:
            raise RecordingError(self._too_large(len(data), inflated=True))
        if len(data) != chunk.uncompressed_size:
            raise RecordingError(f"{self.path}: a chunk inflates to {len(data)} bytes, not the "
                                 f"{chunk.uncompressed_size} it declares: the file is damaged")
        self.left -= len(data)
        return data

    def _too_large(self, size: int, inflated: bool = False) -> str:
        said = "inflates to more than" if inflated else "declares"
        return (f"{self.path}: a chunk {said} {size} bytes, more than hapticop inflates ({MAX_CHUNK_BYTES >> 20} MiB "
                f"a chunk, {MAX_RATIO} times the file in all): not a recording hapticop wrote")


def check_chunks(stream: Clamped, chunk_indexes, path: Path) -> None:
    """Each chunk the summary indexes is where it says, as long as it says, and within what is
    inflated: a damaged chunk is found by `hapticop info`, which reads no chunk, as by a reading."""
    for index in chunk_indexes:
        where = f"{path}: the chunk at byte {index.chunk_start_offset}"
        if index.chunk_start_offset + index.chunk_length > stream.size:
            raise RecordingError(f"{where} is indexed as {index.chunk_length} bytes, past the end of the file")
        if index.uncompressed_size > MAX_CHUNK_BYTES:
            raise RecordingError(f"{where} declares {index.uncompressed_size} bytes inflated, more than hapticop "
                                 f"inflates ({MAX_CHUNK_BYTES >> 20} MiB a chunk)")
        stream.seek(index.chunk_start_offset)
        head = stream.read(1 + 8 + 8 + 8 + 8 + 4 + 4)
        if len(head) < 41:
            raise RecordingError(f"{where} is cut short")
        opcode, length, _, _, inflated, _, named = struct.unpack("<BQQQQII", head)
        compression = stream.read(named)
        data = stream.read(8)
        records_length = struct.unpack("<Q", data)[0] if len(data) == 8 else -1
        if (opcode != 0x06 or length != index.chunk_length - 9 or inflated != index.uncompressed_size
                or compression.decode(errors="replace") != index.compression
                or records_length != length - (8 + 8 + 8 + 4 + 4 + named + 8)):
            raise RecordingError(f"{where} is not the chunk its index describes: the file is damaged")


def _inflated(chunk: Chunk, most: int) -> bytes:
    """At most `most` bytes of the chunk inflated, whatever its frames declare."""
    if chunk.compression == "zstd":
        import zstandard

        return zstandard.ZstdDecompressor().stream_reader(chunk.data, read_across_frames=True).read(most)
    import lz4.frame

    return lz4.frame.LZ4FrameDecompressor().decompress(chunk.data, max_length=most)


def records(stream, path: Path, size: int) -> Iterator[McapRecord]:
    """Every record of the file in order, a chunk's records in place of the chunk, each chunk
    inflated within the budget. No record may declare more bytes than the file holds."""
    inflate = Inflater(path, size)
    for record in StreamReader(stream, record_size_limit=size, emit_chunks=True).records:
        if isinstance(record, Chunk):
            data = inflate(record)
            yield from breakup_chunk(Chunk(compression="", data=data, message_end_time=record.message_end_time,
                                           message_start_time=record.message_start_time,
                                           uncompressed_crc=record.uncompressed_crc,
                                           uncompressed_size=len(data)))
        else:
            yield record
