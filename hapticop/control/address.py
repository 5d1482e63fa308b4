"""Where a running system's control socket is, and who may talk to it (the same user, or root).

Both ends of the control channel need this: the server (`server.py`) to listen and check each
connection's peer, the client (`client.py`) to find a system by its name and check the server.
"""

from __future__ import annotations

import os
import socket
import struct
from pathlib import Path

MAX_REQUEST_BYTES = 1 << 20  # a patch is at most a composition's size (1 MiB)
MAX_REPLY_BYTES = 16 << 20

class ControlError(Exception):
    """The control channel could not be set up or reached; the message says why."""


def socket_path(system: str) -> Path:
    """Where the system's control socket is.

    A value with a '/' or ending in '.sock' is the socket's path; anything else is a system
    name: `$XDG_RUNTIME_DIR/hapticop/NAME.sock`, or `/run/hapticop/NAME.sock` for root
    without XDG_RUNTIME_DIR, or `/tmp/hapticop-UID/NAME.sock`.
    """
    if not is_system_name(system):
        return Path(system)
    if not system or system in (".", ".."):
        raise ControlError(f"{system!r} is not a system name")
    runtime_dir = os.environ.get("XDG_RUNTIME_DIR")
    if runtime_dir:
        return Path(runtime_dir) / "hapticop" / f"{system}.sock"
    uid = os.geteuid()
    if uid == 0:
        return Path("/run/hapticop") / f"{system}.sock"
    return Path(f"/tmp/hapticop-{uid}") / f"{system}.sock"


def is_system_name(system: str) -> bool:
    """A system's name, whose socket goes in the default directory (else: the socket's own path)."""
    return not ("/" in system or system.endswith(".sock"))


def peer_uid(connection: socket.socket) -> int | None:
    """The user id of the process at the other end, or None where SO_PEERCRED is missing."""
    if not hasattr(socket, "SO_PEERCRED"):
        return None
    credentials = connection.getsockopt(socket.SOL_SOCKET, socket.SO_PEERCRED, struct.calcsize("3i"))
    _pid, uid, _gid = struct.unpack("3i", credentials)
    return uid


def peer_pid(connection: socket.socket) -> int | None:
    if not hasattr(socket, "SO_PEERCRED"):
        return None
    return struct.unpack("3i", connection.getsockopt(socket.SOL_SOCKET, socket.SO_PEERCRED, struct.calcsize("3i")))[0]


def allowed(uid: int | None) -> bool:
    return uid is None or uid in (os.geteuid(), 0)
