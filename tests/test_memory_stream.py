"""The in-memory byte stream of the virtual clock: what loopback TCP does in one thread, and the CoLa A
client and simulated TiM561 talking through it with the same bytes as over a socket."""

from __future__ import annotations

import errno
import socket
import struct

import numpy as np
import pytest

from hapticop.devices.memory_stream import BUFFER_BYTES, MemorySockets
from hapticop.devices.sick.client import ColaClient
from hapticop.devices.sick.simulator import TiMSimulator


def _pair(sockets: MemorySockets):
    listener = sockets()
    listener.bind(("127.0.0.1", 0))
    listener.listen(4)
    client = sockets()
    assert client.connect_ex(listener.getsockname()) == errno.EINPROGRESS
    client.getpeername()  # established at once, as on loopback
    served, _ = listener.accept()
    return listener, client, served


def test_no_listener_is_refused_and_an_address_is_taken_once():
    sockets = MemorySockets()
    assert sockets().connect_ex(("127.0.0.1", 2112)) == errno.ECONNREFUSED
    first = sockets()
    first.bind(("127.0.0.1", 2112))
    with pytest.raises(OSError):
        sockets().bind(("127.0.0.1", 2112))
    first.listen()
    first.close()
    again = sockets()
    again.bind(("127.0.0.1", 2112))  # given back when closed


def test_bytes_arrive_in_order_then_the_end_or_a_reset():
    sockets = MemorySockets()
    listener, client, served = _pair(sockets)
    with pytest.raises(BlockingIOError):
        served.recv(10)
    assert client.send(b"abc") == 3 and client.send(bytearray(b"def")) == 3
    buffer = bytearray(4)
    assert served.recv_into(buffer, 2) == 2 and buffer[:2] == b"ab"
    assert served.recv(10) == b"cdef"
    client.send(b"last")
    client.close()
    assert served.recv(10) == b"last" and served.recv(10) == b""  # the end, after the last bytes
    assert served.send(b"x") == 1  # taken once, answered by a reset
    with pytest.raises(ConnectionResetError):
        served.recv(1)
    with pytest.raises(BrokenPipeError):
        served.send(b"x")

    listener2, client2, served2 = _pair(sockets)
    client2.send(b"unread")
    client2.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER, struct.pack("ii", 1, 0))
    client2.close()
    with pytest.raises(ConnectionResetError):  # an abortive close: the peer sees a reset, not the end
        served2.recv(10)


def test_a_full_buffer_takes_what_fits_and_a_closed_listener_resets_the_waiting():
    sockets = MemorySockets()
    listener, client, served = _pair(sockets)
    assert client.send(bytes(BUFFER_BYTES - 10)) == BUFFER_BYTES - 10
    assert client.send(bytes(100)) == 10
    with pytest.raises(BlockingIOError):
        client.send(b"x")
    waiting = sockets()
    waiting.connect_ex(listener.getsockname())
    listener.close()
    assert waiting.recv(1) == b""  # never accepted: closed with its listener
    assert sockets().connect_ex(listener.getsockname()) == errno.ECONNREFUSED


def _streamed_over(sockets) -> tuple[np.ndarray, int, int]:
    """A stepped TiM561 and its CoLa A client, both on a virtual time, over `sockets`: the ranges of
    the third scan, and the bytes each side sent."""
    now = [0]
    ranges = np.linspace(0.5, 9.5, 811)
    device = TiMSimulator(ranges_m=lambda _t: ranges, clock_ns=lambda: now[0], sockets=sockets)
    client = ColaClient(device.host, device.port, clock_ns=lambda: now[0], sockets=sockets)
    out = np.zeros(811)
    try:
        while client.scans < 3:
            assert now[0] < 5e9, "no third scan in 5 s"
            now[0] += 5_000_000
            device.step(now[0])
            client.poll(now[0])
        client.latest_scan(out)
        return out, client.bytes_sent, device.bytes_sent
    finally:
        client.close()
        device.close()


def test_the_cola_client_and_simulator_exchange_the_same_bytes_as_over_loopback():
    memory = _streamed_over(MemorySockets())
    tcp = _streamed_over(socket.socket)
    assert memory[1:] == tcp[1:]
    np.testing.assert_array_equal(memory[0], tcp[0])
    np.testing.assert_allclose(memory[0], np.linspace(0.5, 9.5, 811), atol=1e-3)
