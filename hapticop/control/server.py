"""The control channel of a running system: one JSON line in, one JSON line out.

A running system listens on a Unix domain socket in a directory only its owner can
enter; the socket itself is mode 0600 and every connection's peer credentials are
checked (SO_PEERCRED), so only the same user, or root, can patch or query it.
`hapticop patch` and `hapticop status` talk to it with `client.request`; `address.py` says where it
is and who may talk to it.

One thread serves every client with non-blocking reads, each client with its own buffer, size
limit and deadline, so a slow, idle or malformed client delays no one and cannot stop the server.
Complete requests are handled one at a time in that thread, in the order they complete: a
handler never runs concurrently with itself.
"""

from __future__ import annotations

import json
import os
import re
import select
import selectors
import socket
import stat
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

from hapticop.control.address import MAX_REQUEST_BYTES, ControlError, allowed, peer_pid, peer_uid

MAX_DEPTH = 64  # a request's arrays and objects nest no deeper (a patch is a string in it)
MAX_CLIENTS = 32  # served at once; as many more are told "busy", the rest wait to be accepted
READ_DEADLINE = 2.0  # seconds a client may take to send its whole request line
WRITE_DEADLINE = 5.0  # seconds a client may take to read its reply
DRAIN_DEADLINE = 0.5  # seconds a client's leftover bytes are read after its reply

Handler = Callable[[dict], dict]


