"""A TCP byte stream whose both ends run in this thread: the sockets a CoLa A client and its
simulated scanner talk through under the virtual clock, without the kernel.

The TiM561 speaks CoLa A over TCP, and its driver (`sick.client.ColaClient`) and simulator
(`sick.simulator.TiMSimulator`) are written against non-blocking sockets. Under the virtual clock
every activity runs in one thread, so the runtime hands both the `MemorySockets` factory instead
of `socket.socket`: the same calls (`connect_ex`, `accept`, `send`, `recv`, `recv_into`, `close`)
on the same bytes, moved between two buffers of this process. What loopback TCP does in one
thread is kept: a connection to a listening address is established at once (and waits in the
listener's queue until accepted), a connection to no listener is refused, bytes sent are
readable by the peer as `send` returns, a send into a full peer buffer takes what fits, a closed
peer reads as the end of the stream after its last bytes, and a peer closed with `SO_LINGER`
(1, 0) as a reset; a send to a closed peer is taken once and answered by a reset (the next read
fails, the next send is a broken pipe). There is no descriptor to wait on: `fileno()` is -1.
"""

from __future__ import annotations

import errno
import socket
import struct
from collections import deque

BUFFER_BYTES = 4 << 20
"""What one direction holds before a sender is told to wait (loopback's default buffers, about)."""


class MemoryListener:
    """A listening address: connections wait here, established, until accepted."""

    def __init__(self, sockets: MemorySockets, address: tuple[str, int]):
        self.sockets, self.address = sockets, address
        self.waiting: deque[MemorySocket] = deque()


