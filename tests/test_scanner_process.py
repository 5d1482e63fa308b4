"""The simulated TiM561 as a program of its own: it scans the scene's hallway from the pose the
world writes into shared memory, and takes its faults over stdin (real time, real sockets)."""

from __future__ import annotations

import time

import numpy as np

from hapticop.devices.sick.client import ColaClient
from hapticop.sim.hallway import HallwayGeometry, World
from hapticop.sim.scanner_process import ScannerProcess
from hapticop.sim.scene import Scene, close_scene, open_scene


def _until(condition, seconds: float = 20.0) -> None:
    deadline = time.monotonic() + seconds
    while not condition():
        if time.monotonic() > deadline:
            raise AssertionError(f"not within {seconds} s")
        time.sleep(0.005)


def test_scans_follow_the_world_and_faults_switch(tmp_path):
    geometry = HallwayGeometry.named("H1")
    scene = open_scene(Scene("scanner-test", geometry, World.from_geometry(geometry)))
    scanner = ScannerProcess(scene.shared_pose.name, 15.0, seed=1)
    try:
        _until(scanner.ready)
        client = ColaClient("127.0.0.1", scanner.port, backoff=(0.05, 0.1))
        ranges = np.zeros(811)

        def scan() -> np.ndarray:
            _until(lambda: client.poll() >= 1 and client.latest_scan(ranges))
            return ranges.copy()

        ahead = lambda scan_m: float(np.nanmedian(scan_m[400:411]))  # noqa: E731 - the beams straight ahead
        start = ahead(scan())
        assert abs(start - (geometry.length_m - geometry.start[0] - geometry.lidar.mount[0])) < 0.1
        scene.pose[0] += 3.0  # the world moves the robot: the next scans see the end wall closer
        _until(lambda: ahead(scan()) < start - 2.5)

        scanner.fault("unplugged")
        _until(lambda: (client.poll(), client.state.name)[1] != "STREAMING")
        scanner.fault("none")
        scan()  # reconnected and streaming again
        client.close()
    finally:
        scanner.stop()
        close_scene("scanner-test")
    assert scanner.process.returncode == 0


def test_a_scene_that_is_not_open_is_a_clear_error():
    import pytest

    scanner = ScannerProcess("hapticop-scene-0-nowhere", 15.0, seed=1)
    try:
        with pytest.raises(RuntimeError, match="did not start: FileNotFoundError"):
            _until(scanner.ready)
    finally:
        scanner.stop()
