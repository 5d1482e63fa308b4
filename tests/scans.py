"""Scans of wall segments for the haptics tests, cast by the simulated world's ray caster (MuJoCo's, on a
scene whose walls are the segments)."""

from __future__ import annotations

import math
from collections.abc import Sequence
from functools import lru_cache

import numpy as np
from numpy.typing import NDArray

from hapticop.devices.ropod.body import Body
from hapticop.sim.engine import Engine
from hapticop.sim.scene import Block3, Lidar, Robot, Scene, to_mjcf

Segment = tuple[tuple[float, float], tuple[float, float]]

THIN_M = 1e-6
"""Each segment is a box this thick, behind it as the scanner sees it."""
BEHIND_M = 1e-12
"""The box's face lies this far behind the segment: a wall placed exactly on the footprint's edge is
seen on it or beyond, never inside by a rounding (the tests place walls there)."""


def tim561_angles(points: int = 811, fov_deg: float = 270.0) -> NDArray[np.float64]:
    """Beam angles of a TiM561-like scanner: ``points`` beams evenly over ``fov_deg``, centred ahead."""
    half = math.radians(fov_deg) / 2.0
    return np.linspace(-half, half, points)


@lru_cache(maxsize=64)
def _engine(segments: tuple[Segment, ...], sides: tuple[float, ...], lidar: tuple[float, float, float]) -> Engine:
    walls = []
    for ((ax, ay), (bx, by)), side in zip(segments, sides):
        length = math.hypot(bx - ax, by - ay)
        nx, ny = -(by - ay) / length, (bx - ax) / length  # the segment's left normal
        shift = -side * (0.5 * THIN_M + BEHIND_M)  # the box behind the segment, seen from the scanner
        walls.append(Block3(size_m=(length, THIN_M, 1.0), yaw_deg=math.degrees(math.atan2(by - ay, bx - ax)),
                            position_m=(0.5 * (ax + bx) + shift * nx, 0.5 * (ay + by) + shift * ny)))
    x, y, yaw = lidar
    robot = Robot(lidar=Lidar(x_m=x, y_m=y, yaw_deg=math.degrees(yaw)))
    return Engine(to_mjcf(Scene(walls=tuple(walls), robot=robot)))


def robot_scan(
    angles: NDArray[np.float64],
    segments: Sequence[Segment],
    pose: tuple[float, float, float] = (0.0, 0.0, 0.0),
    body: Body = Body(),
) -> NDArray[np.float64]:
    """Ranges seen by a robot at ``pose`` (x, y, heading of its footprint centre) from its LIDAR mount;
    NaN where a beam hits nothing within the scanner's range (0.05 to 10 m), as the LIDAR block reports it."""
    mount = body.lidar
    x, y, theta = (float(v) for v in pose)
    ox = x + math.cos(theta) * mount.x_m - math.sin(theta) * mount.y_m
    oy = y + math.sin(theta) * mount.x_m + math.cos(theta) * mount.y_m
    key = tuple(((float(a[0]), float(a[1])), (float(b[0]), float(b[1]))) for a, b in segments)
    sides = tuple(1.0 if (bx - ax) * (oy - ay) - (by - ay) * (ox - ax) >= 0 else -1.0
                  for (ax, ay), (bx, by) in key)  # the scanner left (1) or right (-1) of each segment
    engine = _engine(key, sides, (mount.x_m, mount.y_m, mount.yaw_rad))
    engine.place_robot(np.array([x, y, theta]))
    return engine.scan(np.asarray(angles, dtype=np.float64), np.empty(len(angles)), 0.05, 10.0, mount.yaw_rad)


def hallway(width: float, end: float, back: float = -5.0) -> list[Segment]:
    """Dead-end hallway along +x (notes §2): side walls at y = ±width/2 and an end wall at x = end."""
    h = width / 2.0
    return [((back, h), (end, h)), ((back, -h), (end, -h)), ((end, -h), (end, h))]
