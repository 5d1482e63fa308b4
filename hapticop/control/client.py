"""The client's end of the control channel: one request to a running system, one reply (`hapticop
patch`, `status`, `view`)."""

from __future__ import annotations

import errno
import json
import os
import socket

from hapticop.control.address import MAX_REPLY_BYTES, MAX_REQUEST_BYTES, ControlError, allowed, peer_uid, socket_path


class _TooLarge(Exception):
    pass


def _read_line(connection: socket.socket, limit: int) -> bytes:
    """Bytes up to the first newline (or the end of the stream), at most `limit` of them."""
    data = bytearray()
    while True:
        chunk = connection.recv(65536)
        if not chunk:
            return bytes(data)
        newline = chunk.find(b"\n")
        if newline >= 0:
            data += chunk[:newline]
            if len(data) > limit:
                raise _TooLarge
            return bytes(data)
        data += chunk
        if len(data) > limit:
            raise _TooLarge


def request(system_or_path: str | os.PathLike, message: dict, timeout: float = 5.0) -> dict:
    """Send one request to a running system and return its reply, or raise `ControlError`."""
    path = socket_path(os.fspath(system_or_path))
    text = str(system_or_path)
    who = f"'{text}'" if ("/" not in text and not text.endswith(".sock")) else f"at {path}"
    data = json.dumps(message).encode("utf-8") + b"\n"
    if len(data) > MAX_REQUEST_BYTES:
        raise ControlError(f"the request is larger than {MAX_REQUEST_BYTES} bytes")
    client = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    client.settimeout(timeout)
    try:
        try:
            client.connect(str(path))
        except FileNotFoundError:
            raise ControlError(f"no hapticop system {who} is running (no socket at {path})") from None
        except ConnectionRefusedError:
            raise ControlError(f"no hapticop system {who} is running (nothing listens at {path}; "
                               "the socket was left by a process that is gone)") from None
        except PermissionError:
            raise ControlError(f"cannot reach the hapticop system {who}: permission denied on {path} "
                               "(it belongs to another user)") from None
        except TimeoutError:
            raise ControlError(f"the hapticop system {who} did not accept a connection within {timeout:g} s") from None
        except OSError as error:
            if error.errno in (errno.ENOTSOCK, errno.ENOTDIR):
                raise ControlError(f"no hapticop system {who} is running ({path} is not a socket)") from None
            raise ControlError(f"cannot reach the hapticop system {who} at {path}: {error.strerror or error}") from None
        server_uid = peer_uid(client)
        if os.geteuid() != 0 and not allowed(server_uid):
            raise ControlError(f"refusing to talk to {path}: it is served by uid {server_uid}, not by you or root")
        try:
            try:
                client.sendall(data)
            except (BrokenPipeError, ConnectionResetError):
                pass  # refused before it read everything (busy, too large): its reply says why
            line = _read_line(client, MAX_REPLY_BYTES)
        except TimeoutError:
            raise ControlError(f"the hapticop system {who} did not answer within {timeout:g} s") from None
        except _TooLarge:
            raise ControlError(
                f"the reply of the hapticop system {who} is larger than {MAX_REPLY_BYTES} bytes") from None
        except OSError as error:
            raise ControlError(
                f"the connection to the hapticop system {who} failed: {error.strerror or error}") from None
    finally:
        client.close()
    if not line:
        raise ControlError(f"the hapticop system {who} closed the connection without answering")
    try:
        reply = json.loads(line)
    except (UnicodeDecodeError, ValueError):
        raise ControlError(f"the hapticop system {who} answered something that is not JSON") from None
    if not isinstance(reply, dict):
        raise ControlError(f"the hapticop system {who} answered a JSON {type(reply).__name__}, not an object")
    return reply
