"""The part of Foxglove's WebSocket protocol the live view serves, as messages: no sockets here.

Foxglove's protocol (`foxglove.websocket.v1`; `foxglove.sdk.v1` is what the SDK's server and today's
Foxglove app negotiate, with the same messages) has the server send `serverInfo` on connection,
`advertise` for its channels, and each message as a binary frame: opcode 1, the client's
subscription id (u32 LE), the log time (u64 LE, ns) and the payload. A client only subscribes and
unsubscribes: the live view offers no capability (no publishing, parameters or services), so
anything else a client sends breaks the protocol and `ProtocolViolation` says how.
"""

from __future__ import annotations

import base64
import json
import struct
from collections.abc import Container
from dataclasses import dataclass, field

SUBPROTOCOLS = ("foxglove.sdk.v1", "foxglove.websocket.v1")  # preferred first
MESSAGE_DATA = 0x01
_HEADER = struct.Struct("<BIQ")
_BINARY_SCHEMAS = frozenset({"protobuf", "flatbuffer"})  # sent base64; other schemas as text
_U32 = 0xFFFF_FFFF


class ProtocolViolation(ValueError):
    """What a client sent that the live view does not serve; the client is closed with it."""


@dataclass(frozen=True)
class Advertised:
    """One channel as clients see it."""

    id: int
    topic: str
    encoding: str
    schema_name: str = ""
    schema_encoding: str = ""
    schema: bytes = b""
    metadata: dict[str, str] = field(default_factory=dict)

    def as_json(self) -> dict:
        binary = self.schema_encoding in _BINARY_SCHEMAS
        channel = {"id": self.id, "topic": self.topic, "encoding": self.encoding, "schemaName": self.schema_name,
                   "schema": base64.b64encode(self.schema).decode() if binary else self.schema.decode()}
        if self.schema_encoding:
            channel["schemaEncoding"] = self.schema_encoding
        if self.metadata:
            channel["metadata"] = dict(self.metadata)
        return channel


def server_info(name: str, session_id: str) -> str:
    return json.dumps({"op": "serverInfo", "name": name, "capabilities": [], "metadata": {}, "sessionId": session_id})


def advertise(channels: list[Advertised]) -> str:
    return json.dumps({"op": "advertise", "channels": [c.as_json() for c in channels]})


def message_data(subscription: int, log_time_ns: int, payload: bytes) -> bytes:
    """A message's frame; a time before the clock's zero is sent as zero (the field is unsigned)."""
    return _HEADER.pack(MESSAGE_DATA, subscription, max(0, log_time_ns)) + payload


def client_op(text: str, channels: Container[int]) -> tuple[str, list]:
    """A client's message: ('subscribe', [(subscription, channel)]) or ('unsubscribe', [subscription])."""
    try:
        op = json.loads(text)
    except (ValueError, RecursionError):
        raise ProtocolViolation("not JSON") from None
    if not isinstance(op, dict):
        raise ProtocolViolation("not a JSON object")
    if op.get("op") == "subscribe":
        wanted = op.get("subscriptions")
        if not isinstance(wanted, list):
            raise ProtocolViolation("subscribe without a list of subscriptions")
        pairs = []
        for entry in wanted:
            if not isinstance(entry, dict):
                raise ProtocolViolation("a subscription that is no object")
            subscription, channel = _u32(entry.get("id")), _u32(entry.get("channelId"))
            if channel not in channels:
                raise ProtocolViolation(f"no channel {channel}")
            pairs.append((subscription, channel))
        return "subscribe", pairs
    if op.get("op") == "unsubscribe":
        ids = op.get("subscriptionIds")
        if not isinstance(ids, list):
            raise ProtocolViolation("unsubscribe without a list of subscription ids")
        return "unsubscribe", [_u32(i) for i in ids]
    raise ProtocolViolation(f"unsupported op {str(op.get('op'))[:40]!r}")


def _u32(value: object) -> int:
    if type(value) is not int or not 0 <= value <= _U32:
        raise ProtocolViolation("an id that is no 32-bit unsigned integer")
    return value
