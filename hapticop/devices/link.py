"""The seam between a device block and a device served on this machine: its own bytes, on a link.

A real Falcon is reached over USB, a real TiM561 over TCP, real smart wheels over EtherCAT. A
simulated device is an activity of its own that serves the same bytes (Falcon frames, process-data
images) on a `DatagramLink`: a Unix datagram socket in Linux's abstract namespace, named after the
run and the simulating activity. The same link works inside one process, where a datagram is queued
at the receiver before `send` returns (so virtual-clock reruns stay identical), and between
processes, and it leaves no file behind. Neither end ever blocks: a datagram that finds no peer or a
full queue is dropped and counted, as a frame lost on a wire would be.

A device served over TCP (the simulated TiM561 speaks CoLa A on a loopback port) publishes its
address in the run directory instead (`publish_address`, `published_address`).
"""

from __future__ import annotations

import hashlib
import socket
from pathlib import Path

from hapticop.published import publish, published, withdraw

_MAX_NAME = 107  # sun_path holds 108 bytes, the abstract namespace's leading NUL included


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
    def host(cls, run_dir: Path, device_activity: str) -> DatagramLink:
        """The device block's end, talking to the activity that serves the device."""
        name = link_name(run_dir, device_activity)
        return cls(name + ".host", name)

    @classmethod
    def device(cls, run_dir: Path, activity: str) -> DatagramLink:
        """The serving activity's end (the simulated device)."""
        name = link_name(run_dir, activity)
        return cls(name, name + ".host")

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


def publish_address(run_dir: Path, activity: str, host: str, port: int) -> None:
    """Say where `activity` serves its device over TCP."""
    publish(run_dir, "links", activity, (host, port))


def published_address(run_dir: Path, activity: str) -> tuple[str, int] | None:
    """Where `activity` serves its device over TCP, or None until it has said (an address left by
    a process that has ended, in a reused run directory, is not an answer)."""
    return published(run_dir, "links", activity, as_type=tuple[str, int])


def withdraw_address(run_dir: Path, activity: str) -> None:
    withdraw(run_dir, "links", activity)