class ControlServer:
    """Serves `handler(request) -> reply` on a Unix socket until `stop()`."""

    def __init__(self, path: str | os.PathLike, handler: Handler):
        self.path = Path(path)
        self.handler = handler
        self._listener: socket.socket | None = None
        self._thread: threading.Thread | None = None
        self._wake_read: socket.socket | None = None
        self._wake_write: socket.socket | None = None
        self._stopping = threading.Event()
        self._inode: int | None = None
        self._asking: socket.socket | None = None  # the connection whose request the handler is answering

    def client_present(self) -> bool:
        """While the handler runs (on the server's thread): whether the client that asked is still
        connected, so that nothing is done on behalf of a client that left. A client that only shut
        down its sending side still waits for its answer, and is present."""
        connection = self._asking
        if connection is None:
            return True
        poller = select.poll()
        poller.register(connection, select.POLLHUP | select.POLLERR)
        try:
            return not poller.poll(0)
        except OSError:
            return False

    # -- life cycle ----------------------------------------------------------------

    def start(self) -> ControlServer:
        if self._listener is not None:
            raise ControlError(f"the control server at {self.path} is already started")
        self._prepare_directory()
        self._clear_stale_socket()
        listener = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
        try:
            listener.bind(str(self.path))
            os.chmod(self.path, 0o600)
            self._inode = os.stat(self.path).st_ino
            listener.listen(MAX_CLIENTS)
            listener.setblocking(False)
        except OSError as error:
            listener.close()
            raise ControlError(f"cannot listen at {self.path}: {error.strerror or error}") from None
        self._listener = listener
        self._wake_read, self._wake_write = socket.socketpair()
        self._stopping.clear()
        self._thread = threading.Thread(target=self._serve, name=f"hapticop-control {self.path.name}", daemon=True)
        self._thread.start()
        return self

    def stop(self, timeout: float = 5.0) -> None:
        if self._listener is None:
            return
        self._stopping.set()
        try:
            self._wake_write.send(b"x")
        except OSError:
            pass
        if self._thread is not None and self._thread is not threading.current_thread():
            self._thread.join(timeout)
        self._listener.close()
        for end in (self._wake_read, self._wake_write):
            end.close()
        try:
            # Only our own socket: a newer server may have replaced it since.
            if os.stat(self.path).st_ino == self._inode:
                self.path.unlink()
        except FileNotFoundError:
            pass
        self._listener = self._thread = self._wake_read = self._wake_write = None

    def __enter__(self) -> ControlServer:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()

    @property
    def running(self) -> bool:
        return self._thread is not None and self._thread.is_alive()

    def _prepare_directory(self) -> None:
        directory = self.path.parent
        try:
            directory.mkdir(mode=0o700)
            os.chmod(directory, 0o700)  # mkdir's mode is filtered by the umask
        except FileExistsError:
            pass
        except OSError as error:
            raise ControlError(f"cannot create {directory} for the control socket: {error.strerror or error}") from None
        info = os.stat(directory)
        if not stat.S_ISDIR(info.st_mode):
            raise ControlError(f"{directory} is not a directory")
        # Someone else's directory, or one anyone may replace our socket in, is refused.
        if info.st_uid not in (os.geteuid(), 0):
            raise ControlError(f"{directory} belongs to another user (uid {info.st_uid}); refusing to put the "
                               "control socket there")
        if info.st_mode & (stat.S_IWGRP | stat.S_IWOTH) and not info.st_mode & stat.S_ISVTX:
            raise ControlError(f"{directory} is writable by other users; refusing to put the control socket there")

    def _clear_stale_socket(self) -> None:
        try:
            info = os.lstat(self.path)
        except FileNotFoundError:
            return
        if not stat.S_ISSOCK(info.st_mode):
            raise ControlError(f"{self.path} exists and is not a socket; refusing to replace it")
        probe = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
        probe.settimeout(1.0)
        try:
            probe.connect(str(self.path))
        except (ConnectionRefusedError, FileNotFoundError):
            try:
                self.path.unlink()  # left by a process that is gone
            except FileNotFoundError:
                pass
            return
        except OSError as error:
            raise ControlError(f"cannot check the existing socket {self.path}: {error.strerror or error}") from None
        else:
            pid = peer_pid(probe)
            raise ControlError(
                f"a hapticop system is already running at {self.path}"
                + (f" (pid {pid})" if pid else "")
                + "; stop it first, or give this one another name"
            )
        finally:
            probe.close()

    # -- serving -------------------------------------------------------------------

    def _serve(self) -> None:
        """One thread multiplexes every client: each has its own buffer and deadline, so a slow or
        idle client never holds up another; requests are still answered one at a time."""
        clients: dict[socket.socket, _Client] = {}
        with selectors.DefaultSelector() as selector:
            selector.register(self._listener, selectors.EVENT_READ)
            selector.register(self._wake_read, selectors.EVENT_READ)
            listening = True
            try:
                while not self._stopping.is_set():
                    now = time.monotonic()
                    timeout = max(0.0, min((c.deadline for c in clients.values()), default=now + 1.0) - now)
                    for key, events in selector.select(timeout):
                        if key.fileobj is self._wake_read or self._stopping.is_set():
                            return
                        if key.fileobj is self._listener:
                            try:
                                self._accept(selector, clients)
                            except Exception:  # noqa: BLE001 - a failed accept is retried at the next event
                                pass
                        elif key.fileobj in clients:
                            client = clients[key.fileobj]
                            try:
                                self._step(selector, clients, client, events)
                            except Exception:  # noqa: BLE001 - one client's failure must not end the server
                                self._close(selector, clients, client)
                    now = time.monotonic()
                    for client in [c for c in clients.values() if c.deadline <= now]:
                        try:
                            self._expire(selector, clients, client)
                        except Exception:  # noqa: BLE001 - as above
                            self._close(selector, clients, client)
                    # A bounded number of connections: the rest wait in the listen backlog.
                    full = len(clients) >= 2 * MAX_CLIENTS
                    if full == listening:
                        listening = not full
                        if full:
                            selector.unregister(self._listener)
                        else:
                            selector.register(self._listener, selectors.EVENT_READ)
            finally:
                for client in clients.values():
                    _flush(client)  # every request that was read gets its answer, also at shutdown
                    client.connection.close()

    def _accept(self, selector: selectors.BaseSelector, clients: dict[socket.socket, _Client]) -> None:
        while len(clients) < 2 * MAX_CLIENTS:
            try:
                connection, _ = self._listener.accept()
            except OSError:  # none left (EAGAIN), or out of descriptors: the others wait in the backlog
                return
            connection.setblocking(False)
            client = _Client(connection, time.monotonic() + READ_DEADLINE)
            clients[connection] = client
            selector.register(connection, selectors.EVENT_READ)
            try:
                uid = peer_uid(connection)
            except OSError:
                uid = -1
            if not allowed(uid):
                self._answer(selector, client, {"ok": False, "error": f"permission denied: this system belongs to "
                                                f"uid {os.geteuid()}, not uid {uid}"})
            elif sum(1 for c in clients.values() if c.phase == "reading") > MAX_CLIENTS:
                self._answer(selector, client, {"ok": False, "error": f"busy: {MAX_CLIENTS} clients are being "
                                                "served; try again"})

    def _step(self, selector: selectors.BaseSelector, clients: dict[socket.socket, _Client], client: _Client,
              events: int) -> None:
        try:
            if events & selectors.EVENT_READ:
                chunk = client.connection.recv(65536)
                client.received += len(chunk)
                if client.phase == "reading":
                    self._read(selector, client, chunk)
                if not chunk or client.received > 2 * MAX_REQUEST_BYTES:
                    client.eof = True  # nothing more to read (or to bother reading)
            if events & selectors.EVENT_WRITE and client.reply:
                del client.reply[:client.connection.send(client.reply)]
                if not client.reply:
                    client.connection.shutdown(socket.SHUT_WR)
                    client.phase, client.deadline = "draining", time.monotonic() + DRAIN_DEADLINE
        except (BlockingIOError, InterruptedError):
            return
        except OSError:
            client.eof, client.phase = True, "done"  # the client went away; nothing to tell it
        if client.phase == "done" or client.eof and client.phase == "draining":
            self._close(selector, clients, client)
        else:
            self._watch(selector, client)

    @staticmethod
    def _watch(selector: selectors.BaseSelector, client: _Client) -> None:
        events = (0 if client.eof else selectors.EVENT_READ) | (selectors.EVENT_WRITE if client.reply else 0)
        selector.modify(client.connection, events or selectors.EVENT_READ)

    def _read(self, selector: selectors.BaseSelector, client: _Client, chunk: bytes) -> None:
        self._asking = client.connection  # the handler may ask whether it is still there (`client_present`)
        if not chunk:
            client.eof = True  # the end of the stream ends the line too
            self._answer(selector, client, self._reply(bytes(client.buffer)))
            return
        newline = chunk.find(b"\n")
        client.buffer += chunk if newline < 0 else chunk[:newline]
        if len(client.buffer) > MAX_REQUEST_BYTES:
            self._answer(selector, client, {"ok": False,
                                            "error": f"the request is larger than {MAX_REQUEST_BYTES} bytes"})
        elif newline >= 0:
            self._answer(selector, client, self._reply(bytes(client.buffer)))

    def _expire(self, selector: selectors.BaseSelector, clients: dict[socket.socket, _Client], client: _Client) -> None:
        if client.phase == "reading":
            got = f"an incomplete request ({len(client.buffer)} bytes, no newline)" if client.buffer else "nothing"
            self._answer(selector, client, {"ok": False, "error": f"no complete request within {READ_DEADLINE:g} s: "
                                            f"got {got}; a request is one JSON object on one line"})
            client.deadline = time.monotonic() + WRITE_DEADLINE
        else:
            self._close(selector, clients, client)  # a client that does not read its reply, or lingers

    def _answer(self, selector: selectors.BaseSelector, client: _Client, reply: dict) -> None:
        client.phase, client.deadline = "writing", time.monotonic() + WRITE_DEADLINE
        client.buffer.clear()
        client.reply = bytearray(_encode(reply))
        self._watch(selector, client)

    @staticmethod
    def _close(selector: selectors.BaseSelector, clients: dict[socket.socket, _Client], client: _Client) -> None:
        clients.pop(client.connection, None)
        try:
            selector.unregister(client.connection)
        except (KeyError, ValueError):
            pass  # never registered, or already closed
        client.connection.close()

    def _reply(self, line: bytes) -> dict:
        if not line.strip():
            return {"ok": False, "error": "empty request: a request is one JSON object on one line"}
        depth = _nesting_depth(line, MAX_DEPTH)
        if depth > MAX_DEPTH:
            return {"ok": False, "error": f"malformed request: nested deeper than {MAX_DEPTH} levels"}
        try:
            message = json.loads(line, parse_constant=_refuse_constant, parse_int=_bounded_int)
        except Exception as error:  # noqa: BLE001 - whatever a parse raises is the client's mistake
            return {"ok": False, "error": f"malformed request: not JSON ({error})"}
        if not isinstance(message, dict):
            return {"ok": False, "error": "malformed request: a request is a JSON object"}
        try:
            reply = self.handler(message)
        except Exception as error:  # noqa: BLE001 - a handler bug must not end the server
            return {"ok": False, "error": str(error) or type(error).__name__}
        finally:
            self._asking = None
        if not isinstance(reply, dict):
            return {"ok": False, "error": f"the handler answered a {type(reply).__name__}, not a JSON object"}
        return reply


