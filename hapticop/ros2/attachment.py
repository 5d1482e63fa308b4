"""The attachment rmw_zenoh puts on every sample: sequence number, source time, publisher GID.

33 bytes as zenoh-cpp's serializer writes them (rmw_zenoh's `attachment_helpers.cpp`): int64 sequence
number and int64 source timestamp (ns since the Unix epoch), little-endian, then the 16-byte GID with
its length as one LEB128 byte (16). Older rmw_zenoh builds (2024) sent a key-to-bytes map instead;
those are refused as malformed.
"""

from __future__ import annotations

import struct

ATTACHMENT = struct.Struct("<qqB16s")
GID_SIZE = 16


def pack(sequence: int, stamp_ns: int, gid: bytes) -> bytes:
    return ATTACHMENT.pack(sequence, stamp_ns, GID_SIZE, gid)


def unpack(data: bytes) -> tuple[int, int, bytes] | None:
    """(sequence, source time in ns, GID), or None when it is not rmw_zenoh's attachment."""
    if len(data) != ATTACHMENT.size:
        return None
    sequence, stamp_ns, length, gid = ATTACHMENT.unpack(data)
    return None if length != GID_SIZE else (sequence, stamp_ns, gid)