class MemorySocket:
    """One end of a stream (or a listener, once `listen` is called). Never blocks: what a
    non-blocking socket would wait for raises `BlockingIOError`."""

    def __init__(self, sockets: MemorySockets, family: int = socket.AF_INET, kind: int = socket.SOCK_STREAM):
        if kind != socket.SOCK_STREAM:
            raise ValueError("a memory socket is a stream")
        self.sockets, self.family = sockets, family
        self.address: tuple[str, int] | None = None
        self.peer: MemorySocket | None = None
        self.listener: MemoryListener | None = None
        self.incoming = bytearray()  # what the peer sent, not yet read
        self.peer_closed = False  # the peer closed: the end of the stream after `incoming`
        self.reset = False  # the peer closed abortively: the next read fails
        self.closed = False
        self.linger_zero = False
        self.owns_address = False  # a client's own port, given back when it closes

    # -- the calls the CoLa A client and simulator make ---------------------------------------
    def setblocking(self, flag: bool) -> None:
        if flag:
            raise ValueError("a memory socket never blocks")

    def setsockopt(self, level: int, option: int, value: int | bytes) -> None:
        if level == socket.SOL_SOCKET and option == socket.SO_LINGER:
            on, seconds = struct.unpack("ii", value) if isinstance(value, bytes) else (value, 0)
            self.linger_zero = bool(on) and seconds == 0

    def getsockopt(self, level: int, option: int) -> int:
        return 0  # SO_ERROR: a refused connection is refused by connect_ex itself

    def bind(self, address: tuple[str, int]) -> None:
        self.address, self.owns_address = self.sockets.bind(address), True

    def listen(self, _backlog: int = 0) -> None:
        if self.address is None:
            self.bind(("127.0.0.1", 0))
        self.listener = self.sockets.listen(self.address)

    def getsockname(self) -> tuple[str, int]:
        return self.address or ("0.0.0.0", 0)

    def getpeername(self) -> tuple[str, int]:
        if self.peer is None:
            raise OSError(errno.ENOTCONN, "not connected")
        return self.peer.getsockname()

    def connect_ex(self, address: tuple[str, int]) -> int:
        listener = self.sockets.listening.get(tuple(address[:2]))
        if listener is None:
            return errno.ECONNREFUSED
        served = MemorySocket(self.sockets, self.family)
        served.address = listener.address
        self.address, self.owns_address = self.sockets.bind(("127.0.0.1", 0)), True
        self.peer, served.peer = served, self
        listener.waiting.append(served)
        return errno.EINPROGRESS  # as a non-blocking connect says; established by the next call

    def accept(self) -> tuple[MemorySocket, tuple[str, int]]:
        if self.listener is None or not self.listener.waiting:
            raise BlockingIOError(errno.EAGAIN, "no connection waiting")
        served = self.listener.waiting.popleft()
        return served, served.peer.getsockname() if served.peer is not None else ("0.0.0.0", 0)

    def send(self, data) -> int:
        if self.closed:
            raise OSError(errno.EBADF, "closed")
        peer = self.peer
        if peer is None:
            raise OSError(errno.ENOTCONN, "not connected")
        if peer.closed:  # as TCP: the first send is taken and answered by a reset, the next ones fail
            if self.reset:
                raise BrokenPipeError(errno.EPIPE, "the peer closed the connection")
            self.reset = True
            self.incoming.clear()
            return memoryview(data).nbytes
        room = BUFFER_BYTES - len(peer.incoming)
        if room <= 0:
            raise BlockingIOError(errno.EAGAIN, "the peer's buffer is full")
        view = memoryview(data)
        taken = min(room, view.nbytes)
        peer.incoming += view[:taken]
        return taken

    def recv_into(self, buffer, nbytes: int = 0) -> int:
        target = memoryview(buffer).cast("B")
        count = self._take(nbytes or len(target))
        target[: len(count)] = count
        return len(count)

    def recv(self, nbytes: int) -> bytes:
        return bytes(self._take(nbytes))

    def _take(self, nbytes: int) -> bytearray:
        if self.reset:
            raise ConnectionResetError(errno.ECONNRESET, "connection reset by peer")
        incoming = self.incoming
        if not incoming:
            if self.peer_closed or self.closed:
                return bytearray()  # the end of the stream
            raise BlockingIOError(errno.EAGAIN, "nothing to read")
        taken = incoming[:nbytes]
        del incoming[:nbytes]
        return taken

    def fileno(self) -> int:
        return -1  # nothing to select on: under the virtual clock nobody waits

    def close(self) -> None:
        if self.closed:
            return
        self.closed = True
        if self.owns_address and self.address is not None:
            self.sockets.bound.discard(self.address)
        if self.listener is not None:  # connections never accepted are reset
            self.sockets.unlisten(self.listener)
            for served in self.listener.waiting:
                served.close()
            self.listener.waiting.clear()
        peer = self.peer
        if peer is not None and not peer.closed:
            peer.peer_closed = True
            if self.linger_zero:
                peer.reset = True
                peer.incoming.clear()
        self.incoming.clear()


class MemorySockets:
    """The addresses of one run's in-memory streams; called like `socket.socket` to make a socket."""

    FIRST_PORT = 32768  # ports are handed out from here, as the kernel's ephemeral range starts

    def __init__(self) -> None:
        self.listening: dict[tuple[str, int], MemoryListener] = {}
        self.bound: set[tuple[str, int]] = set()
        self._next_port = self.FIRST_PORT

    def __call__(self, family: int = socket.AF_INET, kind: int = socket.SOCK_STREAM) -> MemorySocket:
        return MemorySocket(self, family, kind)

    def bind(self, address: tuple[str, int]) -> tuple[str, int]:
        host, port = address[0], address[1]
        if port == 0:
            while (host, self._next_port) in self.bound:
                self._next_port += 1
            port = self._next_port
            self._next_port += 1
        elif (host, port) in self.bound:
            raise OSError(errno.EADDRINUSE, f"address already in use: {host}:{port}")
        self.bound.add((host, port))
        return host, port

    def listen(self, address: tuple[str, int]) -> MemoryListener:
        listener = self.listening.get(address)
        if listener is None:
            listener = self.listening[address] = MemoryListener(self, address)
        return listener

    def unlisten(self, listener: MemoryListener) -> None:
        if self.listening.get(listener.address) is listener:
            del self.listening[listener.address]


MEMORY_SOCKETS = MemorySockets()
"""This process's in-memory streams: a simulated device and its block, both under the virtual clock,
find each other here by the address the device publishes, as over loopback."""
