"""What crosses between two bridges, as bytes: samples, pings, pongs and each host's state.

Every sample carries its sender's session (a new number each time a bridge starts, so a restarted
peer's sequence numbers are not taken for old ones), its sequence number and its send time on the
sender's clock; the value's bytes follow, in the stream's dtype and shape, which both sides know
from the composition.
"""

from __future__ import annotations

import struct

SAMPLE = struct.Struct("<QQq")  # session, sequence, send time (ns, sender's clock)
PING = struct.Struct("<QQq")  # session, slot, t1
# slot, t1, t2, t3, held (how long the ping waited in an emulated link); then the answering host's name
PONG = struct.Struct("<Qqqqq")
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
