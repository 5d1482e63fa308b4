"""The robot's body: its rectangular footprint and where its LIDAR sits, written once.

The haptic geometry measures clearance from this footprint with ranges taken at this mount;
the simulated world casts its scans from the mount and judges collisions with the footprint;
the LIDAR block places its beams with the mount. The values are those of the hallway
experiment's simulated ropod (0.70 m x 0.60 m, TiM561 0.25 m ahead of the centre, looking ahead).
Robot frame: x forward, y left (REP 103), origin at the footprint's centre.
"""

from __future__ import annotations

import dataclasses
from typing import Annotated

import numpy as np
from annotated_types import Gt
from numpy.typing import ArrayLike, NDArray

from hapticop.devices.sick.scan import SensorMount
from hapticop.parameters import parameters

__all__ = ["Body", "Footprint", "SensorMount"]


@parameters
class Footprint:
    """The robot's rectangular outline, centred on its origin."""

    length_m: Annotated[float, Gt(0)] = 0.70
    """Along x."""
    width_m: Annotated[float, Gt(0)] = 0.60
    """Along y."""

    def corners(self, poses: ArrayLike) -> NDArray[np.float64]:
        """Corners (..., 4, 2) in world coordinates, counter-clockwise from front-left, for poses (..., 3)."""
        p = np.asarray(poses, dtype=np.float64)
        hl, hw = 0.5 * self.length_m, 0.5 * self.width_m
        local = np.array([[hl, hw], [-hl, hw], [-hl, -hw], [hl, -hw]])
        c, s = np.cos(p[..., 2])[..., None], np.sin(p[..., 2])[..., None]
        x = p[..., 0:1] + c * local[:, 0] - s * local[:, 1]
        y = p[..., 1:2] + s * local[:, 0] + c * local[:, 1]
        return np.stack([x, y], axis=-1)


@parameters
class Body:
    """The footprint and the LIDAR's mount on it."""

    footprint: Footprint = dataclasses.field(default_factory=Footprint)
    """The outline clearances are measured from."""
    lidar: SensorMount = SensorMount(x_m=0.25, y_m=0.0, yaw_rad=0.0)
    """The scanner's origin (m) and heading (rad) in the robot frame: its ranges start here."""
