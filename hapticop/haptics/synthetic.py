"""Synthetic scans: ray-cast a 2-D LIDAR against wall segments, for tests and benchmarks.

Not for the control loop (it allocates). Conventions match the LIDAR block: angles in the robot
frame (0 ahead, + left), ranges from the scanner origin, NaN where a beam gets no return.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray

Segment = tuple[tuple[float, float], tuple[float, float]]


def tim561_angles(points: int = 811, fov_deg: float = 270.0) -> NDArray[np.float64]:
    """Beam angles of a TiM561-like scanner: ``points`` beams evenly over ``fov_deg``, centred ahead."""
    half = math.radians(fov_deg) / 2.0
    return np.linspace(-half, half, points)


def cast(
    angles: NDArray[np.float64],
    segments: Sequence[Segment],
    origin: tuple[float, float] = (0.0, 0.0),
    heading: float = 0.0,
    min_range: float = 0.05,
    max_range: float = 10.0,
) -> NDArray[np.float64]:
    """Ranges from a scanner at ``origin`` (world, m) facing ``heading`` (rad) to the nearest segment.

    Beams without a hit within [min_range, max_range] are NaN, like the LIDAR block's invalid beams.
    """
    world = np.asarray(angles, dtype=np.float64) + heading
    dx, dy = np.cos(world), np.sin(world)
    best = np.full(world.shape, np.inf)
    ox, oy = origin
    for (ax, ay), (bx, by) in segments:
        ex, ey = bx - ax, by - ay
        # Solve o + t·d = a + s·e for t (range) and s (position on the segment).
        den = dx * ey - dy * ex
        with np.errstate(divide="ignore", invalid="ignore"):
            t = ((ax - ox) * ey - (ay - oy) * ex) / den
            s = ((ax - ox) * dy - (ay - oy) * dx) / den
        hit = (np.abs(den) > 1e-12) & (t > 0) & (s >= 0) & (s <= 1)
        np.minimum(best, np.where(hit, t, np.inf), out=best)
    best[(best < min_range) | (best > max_range)] = np.nan
    return best


def robot_scan(
    angles: NDArray[np.float64],
    segments: Sequence[Segment],
    pose: tuple[float, float, float] = (0.0, 0.0, 0.0),
    lidar_xy: tuple[float, float] = (0.25, 0.0),
) -> NDArray[np.float64]:
    """Scan seen by a robot at ``pose`` (x, y, heading of its footprint centre) with the LIDAR at ``lidar_xy``."""
    x, y, th = pose
    c, s = math.cos(th), math.sin(th)
    origin = (x + c * lidar_xy[0] - s * lidar_xy[1], y + s * lidar_xy[0] + c * lidar_xy[1])
    return cast(angles, segments, origin=origin, heading=th)


def hallway(width: float, end: float, back: float = -5.0) -> list[Segment]:
    """Dead-end hallway along +x (notes §2): side walls at y = ±width/2 and an end wall at x = end."""
    h = width / 2.0
    return [((back, h), (end, h)), ((back, -h), (end, -h)), ((end, -h), (end, h))]
