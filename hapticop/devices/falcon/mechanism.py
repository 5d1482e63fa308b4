"""The Falcon's mechanism as numbers: link dimensions, drive train and the reachable workspace.

`Geometry` is a parameter set (`hapticop.parameters`): the Falcon block and its simulator
take it as their `geometry` parameter, validated from YAML as it is. `Drive` holds the
encoder and motor conversions. Both feed `FalconKinematics` (`kinematics`); the equations
and where each number comes from are in docs/devices/falcon-kinematics.md.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from hapticop.parameters import parameters

__all__ = ["Geometry", "Drive", "WORKSPACE_CENTRE_M", "WORKSPACE_BOX_M"]

#: Centre of the sampled reachable box (§9: x, y in +-45 mm, z in 80..170 mm). The device
#: frame has no agreed origin (libnifalcon 0.150, ros_falcon_interface 0.125 ...): blocks
#: choose theirs and subtract it after FK.
WORKSPACE_CENTRE_M: tuple[float, float, float] = (0.0, 0.0, 0.125)
#: (low, high) corners of that box, metres. Not every corner is reachable.
WORKSPACE_BOX_M: tuple[tuple[float, float, float], tuple[float, float, float]] = (
    (-0.045, -0.045, 0.080), (0.045, 0.045, 0.170))


@parameters
class Geometry:
    """Mechanism dimensions in metres, libnifalcon's values and signs (docs/devices/falcon-kinematics.md §1).

    The thesis (appendix B) lists r = 36.60, s = 23.09, f = 25.00 mm unsigned plus an unused
    g; following docs/devices/falcon-kinematics.md, we default to libnifalcon's r = 40.00, s = -23.09, f = -25.00 mm,
    the values all reference data was produced with. With r = 36.6 mm the same counts land
    up to ~4 mm elsewhere, so keep the geometry a parameter: the Falcon block and its
    simulator take this class as their `geometry` parameter as it is.
    """

    a: float = 0.060
    """Thigh length (m)."""
    b: float = 0.1025
    """Parallelogram link length (m)."""
    c: float = 0.01443
    """Platform radius (m)."""
    d: float = 0.01125
    """Parallelogram to platform joint offset (m)."""
    e: float = 0.01125
    """Thigh to parallelogram offset (m)."""
    f: float = -0.025
    """Platform-side offset along the joint axis v (m, libnifalcon's sign)."""
    r: float = 0.0400
    """Base radius (m)."""
    s: float = -0.02309
    """Base-side offset along the joint axis v (m, libnifalcon's sign)."""
    leg_angles_deg: tuple[float, float, float] = (105.0, -15.0, -135.0)
    """Leg directions in the x-y plane (deg): legs 1 (top), 2 (right), 3 (left) seen from the front."""


@dataclass(frozen=True)
class Drive:
    """Encoder and motor conversions of one leg (docs/devices/falcon-kinematics.md §7, §8).

    An encoder of 320 slots read in quadrature gives 1280 counts per motor turn; a 14.25 mm
    capstan drives a 110 mm arm sector, so one count is 6.359e-4 rad of thigh; count 0
    (once homed) is taken as 35 deg. Angles use exact degree-to-radian conversion, not
    libnifalcon's rounded 0.0174532925 (relative difference 1e-9, i.e. < 1e-10 m).

    `motor_per_nm` is libnifalcon's empirical torque-to-command factor and sign
    (motor = trunc(-10000 tau)), a starting point, not a calibration: Novint's own driver
    was seen using a different scale. `motor_limit` is the +-4095 docs/devices/falcon-kinematics.md recommend
    (docs/devices/falcon.md §4.1) until hardware says otherwise; `torque_limit_nm` is libnifalcon's 30 N m.
    """

    counts_per_turn: int = 320 * 4
    capstan_diameter_m: float = 0.01425
    sector_diameter_m: float = 0.110
    zero_count_deg: float = 35.0
    motor_per_nm: float = -10000.0
    motor_limit: int = 4095
    torque_limit_nm: float = 30.0

    @property
    def rad_per_count(self) -> float:
        return 2.0 * math.pi / self.counts_per_turn * self.capstan_diameter_m / self.sector_diameter_m

    @property
    def zero_count_rad(self) -> float:
        return math.radians(self.zero_count_deg)
