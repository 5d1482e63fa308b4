"""A stream's samples as protobuf messages: one field holding the array's raw little-endian bytes.

A packed `repeated double` (or float, sfixed32, ...) field is, on the wire, a tag, a length
and the elements' bytes as they lie in memory; so is a `bytes` field. Every sample of a
stream is therefore its fixed prefix followed by the sample's bytes: no protobuf library is
needed to write or read it, yet Foxglove and other viewers decode and plot it with the
schema stored beside it (a FileDescriptorSet, built here by hand).
"""

from __future__ import annotations

import numpy as np

SCHEMA_ENCODING = "protobuf"
MESSAGE_ENCODING = "protobuf"
PACKAGE = "hapticop"

# FieldDescriptorProto.Type: fixed-size element types whose packed encoding is the raw array
_TYPES = {"float64": ("Float64Array", 1), "float32": ("Float32Array", 2), "uint64": ("UInt64Array", 6),
          "uint32": ("UInt32Array", 7), "int32": ("Int32Array", 15), "int64": ("Int64Array", 16)}
_BYTES = ("Bytes", 12)  # anything else (uint8, bool, int16...): one bytes field; dtype and shape in the metadata
_LABEL_OPTIONAL, _LABEL_REPEATED = 1, 3


def _varint(value: int) -> bytes:
    out = bytearray()
    while True:
        byte = value & 0x7F
        value >>= 7
        if value:
            out.append(byte | 0x80)
        else:
            out.append(byte)
            return bytes(out)


def _field(number: int, payload: bytes | str | int) -> bytes:
    """One field of a message: length-delimited for bytes and text, varint for integers."""
    if isinstance(payload, int):
        return _varint(number << 3) + _varint(payload)
    data = payload.encode() if isinstance(payload, str) else payload
    return _varint(number << 3 | 2) + _varint(len(data)) + data


def schema_name(dtype: str) -> str:
    return f"{PACKAGE}.{_TYPES.get(np.dtype(dtype).name, _BYTES)[0]}"


def schema_data(dtype: str) -> bytes:
    """A FileDescriptorSet with the one message type samples of `dtype` are written as."""
    message, kind = _TYPES.get(np.dtype(dtype).name, _BYTES)
    label = _LABEL_OPTIONAL if kind == _BYTES[1] else _LABEL_REPEATED
    field = _field(1, "data") + _field(3, 1) + _field(4, label) + _field(5, kind) + _field(10, "data")
    descriptor = _field(1, message) + _field(2, field)
    file = _field(1, f"{PACKAGE}/{message}.proto") + _field(2, PACKAGE) + _field(4, descriptor) + _field(12, "proto3")
    return _field(1, file)


def prefix(nbytes: int) -> bytes:
    """What comes before a sample's `nbytes` bytes: field 1, length-delimited."""
    return b"\x0a" + _varint(nbytes)


def decode(data: bytes, dtype: str, shape: tuple[int, ...]) -> np.ndarray:
    """A recorded sample back as its array."""
    element = np.dtype(dtype).newbyteorder("<")
    nbytes = element.itemsize * int(np.prod(shape, dtype=np.int64))
    return np.frombuffer(data, dtype=element, count=nbytes // element.itemsize,
                         offset=len(prefix(nbytes))).reshape(shape)
