"""The device link: a device block's bytes reach the activity serving the device, and back,
within one process and between two, without either end ever blocking."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

from hapticop.devices.link import (
    DatagramLink,
    MemoryLink,
    link_name,
    publish_address,
    published_address,
    withdraw_address,
)

# Each behaviour holds for the socket and for the in-memory link the virtual clock uses (memory=True).
both = pytest.mark.parametrize("memory", [False, True], ids=["socket", "memory"])


@both
def test_frames_cross_in_order_within_one_process(tmp_path, memory):
    device = DatagramLink.device(tmp_path, "falcon_sim", memory)
    host = DatagramLink.host(tmp_path, "falcon_sim", memory)
    buffer = bytearray(64)
    assert host.receive_into(buffer) == 0  # nothing yet: no wait
    assert host.send(b"command-1") and host.send(b"command-2")
    assert device.receive_into(buffer) == 9 and bytes(buffer[:9]) == b"command-1"
    assert device.receive_into(buffer) == 9 and bytes(buffer[:9]) == b"command-2"
    assert device.receive_into(buffer) == 0
    assert device.send(b"status")
    assert host.receive_into(buffer) == 6 and bytes(buffer[:6]) == b"status"
    host.close()
    device.close()


@both
def test_a_missing_device_drops_the_frame_and_counts_it(tmp_path, memory):
    host = DatagramLink.host(tmp_path, "nobody", memory)
    assert not host.send(b"frame")
    assert host.dropped == 1
    host.close()


@both
def test_a_device_that_does_not_keep_up_never_blocks_the_host(tmp_path, memory):
    device = DatagramLink.device(tmp_path, "slow", memory)
    host = DatagramLink.host(tmp_path, "slow", memory)
    sent = sum(host.send(bytes(168 * 4)) for _ in range(5000))
    assert sent < 5000 and host.dropped == 5000 - sent  # the queue filled; the rest were dropped
    host.close()
    device.close()


def test_the_memory_link_drops_what_the_socket_drops(tmp_path):
    """A virtual run's frames are dropped where a socket's would be: reruns and the wall clock agree."""
    counts = []
    for memory in (False, True):
        device = DatagramLink.device(tmp_path, "burst", memory)
        host = DatagramLink.host(tmp_path, "burst", memory)
        buffer = bytearray(64)
        taken = []
        for burst in (3, 30, 1, 12):  # bursts longer and shorter than the queue, partly drained between
            sent = sum(host.send(bytes([i]) * 8) for i in range(burst))
            taken.append((sent, device.receive_into(buffer), device.receive_into(buffer)))
        counts.append((taken, host.dropped))
        host.close()
        device.close()
    assert counts[0] == counts[1]


def test_a_frame_lands_whole_in_a_two_dimensional_image(tmp_path):
    device = DatagramLink.device(tmp_path, "wheels", memory=True)
    host = DatagramLink.host(tmp_path, "wheels", memory=True)
    image = np.arange(8, dtype=np.uint8).reshape(2, 4)
    assert host.send(image)
    received = np.zeros((2, 4), np.uint8)
    assert device.receive_into(received) == 8 and np.array_equal(received, image)
    host.close()
    device.close()


def test_a_closed_memory_end_frees_its_name(tmp_path):
    device = DatagramLink.device(tmp_path, "again", memory=True)
    with pytest.raises(OSError):
        DatagramLink.device(tmp_path, "again", memory=True)  # as a second bind would fail
    device.close()
    device = DatagramLink.device(tmp_path, "again", memory=True)
    assert isinstance(device, MemoryLink)
    host = DatagramLink.host(tmp_path, "again", memory=True)
    device.close()
    assert not host.send(b"x") and host.dropped == 1  # the device went away: no one to queue at
    host.close()


def test_links_of_two_runs_are_apart(tmp_path):
    assert link_name(tmp_path / "a", "sim") != link_name(tmp_path / "b", "sim")


def test_a_device_in_another_process_answers(tmp_path):
    program = (
        "import sys; from pathlib import Path; from hapticop.devices.link import DatagramLink\n"
        "d = DatagramLink.device(Path(sys.argv[1]), 'echo'); print('ready', flush=True)\n"
        "d.sock.setblocking(True); b = bytearray(64); n = d.receive_into(b); d.send(bytes(b[:n]).upper())\n"
    )
    child = subprocess.Popen([sys.executable, "-c", program, str(tmp_path)], stdout=subprocess.PIPE, text=True)
    try:
        assert child.stdout.readline().strip() == "ready"
        host = DatagramLink.host(tmp_path, "echo")
        host.sock.setblocking(True)
        host.sock.settimeout(10)
        assert host.send(b"ping")
        buffer = bytearray(64)
        n = host.sock.recv_into(buffer)
        assert bytes(buffer[:n]) == b"PING"
        host.close()
    finally:
        child.wait(10)


def test_a_tcp_address_is_published_whole_and_withdrawn(tmp_path):
    assert published_address(tmp_path, "lidar_sim") is None
    publish_address(tmp_path, "lidar_sim", "127.0.0.1", 40123)
    assert published_address(tmp_path, "lidar_sim") == ("127.0.0.1", 40123)
    withdraw_address(tmp_path, "lidar_sim")
    assert published_address(tmp_path, "lidar_sim") is None


def test_an_address_left_by_an_ended_process_is_no_answer(tmp_path):
    subprocess.run([sys.executable, "-c", "import sys; from hapticop.devices.link import publish_address; "
                    "publish_address(sys.argv[1], 'lidar_sim', '127.0.0.1', 40123)", str(tmp_path)], check=True)
    assert published_address(tmp_path, "lidar_sim") is None
