"""The seam between a device block and a device served on this machine: its own bytes, on a link.

A real Falcon is reached over USB, a real TiM561 over TCP, real smart wheels over EtherCAT. A
simulated device is an activity of its own that serves the same bytes (Falcon frames, process-data
images) on a `DatagramLink`: a Unix datagram socket in Linux's abstract namespace, named after the
run and the simulating activity. The same link works inside one process, where a datagram is queued
at the receiver before `send` returns (so virtual-clock reruns stay identical), and between
processes, and it leaves no file behind. Neither end ever blocks: a datagram that finds no peer or a
full queue is dropped and counted, as a frame lost on a wire would be.

Under the virtual clock every activity runs in one thread of one process, so the runtime asks for
a `MemoryLink` instead (`memory=True`): the same datagrams, the same drops (no peer, or a full
queue, as long as the kernel's), kept in a queue in this process, no system call.

A device served over TCP (the simulated TiM561 speaks CoLa A on a loopback port) publishes its
address in the run directory instead (`publish_address`, `published_address`).
"""

from __future__ import annotations

import hashlib
import socket
from collections import deque
from pathlib import Path

from hapticop.published import publish, published, withdraw

_MAX_NAME = 107  # sun_path holds 108 bytes, the abstract namespace's leading NUL included


def _socket_queue() -> int:
    """How many datagrams a Unix socket holds before a sender is refused: Linux refuses once more
    than net.unix.max_dgram_qlen are waiting (10 by default)."""
    try:
        return int(Path("/proc/sys/net/unix/max_dgram_qlen").read_text()) + 1
    except (OSError, ValueError):
        return 11


_QUEUE = _socket_queue()


def link_name(run_dir: Path, activity: str) -> str:
    """The abstract socket name of `activity`'s device in the run at `run_dir` (same in every process)."""
    run = hashlib.sha1(str(Path(run_dir).resolve()).encode()).hexdigest()[:16]
    name = f"\0hapticop-{run}-{activity}"
    if len(name.encode()) > _MAX_NAME:
        raise ValueError(f"activity name '{activity}' is too long for a device link")
    return name


class DatagramLink:
    """One end of a device's link: `send` a datagram to the other end, `receive_into` the next one."""

    def __init__(self, local: str, peer: str):
        self.peer = peer
        self.dropped = 0  # datagrams sent while the peer was absent or behind
        self.sock = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
        try:
            self.sock.bind(local)
        except OSError:
            self.sock.close()
            raise
        self.sock.setblocking(False)

    @classmethod
    def host(cls, run_dir: Path, device_activity: str, memory: bool = False) -> DatagramLink | MemoryLink:
        """The device block's end, talking to the activity that serves the device (`memory`: both
        ends run in this thread, so the link is a `MemoryLink`)."""
        name = link_name(run_dir, device_activity)
        return (MemoryLink if memory else cls)(name + ".host", name)

    @classmethod
    def device(cls, run_dir: Path, activity: str, memory: bool = False) -> DatagramLink | MemoryLink:
        """The serving activity's end (the simulated device)."""
        name = link_name(run_dir, activity)
        return (MemoryLink if memory else cls)(name, name + ".host")

    def send(self, data) -> bool:
        """Send one datagram; False (and counted) if the other end is not there or not keeping up."""
        try:
            self.sock.sendto(data, self.peer)
            return True
        except (BlockingIOError, ConnectionRefusedError, FileNotFoundError):
            self.dropped += 1
            return False

    def receive_into(self, buffer) -> int:
        """The next datagram into `buffer`; its size, or 0 when none is waiting."""
        try:
            return self.sock.recv_into(buffer)
        except BlockingIOError:
            return 0

    def fileno(self) -> int:
        return self.sock.fileno()

    def close(self) -> None:
        self.sock.close()


class MemoryLink:
    """One end of a link whose both ends run in this thread: a `DatagramLink` without the socket.

    The ends find each other by the same names in a table of this process; what `send` would have
    queued in the kernel is queued here as bytes, dropped in the same cases."""

    _bound: dict[str, deque[bytes]] = {}  # name -> the datagrams waiting at that end

    def __init__(self, local: str, peer: str):
        if local in self._bound:
            raise OSError(f"address already in use: {local!r}")
        self.local, self.peer = local, peer
        self.dropped = 0
        self.queue: deque[bytes] = deque()
        self._bound[local] = self.queue

    def send(self, data) -> bool:
        queue = self._bound.get(self.peer)
        if queue is None or len(queue) >= _QUEUE:
            self.dropped += 1
            return False
        queue.append(bytes(data))
        return True

    def receive_into(self, buffer) -> int:
        if not self.queue:
            return 0
        data = self.queue.popleft()
        target = memoryview(buffer).cast("B")
        n = min(len(data), len(target))  # a datagram longer than the buffer is cut, as recv_into does
        target[:n] = data[:n]
        return n

    def close(self) -> None:
        if self._bound.get(self.local) is self.queue:
            del self._bound[self.local]
        self.queue.clear()


def publish_address(run_dir: Path, activity: str, host: str, port: int) -> None:
    """Say where `activity` serves its device over TCP."""
    publish(run_dir, "links", activity, (host, port))


def published_address(run_dir: Path, activity: str) -> tuple[str, int] | None:
    """Where `activity` serves its device over TCP, or None until it has said (an address left by
    a process that has ended, in a reused run directory, is not an answer)."""
    return published(run_dir, "links", activity, as_type=tuple[str, int])


def withdraw_address(run_dir: Path, activity: str) -> None:
    withdraw(run_dir, "links", activity)