@dataclass
class _Client:
    """One connection's progress: reading its line, writing its reply, then draining what it
    still sends (closing with unread data would reset the connection before it read the reply)."""

    connection: socket.socket
    deadline: float
    phase: str = "reading"
    buffer: bytearray = field(default_factory=bytearray)
    reply: bytearray = field(default_factory=bytearray)
    received: int = 0
    eof: bool = False


def _flush(client: _Client, timeout: float = 0.5) -> None:
    """Send what is left of a client's reply, waiting a little for a slow reader; give up quietly."""
    if not client.reply:
        return
    try:
        client.connection.settimeout(timeout)
        client.connection.sendall(client.reply)
    except OSError:
        pass


_BRACKETS = re.compile(rb'"(?:[^"\\]|\\.)*"|[\[\]{}]')


def _nesting_depth(line: bytes, limit: int) -> int:
    """How deep the JSON text's arrays and objects nest (strings skipped), counted no further
    than past `limit`: checked before parsing, so the parser never recurses that deep."""
    depth = 0
    for match in _BRACKETS.finditer(line):
        token = match.group()
        if token in (b"[", b"{"):
            depth += 1
            if depth > limit:
                return depth
        elif token in (b"]", b"}"):
            depth -= 1
    return depth


def _refuse_constant(name: str) -> float:
    raise ValueError(f"{name} is not a number a request may carry")


MAX_DIGITS = 1000  # an integer a request carries is an id, a count or a parameter, never a bignum


def _bounded_int(text: str) -> int:
    digits = len(text.lstrip("-"))
    if digits > MAX_DIGITS:
        raise ValueError(f"an integer of {digits} digits is longer than a request may carry")
    return int(text)


def _encode(reply: dict) -> bytes:
    try:
        text = json.dumps(reply, allow_nan=False)
    except Exception as error:  # noqa: BLE001 - a reply that cannot be written is reported, not raised
        text = json.dumps({"ok": False, "error": f"the reply cannot be written as JSON: {error}"})
    return text.encode("utf-8") + b"\n"


