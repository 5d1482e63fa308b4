"""Scans of wall segments for the haptics tests, cast by the simulated world's one ray caster."""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray

from hapticop.devices.ropod.body import Body
from hapticop.sim.hallway import World

Segment = tuple[tuple[float, float], tuple[float, float]]


def tim561_angles(points: int = 811, fov_deg: float = 270.0) -> NDArray[np.float64]:
    """Beam angles of a TiM561-like scanner: ``points`` beams evenly over ``fov_deg``, centred ahead."""
    half = math.radians(fov_deg) / 2.0
    return np.linspace(-half, half, points)


def robot_scan(
    angles: NDArray[np.float64],
    segments: Sequence[Segment],
    pose: tuple[float, float, float] = (0.0, 0.0, 0.0),
    body: Body = Body(),
) -> NDArray[np.float64]:
    """Ranges seen by a robot at ``pose`` (x, y, heading of its footprint centre) from its LIDAR mount;
    NaN where a beam hits nothing within the scanner's range, as the LIDAR block reports it."""
    return World(segments).raycast(pose, body.lidar, angles, np.empty(len(angles)))


def hallway(width: float, end: float, back: float = -5.0) -> list[Segment]:
    """Dead-end hallway along +x (notes §2): side walls at y = ±width/2 and an end wall at x = end."""
    h = width / 2.0
    return [((back, h), (end, h)), ((back, -h), (end, -h)), ((end, -h), (end, h))]
