"""Benchmark: the scene world's cost per cycle on MuJoCo, and the LIDAR's scan.

The world steps alone under a virtual clock (as the simulators' thread steps it), the robot driving
down H4 at 0.5 m/s and the operator driving (so each cycle is recorded and judged), its compute
timed per call; the LIDAR's scan (811 beams, `mj_multiRay`) is timed the same way. Figures in
microseconds (p50, p99, max).

    python bench/micro_scene.py --cycles 20000
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np


def _stats(samples: list[float]) -> str:
    a = np.asarray(samples) * 1e6
    p50, p90, p99 = np.percentile(a, (50, 90, 99))
    return f"p50 {p50:.1f} | p90 {p90:.1f} | p99 {p99:.1f} | max {a.max():.1f}"


def _world(block, params: dict, cycles: int) -> list[float]:
    import sys

    sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tests"))
    from runtime_helpers import standalone

    from hapticop.runtime.clock import VirtualClock

    clock = VirtualClock()
    with tempfile.TemporaryDirectory() as run_dir:
        world = standalone(block, "world", params, Path(run_dir), clock)
        world.create()
        pose, twist, driven = world.inputs.robot_pose, world.inputs.robot_twist, world.inputs.operator_time
        times = []
        for i in range(cycles):
            clock.advance_to(clock.now_ns() + 1_000_000)
            pose.value[0] = 0.5e-3 * (i % 8000)
            twist.value[0] = 0.5
            driven.value[...] = i * 1e-3  # the operator drives: the world records and judges every cycle
            pose.meta[0] = twist.meta[0] = driven.meta[0] = i + 1
            started = time.perf_counter()
            world.compute()
            times.append(time.perf_counter() - started)
        return times


def _scans(count: int) -> list[float]:
    from hapticop.devices.sick.device_model import ANGLES_RAD
    from hapticop.sim import scene_files
    from hapticop.sim.engine import Engine

    engine = Engine(scene_files.load("H4")[0].xml)
    angles, ranges = np.asarray(ANGLES_RAD, dtype=float), np.zeros(811)
    times = []
    for i in range(count):
        pose = np.array([0.5 + 0.01 * (i % 800), 0.1, 0.05])
        started = time.perf_counter()
        engine.place_robot(pose)
        engine.scan(angles, ranges, 0.05, 10.0)
        times.append(time.perf_counter() - started)
    return times


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--cycles", type=int, default=20000)
    args = parser.parse_args()
    from hapticop.sim.scene_world import SceneWorld

    print("| what | us per call |")
    print("|---|---|")
    print(f"| scene_world compute (H4: place, mj_step, clearance, contact) | "
          f"{_stats(_world(SceneWorld, {'scene': 'H4', 'plot': False}, args.cycles))} |")
    print(f"| mj_multiRay scan, 811 beams | {_stats(_scans(max(args.cycles // 20, 200)))} |")


if __name__ == "__main__":
    main()
