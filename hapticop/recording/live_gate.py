"""The live view's one listening socket: a client gets in only with the run's token, then is served
Foxglove's WebSocket protocol (`live_protocol`) by this gate itself.

The SDK's own server has no hook to authenticate a client and listens on TCP, so behind a gate it
would be a second port that any local user could find and open without the token; so no SDK
server runs, and this gate is the only socket of the live view. A client's HTTP upgrade request
must carry the run's token (`?token=` in its URL); the gate reads that request (bounded in size and
time), answers anything else with 401 and closes, and otherwise completes the WebSocket handshake
with `websockets`' protocol layer (no I/O of its own, so every byte is read and bounded here). With a
certificate and key the gate speaks TLS only (`wss://`).

The writer (the recorder, on its own thread) never waits: it appends each frame to each subscribed
client's backlog, whose oldest message is dropped when full, and wakes that client's sender on the
gate's thread at most once per pass. A client that stops reading stalls only its own sender, and
is dropped after `STALL_S`; a client that breaks the protocol (garbage, a binary frame, an unknown
channel, a message over `CLIENT_MESSAGE_LIMIT`) is closed at once.

The token is a per-run secret, written owner-only in the run directory, so another user of the
machine cannot watch (docs/security.md).
"""

from __future__ import annotations

import asyncio
import hmac
import os
import secrets
import ssl
import threading
import time
from collections import deque
from pathlib import Path
from urllib.parse import parse_qs, urlsplit

from websockets.frames import Opcode
from websockets.protocol import OPEN
from websockets.server import ServerProtocol

from hapticop.recording.live_protocol import (
    SUBPROTOCOLS,
    Advertised,
    ProtocolViolation,
    advertise,
    client_op,
    message_data,
    server_info,
)

HEAD_LIMIT = 8192  # an upgrade request is a few hundred bytes
HEAD_TIMEOUT_S = 5.0  # a client that does not finish its TLS handshake and request by then is dropped
MAX_CLIENTS = 64  # connections at once (a browser tab is one), counted from their first byte
CLIENT_MESSAGE_LIMIT = 65536  # a client only subscribes: a larger message closes it (1009)
BACKLOG = 1024  # messages waiting per client; the oldest goes first (as the SDK's server did)
STALL_S = 30.0  # a client that takes no bytes for this long is dropped
CHUNK = 65536
CLOSE_GRACE_S = 1.0  # for a client to answer the goodbye
REFUSED = b"HTTP/1.1 401 Unauthorized\r\nContent-Length: 0\r\nConnection: close\r\n\r\n"
BUSY = b"HTTP/1.1 503 Service Unavailable\r\nContent-Length: 0\r\nConnection: close\r\n\r\n"


def new_token() -> str:
    return secrets.token_urlsafe(32)


def write_token(run_dir: Path, port: int, token: str) -> Path:
    """`live-view-PORT.token` in the run directory, readable by its owner only (whatever the run's mask)."""
    path = Path(run_dir) / f"live-view-{port}.token"
    fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC | os.O_NOFOLLOW, 0o600)
    try:
        os.fchmod(fd, 0o600)
        os.write(fd, token.encode() + b"\n")
    finally:
        os.close(fd)
    return path


def token_of(head: bytes) -> str | None:
    """The `token` of an HTTP request's target, or None."""
    try:
        target = head.split(b"\r\n", 1)[0].split(b" ")[1].decode("ascii")
    except (IndexError, UnicodeDecodeError):
        return None
    values = parse_qs(urlsplit(target).query).get("token")
    return values[0] if values else None


class _Client:
    """One admitted client: what it subscribed to and what waits for it."""

    def __init__(self, protocol: ServerProtocol) -> None:
        self.protocol = protocol
        self.subscriptions: dict[int, int] = {}  # channel -> subscription id; replaced whole, read by the writer
        self.data: deque[bytes] = deque(maxlen=BACKLOG)
        self.control: deque[str] = deque()
        self.wake = asyncio.Event()
        self.waking = False
        self.leaving = False  # the gate stops: say goodbye once the backlog is sent


