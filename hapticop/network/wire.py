"""What crosses between two bridges, as bytes: samples, pings, pongs and each host's state.

Every sample carries its sender's session (a new number each time a bridge starts, so a restarted
peer's sequence numbers are not taken for old ones), its sequence number and its send time on the
sender's clock; the value's bytes follow, in the stream's dtype and shape, which both sides know
from the composition.

A ping carries a nonce its pong must return with the asking session, so only an answer to a ping
this bridge sent (and from the session of the host it asked) can move the clock estimate. Whatever
arrives is read defensively by the bridge (docs/teleop.md, "What the link refuses").
"""

from __future__ import annotations

import struct

SAMPLE = struct.Struct("<QQq")  # session, sequence, send time (ns, sender's clock)
PING = struct.Struct("<QQQq")  # session, slot, nonce, t1
# the asker's session, slot, nonce, t1, t2, t3, held (how long the ping waited in an emulated link), the
# answerer's session; then the answering host's name
PONG = struct.Struct("<QQQqqqqQ")
STATE = struct.Struct("<Q?")  # session, ended; then the names of the exported places holding, comma-separated


def sample_key(system: str, stream: str) -> str:
    return f"hapticop/{system}/stream/{stream}"


def ping_key(system: str, host: str) -> str:
    return f"hapticop/{system}/ping/{host}"


def pong_key(system: str, host: str) -> str:
    """Pongs answering the pings of `host`."""
    return f"hapticop/{system}/pong/{host}"


def state_key(system: str, host: str) -> str:
    return f"hapticop/{system}/state/{host}"
