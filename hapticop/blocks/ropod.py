"""The ropod platform velocity controller: platform twist setpoint in, wheel currents out.

Three platform controllers (x, y, theta) and eight wheel controllers, each the generic
gain / PI / lead-lag / low-pass chain at 1 kHz, with the thesis's Appendix D values
(../shared/reference/ropod-controller.md).
"""

from __future__ import annotations

import numpy as np
from pydantic import Field

from hapticop.blocks.base import Block
from hapticop.blocks.ethercat import SMARTWHEEL_INPUT_BYTES, SMARTWHEEL_OUTPUT_BYTES
from hapticop.blocks.interface import Interface, Params, Port, RateRange


class LinearController(Params):
    """Gain, PI with saturation and anti-windup, lead-lag, low pass (Tustin)."""

    p_gain: float
    i_fhz: float = Field(ge=0)
    ll_zero_fhz: float = Field(gt=0)
    ll_pole_fhz: float = Field(gt=0)
    lpf_fhz: float = Field(gt=0)
    i_saturation: float = Field(gt=0)


class RopodGeometry(Params):
    wheel_radius_m: float = 0.0525
    caster_offset_m: float = 0.01
    wheel_distance_m: float = 0.08
    pivots_m: tuple[tuple[float, float], ...] = ((0.21, 0.21), (-0.21, 0.21), (-0.21, -0.21), (0.21, -0.21))
    mass_kg: float = 36.5


class RopodControllerParams(Params):
    platform_xy: LinearController = Field(
        default_factory=lambda: LinearController(p_gain=100, i_fhz=0.25, ll_zero_fhz=20, ll_pole_fhz=20,
                                                 lpf_fhz=100, i_saturation=100)
    )
    platform_theta: LinearController = Field(
        default_factory=lambda: LinearController(p_gain=755, i_fhz=0.3, ll_zero_fhz=20, ll_pole_fhz=20,
                                                 lpf_fhz=100, i_saturation=100)
    )
    wheel: LinearController = Field(
        default_factory=lambda: LinearController(p_gain=0.05, i_fhz=0, ll_zero_fhz=2, ll_pole_fhz=10,
                                                 lpf_fhz=50, i_saturation=7)
    )
    torque_constant_nm_per_a: float = Field(0.28, gt=0)
    current_limit_a: float = Field(10.0, gt=0)
    pivot_offsets_rad: tuple[float, ...] = (4.691878, 3.224157, 0.028178, 5.856820)
    geometry: RopodGeometry = Field(default_factory=RopodGeometry)


class RopodController(Block):
    Params = RopodControllerParams
    capability_params = frozenset({"platform_xy", "platform_theta", "wheel"})

    @classmethod
    def interface(cls, params: RopodControllerParams) -> Interface:
        wheels = len(params.geometry.pivots_m)
        return Interface(
            inputs={
                "velocity_setpoint": Port("float64", (3,), "m/s, m/s, rad/s", "platform twist [vx, vy, wz]"),
                "wheel_sensors": Port("uint8", (wheels, SMARTWHEEL_INPUT_BYTES), "1", "TxPDO image per wheel"),
            },
            outputs={
                "wheel_commands": Port("uint8", (wheels, SMARTWHEEL_OUTPUT_BYTES), "1", "RxPDO image per wheel"),
                "platform_velocity": Port("float64", (3,), "m/s, m/s, rad/s", "measured platform twist"),
            },
            flags_read={"stop": "hold zero velocity (a wheel is not operational)"},
            rate=RateRange(1000.0, 1000.0, "the discretised controllers are tuned for Ts = 1 ms"),
        )

    def configure_resources(self) -> None:
        from hapticop.devices.ropod import Geometry, LinearControllerParams, PlatformControllerParams
        from hapticop.devices.ropod import PlatformVelocityController

        p = self.params
        gains = {name: LinearControllerParams(**getattr(p, name).model_dump())
                 for name in ("platform_xy", "platform_theta", "wheel")}
        geometry = Geometry(wheel_radius_m=p.geometry.wheel_radius_m, caster_offset_m=p.geometry.caster_offset_m,
                            wheel_distance_m=p.geometry.wheel_distance_m, pivots_m=p.geometry.pivots_m)
        self.controller = PlatformVelocityController(PlatformControllerParams(
            **gains, geometry=geometry, torque_constant_nm_per_a=p.torque_constant_nm_per_a,
            current_limit_a=p.current_limit_a, pivot_offsets_rad=p.pivot_offsets_rad))
        self.zero = np.zeros(3)

    def configure_capabilities(self) -> None:
        self.controller.reset()  # new gains, or a restart: no stale integrator

    def compute(self) -> None:
        sensors, setpoint = self.inputs.wheel_sensors, self.inputs.velocity_setpoint
        if sensors.seq == 0:
            return  # no process data yet: nothing to control
        stop = self.flags["stop"] or not setpoint.valid  # a stale setpoint is no setpoint
        commands, velocity = self.outputs.wheel_commands, self.outputs.platform_velocity
        self.controller.step(self.zero if stop else setpoint.value, sensors.value, commands.value, velocity.value,
                             stop=stop)
        commands.publish()
        velocity.publish()

    def pausing(self) -> None:
        self._safe()

    def clean(self) -> None:
        self._safe()

    def _safe(self) -> None:
        if hasattr(self, "controller"):
            self.controller.write_safe_commands(self.outputs.wheel_commands.value)
            self.outputs.wheel_commands.publish()
