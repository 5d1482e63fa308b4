"""The hallway experiment's log made from a recording's streams, for a run with no simulated world to record it.

Why: with the real robot nothing records the run the way the world block does, yet its recording
holds the streams the metrics and the picture need (docs/hallway-experiment.md §5). They are found
by the block and port that write them, whatever the composition calls them: the haptic controller's
commanded twist and forces on its own cycles, the Falcon's handle, and the ropod controller's measured
platform twist, integrated from the hallway's start pose into the path. That path is odometry: it
drifts as wheels slip, where a simulated world's log has the true pose.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from typing import Any

import numpy as np

# what the log takes from which writer: (block type, output port)
COMMAND = ("haptic_controller", "velocity_setpoint")
SOURCES = {
    "force_env": ("haptic_controller", "environment_force"),
    "force_device": ("haptic_controller", "force"),
    "handle_position": ("falcon", "position"),
    "handle_velocity": ("falcon", "velocity"),
}
ODOMETRY = ("ropod_controller", "platform_velocity")
READ = (COMMAND, ODOMETRY, *SOURCES.values())


class MissingStream(ValueError):
    """The recording lacks a stream the log cannot be made without."""


def writers(streams: Mapping[str, str], blocks: Mapping[str, str]) -> dict[tuple[str, str], str]:
    """(block type, port) -> stream, from each stream's writer ('activity.port') and each activity's block;
    the first in file order where two blocks of a type write."""
    found: dict[tuple[str, str], str] = {}
    for name, writer in streams.items():
        activity, port = writer.split(".")
        found.setdefault((blocks.get(activity, ""), port), name)
    return found


def integrate(times_ns: np.ndarray, twists: np.ndarray, start: tuple[float, float, float]) -> np.ndarray:
    """Poses (x, y, theta) at each sample from a twist (vx, vy in the robot's frame, wz) held between
    samples, from `start`."""
    poses = np.empty((len(times_ns), 3))
    x, y, theta = start
    for i in range(len(times_ns)):
        if i:
            dt = (int(times_ns[i]) - int(times_ns[i - 1])) / 1e9
            vx, vy, wz = (float(v) for v in twists[i - 1])
            mid = theta + 0.5 * wz * dt
            x += (vx * math.cos(mid) - vy * math.sin(mid)) * dt
            y += (vx * math.sin(mid) + vy * math.cos(mid)) * dt
            theta += wz * dt
        poses[i] = x, y, theta
    return poses


def _at(times_ns: np.ndarray, sample_ns: np.ndarray, values: np.ndarray) -> np.ndarray:
    """The latest of `values` published at or before each time (the first one before any)."""
    index = np.clip(np.searchsorted(sample_ns, times_ns, side="right") - 1, 0, len(sample_ns) - 1)
    return values[index]


def hallway_log(found: Mapping[tuple[str, str], str], series: Callable[[str], Any],
                start: tuple[float, float, float]) -> dict[str, np.ndarray]:
    """The log's channels (`sim.recording.CHANNELS`) on the haptic controller's cycles, from when it first
    commanded motion. `series(stream)` gives a recorded stream's samples (`recording.reading.Series`)."""
    for needed in (COMMAND, ODOMETRY):
        if needed not in found:
            raise MissingStream(f"no recorded stream from a {needed[0]} block's '{needed[1]}' port: the path and "
                                "the commands come from it")
    command = series(found[COMMAND])
    odometry = series(found[ODOMETRY])
    if len(command.values) < 2 or not len(odometry.values):
        raise MissingStream(f"'{found[COMMAND]}' or '{found[ODOMETRY]}' holds too few samples for a run")
    moving = np.flatnonzero(np.abs(command.values).max(axis=1) > 0)
    first = int(moving[0]) if len(moving) else 0
    times = command.publish_ns[first:]
    poses = integrate(odometry.publish_ns, odometry.values, start)
    twist = _at(times, odometry.publish_ns, odometry.values)
    cmd = command.values[first:]
    log = {"t": (times - times[0]) / 1e9, "pose": _at(times, odometry.publish_ns, poses),
           "robot_velocity": twist[:, [0, 2]].astype(np.float64), "cmd": cmd[:, [0, 2]].astype(np.float64)}
    for channel, writer in SOURCES.items():
        if writer in found:
            samples = series(found[writer])
            if len(samples.values):
                log[channel] = _at(times, samples.publish_ns, samples.values).astype(np.float64)
    return log