class Gate:
    """Listens at `host:port` (0: any free port) on a thread of its own and serves the live view's channels
    to clients that hold `token`."""

    def __init__(self, host: str, port: int, token: str, name: str = "hapticop",
                 tls: tuple[bytes, bytes] | None = None) -> None:
        self._token = token.encode()
        self.refused = 0  # requests without the token
        self.dropped = 0  # admitted clients closed for breaking the protocol or stalling
        self._context = _server_context(*tls) if tls is not None else None
        self._connections = 0
        self._info = server_info(name, str(time.time_ns()))
        self._lock = threading.Lock()  # the channels and the clients, between the writer and the gate's thread
        self._channels: dict[int, Advertised] = {}
        self._clients: tuple[_Client, ...] = ()
        self._loop = asyncio.new_event_loop()
        self._started = threading.Event()
        self._error: BaseException | None = None
        self._thread = threading.Thread(target=self._run, args=(host, port), name="live-view-gate", daemon=True)
        self._thread.start()
        self._started.wait()
        if self._error is not None:
            raise self._error

    # The writer's side (any thread): never waits on a client.

    def advertise(self, channel: Advertised) -> None:
        text = advertise([channel])
        with self._lock:
            self._channels[channel.id] = channel
            for client in self._clients:
                client.control.append(text)
                self._wake(client)

    def subscribed(self, channel: int) -> bool:
        return any(channel in client.subscriptions for client in self._clients)

    def send(self, channel: int, log_time_ns: int, payload: bytes) -> None:
        for client in self._clients:
            subscription = client.subscriptions.get(channel)
            if subscription is not None:
                client.data.append(message_data(subscription, log_time_ns, payload))
                self._wake(client)

    def _wake(self, client: _Client) -> None:
        if not client.waking:
            client.waking = True
            try:
                self._loop.call_soon_threadsafe(client.wake.set)
            except RuntimeError:  # the gate has stopped
                pass

    # The gate's thread.

    def _run(self, host: str, port: int) -> None:
        asyncio.set_event_loop(self._loop)
        try:
            self._server = self._loop.run_until_complete(asyncio.start_server(
                self._serve, host, port, ssl=self._context, limit=HEAD_LIMIT, ssl_handshake_timeout=HEAD_TIMEOUT_S
                if self._context else None))
            self.port = self._server.sockets[0].getsockname()[1]
        except BaseException as error:  # noqa: BLE001 - told to the caller, which raises it
            self._error = error
            self._started.set()
            return
        self._started.set()
        self._loop.run_forever()

    async def _serve(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        if self._connections >= MAX_CLIENTS:
            await _answer(writer, BUSY)
            return
        self._connections += 1
        try:
            try:
                head = await asyncio.wait_for(reader.readuntil(b"\r\n\r\n"), HEAD_TIMEOUT_S)
            except (TimeoutError, asyncio.IncompleteReadError, asyncio.LimitOverrunError, OSError):
                return
            given = token_of(head)
            if given is None or not hmac.compare_digest(given.encode(), self._token):
                self.refused += 1
                await _answer(writer, REFUSED)
                return
            protocol = ServerProtocol(subprotocols=list(SUBPROTOCOLS), max_size=CLIENT_MESSAGE_LIMIT)
            protocol.receive_data(head)
            requests = protocol.events_received()
            if requests:  # else not HTTP: the protocol's own answer, if any
                protocol.send_response(protocol.accept(requests[0]))
            if not await _flush(writer, protocol) or protocol.state is not OPEN:
                return
            client = _Client(protocol)
            with self._lock:
                client.control.extend([self._info, advertise(list(self._channels.values()))])
                self._clients = (*self._clients, client)
            client.wake.set()
            try:
                await self._session(reader, writer, client)
            finally:
                with self._lock:
                    self._clients = tuple(c for c in self._clients if c is not client)
        finally:
            self._connections -= 1
            writer.close()

    async def _session(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter, client: _Client) -> None:
        receiving = asyncio.ensure_future(self._receive(reader, writer, client))
        sending = asyncio.ensure_future(self._send(writer, client))
        try:
            await asyncio.wait({receiving, sending}, return_when=asyncio.FIRST_COMPLETED)
            if sending.done() and client.leaving:  # the goodbye is sent: the client's answer ends the receiving
                await asyncio.wait({receiving}, timeout=CLOSE_GRACE_S)
        finally:
            for task in (receiving, sending):
                task.cancel()
            await asyncio.gather(receiving, sending, return_exceptions=True)

    async def _receive(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter, client: _Client) -> None:
        protocol = client.protocol
        while True:
            try:
                data = await reader.read(CHUNK)
            except OSError:
                return
            if data:
                protocol.receive_data(data)
            else:
                protocol.receive_eof()
            for frame in protocol.events_received():
                if protocol.state is not OPEN:
                    break
                try:
                    self._handle(client, frame)
                except ProtocolViolation as violation:
                    self.dropped += 1
                    protocol.fail(1008, str(violation)[:120])
                    break
            if protocol.parser_exc is not None and not isinstance(protocol.parser_exc, EOFError):
                self.dropped += 1  # over the size limit, or not WebSocket framing: the protocol failed it
            if not await _flush(writer, protocol) or not data or protocol.close_expected():
                return

    def _handle(self, client: _Client, frame) -> None:
        if frame.opcode in (Opcode.PING, Opcode.PONG, Opcode.CLOSE):
            return  # the protocol layer answers these
        if frame.opcode is not Opcode.TEXT or not frame.fin:
            raise ProtocolViolation("only whole text messages are served")
        try:
            text = frame.data.decode()
        except UnicodeDecodeError:
            raise ProtocolViolation("not UTF-8") from None
        op, items = client_op(text, self._channels)
        subscriptions = dict(client.subscriptions)
        if op == "subscribe":
            for subscription, channel in items:
                if subscription in subscriptions.values() or channel in subscriptions:
                    raise ProtocolViolation(f"subscription {subscription} or channel {channel} taken")
                subscriptions[channel] = subscription
        else:
            gone = set(items)
            subscriptions = {c: s for c, s in subscriptions.items() if s not in gone}
        client.subscriptions = subscriptions

    async def _send(self, writer: asyncio.StreamWriter, client: _Client) -> None:
        protocol = client.protocol
        while True:
            await client.wake.wait()
            client.wake.clear()
            client.waking = False
            if protocol.state is not OPEN:
                return
            leaving = client.leaving  # read once: it may turn while this pass is written
            while client.control:
                protocol.send_text(client.control.popleft().encode())
            while client.data:
                protocol.send_binary(client.data.popleft())
            if leaving:
                protocol.send_close(1001, "the run ended")
            try:
                if not await asyncio.wait_for(_flush(writer, protocol), STALL_S):
                    return
            except TimeoutError:
                self.dropped += 1
                return
            if leaving:
                return

    def stop(self) -> None:
        """Stop listening; each client gets its backlog and a goodbye, within `CLOSE_GRACE_S` to answer it."""
        if self._thread.is_alive():
            asyncio.run_coroutine_threadsafe(self._close(), self._loop)
            self._thread.join()
            self._loop.close()

    async def _close(self) -> None:
        self._server.close()
        for client in self._clients:
            client.leaving = True
            client.wake.set()
        tasks = [t for t in asyncio.all_tasks() if t is not asyncio.current_task()]
        if tasks:
            _, pending = await asyncio.wait(tasks, timeout=2 * CLOSE_GRACE_S)
            for task in pending:
                task.cancel()
            await asyncio.gather(*pending, return_exceptions=True)
        self._loop.stop()


async def _flush(writer: asyncio.StreamWriter, protocol: ServerProtocol) -> bool:
    """What the protocol has to send, written and drained; False when the connection is gone or ending."""
    try:
        for data in protocol.data_to_send():
            if not data:  # the protocol's end of the stream
                return False
            writer.write(data)
        await writer.drain()
    except OSError:
        return False
    return True


async def _answer(writer: asyncio.StreamWriter, response: bytes) -> None:
    try:
        writer.write(response)
        await asyncio.wait_for(writer.drain(), HEAD_TIMEOUT_S)
    except (TimeoutError, OSError):
        pass
    finally:
        writer.close()


def _server_context(cert: bytes, key: bytes) -> ssl.SSLContext:
    """A TLS server context from PEM bytes (the ssl module reads files: a private temporary directory)."""
    import tempfile

    context = ssl.SSLContext(ssl.PROTOCOL_TLS_SERVER)
    context.minimum_version = ssl.TLSVersion.TLSv1_2
    with tempfile.TemporaryDirectory() as directory:
        cert_path, key_path = Path(directory) / "cert.pem", Path(directory) / "key.pem"
        for path, data in ((cert_path, cert), (key_path, key)):
            fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
            with os.fdopen(fd, "wb") as out:
                out.write(data)
        context.load_cert_chain(cert_path, key_path)
    return context
