"""Benchmark: what the scene world costs the simulators' thread per cycle, and the LIDAR's scan, in this
thread's CPU time (time.thread_time_ns), so that other work on a busy machine does not count.

Each block runs on the runtime's own runner (hapticop.testing.BlockHarness) under a virtual clock, as its
thread steps it: `scene_world` on H4 with the robot driving down it at 0.5 m/s and the operator driving
(each cycle recorded and judged: the hallway's case), and `scene_world` on the bilateral desk
(systems/scenes/bilateral.yaml) with the follower's handle moving in and out of the wall; the 811-beam
scan is the simulated TiM561's `mj_multiRay` from the robot on H4. Each row: p50, p99 and max of the
calls, in microseconds, for each of `--repeat` rounds.

    python bench/scene_cost.py --cycles 20000 --repeat 3

`--old` measures the hand-written world of the commit before the scene world (a6da3ca~1) instead:
`hallway_world` on H4 and its ray caster, with PYTHONPATH at that commit's tree (`git archive`).
"""

from __future__ import annotations

import argparse
import math
import os
import time
from pathlib import Path

import numpy as np

from hapticop.testing import BlockHarness

ROOT = Path(__file__).resolve().parent.parent


def _stats(samples: list[int]) -> tuple[float, float, float]:
    a = np.asarray(samples) / 1e3
    return float(np.percentile(a, 50)), float(np.percentile(a, 99)), float(a.max())


def _timed(harness: BlockHarness, cycles: int, feed) -> list[int]:
    harness.configure()
    times = []
    for i in range(cycles):
        feed(harness, i)
        started = time.thread_time_ns()
        harness.step()
        times.append(time.thread_time_ns() - started)
    return times


def _driving(harness: BlockHarness, i: int) -> None:
    harness.feed("robot_pose", [0.5e-3 * (i % 8000), 0.0, 0.0])
    harness.feed("robot_twist", [0.5, 0.0, 0.0])
    harness.feed("operator_time", i * 1e-3)  # the operator drives: the world records and judges every cycle


def _hallway(block: str, params: dict, cycles: int) -> list[int]:
    import tempfile

    with tempfile.TemporaryDirectory() as run_dir:
        return _timed(BlockHarness(block, params, name="world", run_dir=run_dir), cycles, _driving)


def _handle(harness: BlockHarness, i: int) -> None:
    z = -0.02 + 0.004 * math.sin(2 * math.pi * i / 1000)  # in and out of the wall, 4 mm each way, at 1 Hz
    harness.feed("follower_handle_position", [0.0, 0.0, z])
    harness.feed("follower_handle_velocity", [0.0, 0.0, 0.004 * 2 * math.pi * math.cos(2 * math.pi * i / 1000)])


def _desk(cycles: int) -> list[int]:
    import sys
    import tempfile

    sys.path.append(str(ROOT / "systems"))  # the scene file beside the composition
    params = {"scene": "scenes/bilateral.yaml", "judge": False, "plot": False}
    with tempfile.TemporaryDirectory() as run_dir:
        return _timed(BlockHarness("scene_world", params, name="world", run_dir=run_dir), cycles, _handle)


def _scans(count: int, old: bool) -> list[int]:
    from hapticop.devices.sick.device_model import ANGLES_RAD

    angles, ranges, times = np.asarray(ANGLES_RAD, dtype=float), np.zeros(811), []
    if old:
        from hapticop.sim.hallway import HallwayGeometry, World

        geometry = HallwayGeometry.named("H4")
        walls = World.from_geometry(geometry)

        def scan(pose):
            walls.raycast(pose, geometry.lidar.mount, angles, ranges, 10.0, 0.05)
    else:
        from hapticop.sim import scene_files
        from hapticop.sim.engine import Engine

        engine = Engine(scene_files.load("H4")[0].xml)

        def scan(pose):
            engine.place_robot(pose)
            engine.scan(angles, ranges, 0.05, 10.0)
    for i in range(count):
        pose = np.array([0.5 + 0.01 * (i % 800), 0.1, 0.05])
        started = time.thread_time_ns()
        scan(pose)
        times.append(time.thread_time_ns() - started)
    return times


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--cycles", type=int, default=20000)
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--old", action="store_true", help="the hand-written world (PYTHONPATH at a6da3ca~1)")
    args = parser.parse_args()
    rows: dict[str, list[tuple[float, float, float]]] = {}
    for _ in range(args.repeat):
        if args.old:
            rows.setdefault("hallway_world compute (H4, driving, judged)", []).append(
                _stats(_hallway("hallway_world", {"hallway": "H4", "plot": False}, args.cycles)))
        else:
            rows.setdefault("scene_world compute (H4, driving, judged)", []).append(
                _stats(_hallway("scene_world", {"scene": "H4", "plot": False}, args.cycles)))
            rows.setdefault("scene_world compute (bilateral desk, handle in and out of the wall)", []).append(
                _stats(_desk(args.cycles)))
        rows.setdefault("scan, 811 beams" + (" (hand-written ray caster)" if args.old else " (mj_multiRay)"),
                        []).append(_stats(_scans(max(args.cycles // 20, 200), args.old)))
    print(f"load average {' '.join(f'{x:.2f}' for x in os.getloadavg())}; us of thread CPU time per call, "
          "p50 / p99 / max, one round each")
    print("| what | " + " | ".join(f"round {i + 1}" for i in range(args.repeat)) + " |")
    print("|---|" + "---|" * args.repeat)
    for what, stats in rows.items():
        print(f"| {what} | " + " | ".join(f"{a:.1f} / {b:.1f} / {c:.0f}" for a, b, c in stats) + " |")


if __name__ == "__main__":
    main()
