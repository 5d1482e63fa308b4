"""The haptic controller: handle displacement to robot velocity, obstacles to force.

It holds the handle at its origin with a PD (Kp 55 N/m, Kd 0.2 Ns/m), maps displacement to
velocity setpoints with the car-driving metaphor (k1 28, k2 10, 0.5 cm dead zone) and adds
the environmental force of the chosen model, everything limited to 10 N per axis.
"""

from __future__ import annotations

from typing import Literal

from pydantic import Field

from hapticop.blocks.base import Block
from hapticop.blocks.interface import Interface, Params, Port, RateRange


class HapticControllerParams(Params):
    kp_n_per_m: float = Field(55.0, ge=0, description="handle-centring stiffness")
    kd_ns_per_m: float = Field(0.2, ge=0, description="handle-centring damping")
    force_limit_n: float = Field(10.0, gt=0, le=20.0, description="per-axis force saturation")
    k1: float = Field(28.0, description="forward speed per handle displacement, (m/s)/m")
    k2: float = Field(10.0, description="turn rate per handle displacement, (rad/s)/m")
    dead_zone_m: float = Field(0.005, ge=0)
    force_model: Literal["none", "thesis", "braking_field"] = "thesis"
    k3_n_per_m: float = Field(100.0, ge=0, description="environmental force scale, z (eq. 5.5)")
    k4_n_per_m: float = Field(100.0, ge=0, description="environmental force scale, x (eq. 5.6)")
    d_max_m: float = Field(2.0, gt=0, description="range beyond which obstacles exert no force")
    moving_average: int = Field(3, ge=1, description="window of the range filter (811 points give 809)")
    scan_points: int = Field(811, ge=2, le=10_000)


class HapticController(Block):
    Params = HapticControllerParams
    flags_read = {"resources_ready": "the Falcon, LIDAR and ropod controller are running"}

    @classmethod
    def interface(cls, params: HapticControllerParams) -> Interface:
        n = (params.scan_points,)
        return Interface(
            inputs={
                "handle_position": Port("float64", (3,), "m"),
                "handle_velocity": Port("float64", (3,), "m/s"),
                "ranges": Port("float32", n, "m"),
                "angles": Port("float32", n, "rad"),
                "platform_velocity": Port("float64", (3,), "m/s, m/s, rad/s", required=False),
            },
            outputs={
                "force": Port("float64", (3,), "N", "force for the Falcon"),
                "velocity_setpoint": Port("float64", (3,), "m/s, m/s, rad/s", "platform twist [vx, vy, wz]"),
            },
            flags_read=dict(cls.flags_read),
            rate=RateRange(500.0, 2000.0, "the haptic loop renders stiff forces only near 1 kHz"),
        )
