"""The simulated TiM561 as an activity: it scans the world's scene from the pose the world
streams, serves CoLa A where it says it does, and switches its faults (virtual clock: the in-memory
streams its block and the LIDAR's then talk through; real time and loopback TCP in test_runtime_realtime.py)."""

from __future__ import annotations

import logging

import numpy as np

from hapticop.devices.link import published_address
from hapticop.devices.memory_stream import MEMORY_SOCKETS
from hapticop.devices.sick.client import ColaClient
from hapticop.runtime.clock import VirtualClock
from hapticop.sim import scene_files
from hapticop.sim.devices.tim561 import Tim561Simulator
from hapticop.sim.world_share import PublishedScene, publish_world, withdraw_world

from .runtime_helpers import standalone

PERIOD_NS = 66_666_667


def test_a_world_that_is_not_open_is_waited_for_and_said(tmp_path, caplog):
    clock = VirtualClock()
    scanner = standalone(Tim561Simulator, "lidar_sim", {"world": "world"}, tmp_path, clock)
    scanner.create()
    with caplog.at_level(logging.INFO, logger="test.lidar_sim"):
        assert scanner.configure_resources() is False
        assert scanner.configure_resources() is False
    assert [r.getMessage() for r in caplog.records] == ["waiting for the world 'world' to open its hallway"]
    assert published_address(tmp_path, "lidar_sim") is None


def test_scans_follow_the_world_and_faults_switch(tmp_path):
    loaded, _ = scene_files.load("H1")
    scene = loaded.scene
    shared = PublishedScene.of(scene, loaded.xml)
    publish_world(tmp_path, "world", shared)
    clock = VirtualClock()
    scanner = standalone(Tim561Simulator, "lidar_sim", {"world": "world"}, tmp_path, clock, seed=1)
    scanner.create()
    assert scanner.configure_resources() is True
    client = ColaClient(*published_address(tmp_path, "lidar_sim"), backoff=(0.05, 0.1), clock_ns=clock.now_ns,
                        sockets=MEMORY_SOCKETS)
    pose = scanner.inputs.pose_in_hallway
    ranges = np.zeros(811)

    def cycle() -> bool:
        """One period of the simulation's thread, then of the LIDAR's: a new scan?"""
        clock.advance_to(clock.now_ns() + PERIOD_NS)
        scanner.compute()
        return client.poll(clock.now_ns()) >= 1 and client.latest_scan(ranges)

    def scan(cycles: int = 60) -> np.ndarray:
        for _ in range(cycles):
            if cycle():
                return ranges.copy()
        raise AssertionError(f"no scan in {cycles} periods")

    def ahead(scan_m: np.ndarray) -> float:
        return float(np.nanmedian(scan_m[400:411]))  # the beams straight ahead

    try:
        start = ahead(scan())  # no pose from the world yet: the robot stands at its start
        end = next(w for w in scene.walls if w.name == scene.hallway.end_wall[0])
        face_x = end.position_m[0] - end.size_m[0] / 2  # the end wall's face towards the robot
        assert abs(start - (face_x - scene.robot.start[0] - scene.robot.lidar.x_m)) < 0.1
        pose.value[:] = shared.start
        pose.value[0] += 3.0  # the world streams the robot 3 m further: the end wall is closer
        pose.meta[0] = 1
        assert abs(ahead(scan()) - (start - 3.0)) < 0.1

        scanner.params = scanner.params.model_copy(update={"sim_fault": "unplugged"})
        for _ in range(10):
            cycle()
        assert client.state.name != "STREAMING" and not scanner.device.connected
        scanner.params = scanner.params.model_copy(update={"sim_fault": "stall"})
        for _ in range(60):
            cycle()
        assert scanner.device.connected and client.state.name == "STREAMING"  # connected, yet no scan arrives
        before = client.scans
        for _ in range(10):
            cycle()
        assert client.scans == before
        scanner.params = scanner.params.model_copy(update={"sim_fault": "none"})
        scan()  # streaming again
    finally:
        client.close()
        scanner.clean()
        withdraw_world(tmp_path, "world")
    assert published_address(tmp_path, "lidar_sim") is None  # withdrawn with the scanner
