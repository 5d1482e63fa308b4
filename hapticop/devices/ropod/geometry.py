"""The ropod's smart-wheel geometry: a parameter set of its own, apart from the compiled kinematics
(a compiled module's classes have no source to read their field docstrings from)."""

from __future__ import annotations

from typing import Annotated

from annotated_types import Gt

from hapticop.parameters import parameters

__all__ = ["Geometry"]


@parameters
class Geometry:
    """Ropod geometry as compiled in the June-2019 controller (docs/devices/ropod.md §2.2), in metres.

    Pivots SW1..SW4 counter-clockwise from front-left; the order is a known open question (§10 Q1).
    """

    wheel_radius_m: Annotated[float, Gt(0)] = 0.0525
    """r, the radius of each wheel."""
    caster_offset_m: Annotated[float, Gt(0)] = 0.01
    """s, how far each unit's axle trails its pivot."""
    wheel_distance_m: Annotated[float, Gt(0)] = 0.08
    """d, the distance between a unit's two wheels."""
    pivots_m: tuple[tuple[float, float], ...] = ((0.21, 0.21), (-0.21, 0.21), (-0.21, -0.21), (0.21, -0.21))
    """(x, y) of each unit's pivot in the robot frame, SW1 first."""

    @property
    def units(self) -> int:
        return len(self.pivots_m)

    @property
    def wheels(self) -> int:
        return 2 * len(self.pivots_m)

    @property
    def k(self) -> float:
        """Lateral-to-differential lever d/(2s): moving across a unit costs k times the wheel speed."""
        return self.wheel_distance_m / (2.0 * self.caster_offset_m)
