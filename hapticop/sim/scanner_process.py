"""The simulated TiM561 in a process of its own, as the real scanner is a device of its own.

In real time a scan costs the simulator a ray cast and an 811-value telegram, about 0.6 ms of
Python at 15 Hz. Run as a thread it would hold the GIL of a process with a 1 kHz loop, and
every scan would delay that loop. So in real time the lidar block's `sim` driver starts this
program (`python -m hapticop.sim.scanner_process`), which serves CoLa A on a loopback port like
the device, sees the robot where the simulated world puts it through the scene's shared
memory, says its port on stdout and takes fault switches on stdin; it ends when stdin closes,
so it never outlives the block that started it. Under the virtual clock the block steps an
in-process simulator instead, so runs repeat bit for bit.
"""

from __future__ import annotations

import argparse
import os
import select
import subprocess
import sys
from typing import Callable

import numpy as np

from hapticop.sim.hallway import HallwayGeometry, World

FAULTS = ("none", "unplugged", "stall", "garbage")  # the lidar block's `sim_fault`


def scan_of(world: World, geometry: HallwayGeometry, pose: np.ndarray) -> Callable[[int], np.ndarray]:
    """The simulator's `ranges_m`: the hallway ray-cast from the robot's pose as it is when asked."""
    from hapticop.devices.sick.simulator import ANGLES_RAD

    lidar = geometry.lidar
    mount, angles = np.asarray(lidar.mount, dtype=float), np.asarray(ANGLES_RAD, dtype=float)
    cast, where = np.zeros(len(angles)), np.zeros(3)

    def ranges_m(_now_ns: int) -> np.ndarray:
        np.copyto(where, pose)  # one copy: the world may move the robot meanwhile
        world.raycast(where, mount, angles, cast, max_range=lidar.max_range_m, min_range=lidar.min_range_m)
        np.nan_to_num(cast, copy=False, nan=0.0)  # no echo: the TiM reports 0
        return cast

    return ranges_m


class ScannerProcess:
    """The block's handle on the program: its port once it listens, fault switches, stop."""

    def __init__(self, scene_memory: str, scan_rate_hz: float, seed: int):
        self.process = subprocess.Popen(
            [sys.executable, "-m", "hapticop.sim.scanner_process", scene_memory, str(scan_rate_hz), str(seed)],
            stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True, bufsize=1)
        self.port: int | None = None

    def ready(self) -> bool:
        """True once the simulator listens (never blocks: the caller asks again next cycle)."""
        if self.port is None:
            if select.select([self.process.stdout], [], [], 0)[0]:
                line = self.process.stdout.readline().strip()
                if not line.isdigit():
                    raise RuntimeError(f"the simulated scanner did not start: {line or 'it ended'}")
                self.port = int(line)
            elif self.process.poll() is not None:
                raise RuntimeError(f"the simulated scanner ended (exit code {self.process.returncode})")
        return self.port is not None

    def fault(self, name: str) -> None:
        """Switch the simulated scanner's fault (one of `FAULTS`)."""
        if name not in FAULTS:
            raise ValueError(f"unknown scanner fault {name!r}; one of {', '.join(FAULTS)}")
        self.process.stdin.write(name + "\n")

    def stop(self, timeout_s: float = 5.0) -> None:
        try:
            self.process.stdin.close()  # its signal to end
            self.process.wait(timeout_s)
        except (OSError, subprocess.TimeoutExpired):
            self.process.kill()
            self.process.wait(timeout_s)
        self.process.stdout.close()


def main() -> None:
    from multiprocessing import resource_tracker

    from hapticop.devices.sick.simulator import TiMSimulator
    from hapticop.runtime.realtime import normal_scheduling
    from hapticop.sim.scene import attach_scene

    parser = argparse.ArgumentParser(description="a simulated TiM561 on loopback, in the world of a running scene")
    parser.add_argument("scene_memory")
    parser.add_argument("scan_rate_hz", type=float)
    parser.add_argument("seed", type=int)
    args = parser.parse_args()
    normal_scheduling()  # started by a real-time thread, but the device is not part of the system
    try:
        scene = attach_scene(args.scene_memory)
        # Only attached: the world's process unlinks it, not this process's resource tracker.
        resource_tracker.unregister(scene.shared_pose._name, "shared_memory")  # noqa: SLF001
        geometry = scene.geometry
        simulator = TiMSimulator("127.0.0.1", 0, ranges_m=scan_of(World.from_geometry(geometry), geometry, scene.pose),
                                 noise_std_m=geometry.lidar.noise_sigma_m, rng=np.random.default_rng(args.seed),
                                 scan_rate_hz=args.scan_rate_hz)
    except Exception as error:  # noqa: BLE001 - the block reports it
        print(f"{type(error).__name__}: {error}", flush=True)
        return
    simulator.start()
    print(simulator.port, flush=True)
    fault, stdin = "none", sys.stdin.fileno()
    try:
        while True:
            if fault == "garbage":
                simulator.inject_garbage()  # noise between telegrams, as long as the fault lasts
            if not select.select([stdin], [], [], 1.0 / args.scan_rate_hz)[0]:
                continue
            line = sys.stdin.readline()
            if not line:
                break  # stdin closed: the block is done with us
            fault = line.strip()
            simulator.set_fault(fault)
    finally:
        simulator.close()
        os._exit(0)  # the scene's views are still mapped; nothing more to tidy


if __name__ == "__main__":
    main()
