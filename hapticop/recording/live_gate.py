"""The live view's gate: a client is let through to Foxglove's server only with the run's token.

Foxglove's WebSocket protocol has no authentication and the SDK's server no hook to add one (no
connection callback, no way to close a client), so the SDK's server listens on a loopback port of
its own and this gate listens where the user asked. A client's HTTP upgrade request must carry the
run's token (`?token=` in its URL); the gate reads that request (bounded in size and time), answers
anything else with 401 and closes, and otherwise forwards the request and then the bytes both ways.
With a certificate and key the gate speaks TLS (`wss://`). A client that stops reading stalls only its
own connection: the gate stops reading for it, and the SDK drops that client's oldest messages.

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
from pathlib import Path
from urllib.parse import parse_qs, urlsplit

HEAD_LIMIT = 8192  # an upgrade request is a few hundred bytes
HEAD_TIMEOUT_S = 5.0  # a client that does not finish its request by then is dropped
MAX_CLIENTS = 64  # connections at once (a browser tab is one)
CHUNK = 65536
CLOSE_GRACE_S = 1.0  # the SDK's goodbye crosses loopback well within this
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


class Gate:
    """Listens at `host:port` (0: any free port) on a thread of its own; lets a client with `token` through to
    `127.0.0.1:inner_port`."""

    def __init__(self, host: str, port: int, inner_port: int, token: str,
                 tls: tuple[bytes, bytes] | None = None) -> None:
        self.inner_port, self._token = inner_port, token.encode()
        self.refused = 0
        self._context = _server_context(*tls) if tls is not None else None
        self._clients = 0
        self._loop = asyncio.new_event_loop()
        self._started = threading.Event()
        self._error: BaseException | None = None
        self._thread = threading.Thread(target=self._run, args=(host, port), name="live-view-gate", daemon=True)
        self._thread.start()
        self._started.wait()
        if self._error is not None:
            raise self._error

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
        if self._clients >= MAX_CLIENTS:
            await _answer(writer, BUSY)
            return
        self._clients += 1
        try:
            try:
                head = await asyncio.wait_for(reader.readuntil(b"\r\n\r\n"), HEAD_TIMEOUT_S)
            except (TimeoutError, asyncio.IncompleteReadError, asyncio.LimitOverrunError, OSError):
                writer.close()
                return
            given = token_of(head)
            if given is None or not hmac.compare_digest(given.encode(), self._token):
                self.refused += 1
                await _answer(writer, REFUSED)
                return
            try:
                inner_reader, inner_writer = await asyncio.open_connection("127.0.0.1", self.inner_port)
            except OSError:
                await _answer(writer, BUSY)
                return
            inner_writer.write(head)
            await asyncio.gather(_pipe(reader, inner_writer), _pipe(inner_reader, writer), return_exceptions=True)
        finally:
            self._clients -= 1

    def stop(self) -> None:
        """Stop listening; the connections still open get `CLOSE_GRACE_S` to pass on the server's goodbye."""
        if self._thread.is_alive():
            asyncio.run_coroutine_threadsafe(self._close(), self._loop)
            self._thread.join()
            self._loop.close()

    async def _close(self) -> None:
        self._server.close()
        tasks = [t for t in asyncio.all_tasks() if t is not asyncio.current_task()]
        if tasks:
            _, pending = await asyncio.wait(tasks, timeout=CLOSE_GRACE_S)
            for task in pending:
                task.cancel()
            await asyncio.gather(*pending, return_exceptions=True)
        self._loop.stop()


async def _answer(writer: asyncio.StreamWriter, response: bytes) -> None:
    try:
        writer.write(response)
        await asyncio.wait_for(writer.drain(), HEAD_TIMEOUT_S)
    except (TimeoutError, OSError):
        pass
    finally:
        writer.close()


async def _pipe(source: asyncio.StreamReader, sink: asyncio.StreamWriter) -> None:
    """Bytes from one side to the other until either ends; a sink that stops reading holds back only this pipe."""
    try:
        while data := await source.read(CHUNK):
            sink.write(data)
            await sink.drain()
    finally:
        sink.close()


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
