"""The ropod platform velocity controller: platform twist setpoint in, wheel currents out.

Three platform controllers (x, y, theta) and eight wheel controllers, each the generic
gain / PI / lead-lag / low-pass chain at 1 kHz, with the thesis's Appendix D values
(``hapticop.devices.ropod``, whose parameter sets these are).
"""

from __future__ import annotations

import dataclasses

import numpy as np
from pydantic import Field, field_validator

from hapticop.blocks.base import Block
from hapticop.blocks.bounds import Bounds
from hapticop.blocks.interface import Interface, Params, Port, RateRange
from hapticop.devices.ropod.controller_params import LinearControllerParams
from hapticop.devices.ropod.geometry import Geometry
from hapticop.devices.ropod.pdo import RXPDO_BYTES, TXPDO_BYTES
from hapticop.devices.ropod.velocity_controller import PlatformControllerParams, PlatformVelocityController

_LIBRARY = PlatformControllerParams()  # the defaults, written once in the library


SETPOINT_RANGE = (-10.0, 10.0)  # m/s and rad/s: refused beyond (not clipped); max_velocity clips what is inside


class RopodControllerParams(Params):
    """The parameters of ``PlatformControllerParams`` a composition tunes, under the library's names."""

    platform_xy: LinearControllerParams = Field(_LIBRARY.platform_xy, description="the x and y platform controllers")
    platform_theta: LinearControllerParams = Field(_LIBRARY.platform_theta, description="the yaw platform controller")
    wheel: LinearControllerParams = Field(_LIBRARY.wheel, description="the eight damping wheel controllers")
    geometry: Geometry = _LIBRARY.geometry
    torque_constant_nm_per_a: float = Field(_LIBRARY.torque_constant_nm_per_a, gt=0,
                                            description="motor torque per ampere")
    current_limit_a: float = Field(_LIBRARY.current_limit_a, gt=0, description="per-motor current limit")
    hold_below: float | None = Field(
        _LIBRARY.hold_below, gt=0, description="standstill hold: with a zero setpoint and the measured twist "
        "below this (m/s, rad/s), the platform integrators stay at zero, so braking's wind-up cannot drive "
        "the stopped robot back; null: the plain PI")
    max_velocity: tuple[float, float, float] = Field(
        _LIBRARY.max_velocity, description="the robot's own limits on what it executes, whatever the setpoint: "
        "|vx|, |vy| (m/s) and |wz| (rad/s)")
    max_acceleration: tuple[float, float, float] | None = Field(
        _LIBRARY.max_acceleration, description="the robot's own limits on how fast the executed setpoint "
        "changes: m/s², m/s², rad/s² (null: a step is followed at once)")
    pivot_offsets_rad: tuple[float, ...] = Field(
        _LIBRARY.pivot_offsets_rad,
        description="pivot encoder offsets, SW1 first: a unit's angle is its reading minus its offset")


    @field_validator("max_velocity", "max_acceleration")
    @classmethod
    def _positive(cls, limits: tuple[float, float, float] | None) -> tuple[float, float, float] | None:
        if limits is not None and min(limits) <= 0:
            raise ValueError(f"every limit must be above zero, not {list(limits)}")
        return limits


class RopodController(Block):
    Params = RopodControllerParams
    running_params = frozenset({"platform_xy", "platform_theta", "wheel"})  # gains retune bumplessly

    @classmethod
    def interface(cls, params: RopodControllerParams) -> Interface:
        wheels = len(params.geometry.pivots_m)
        return Interface(
            inputs={
                "velocity_setpoint": Port("float64", (3,), "m/s, m/s, rad/s", "platform twist [vx, vy, wz]",
                                          range=SETPOINT_RANGE),
                "wheel_sensors": Port("uint8", (wheels, TXPDO_BYTES), "1", "TxPDO image per wheel"),
            },
            outputs={
                "wheel_commands": Port("uint8", (wheels, RXPDO_BYTES), "1", "RxPDO image per wheel"),
                "platform_velocity": Port("float64", (3,), "m/s, m/s, rad/s", "measured platform twist"),
            },
            flags_read={"stop": "hold zero velocity (a wheel is not operational)"},
            rate=RateRange(1000.0, 1000.0, "the discretised controllers are tuned for Ts = 1 ms"),
        )

    def configure_resources(self) -> None:
        self.controller = PlatformVelocityController(self._controller_params())
        self.zero = np.zeros(3)
        self.stopped = False  # what the stop flag last said, so each change is logged once
        self.bounds = Bounds(self.interface(self.params).inputs["velocity_setpoint"], f"{self.name}.velocity_setpoint")
        self.setpoint_seq = -1
        self.setpoint_good = False

    def configure_capabilities(self) -> None:
        """A (re)start: no stale integrator."""
        params = self._controller_params()
        if params != self.controller.params:
            self.controller = PlatformVelocityController(params)
        else:
            self.controller.reset()

    def retune(self, changed: frozenset[str]) -> None:
        """New gains while driving: the controllers keep their states, so the wheels see no jump."""
        self.controller.retune(self._controller_params())

    def compute(self) -> None:
        sensors, setpoint = self.inputs.wheel_sensors, self.inputs.velocity_setpoint
        if sensors.seq == 0:
            return  # no process data yet: nothing to control
        if self.flags["stop"] != self.stopped:
            self.stopped = self.flags["stop"]
            if self.stopped:
                self.log.info("stop raised: holding the platform at zero velocity")
            else:
                self.log.info("stop lowered: following the setpoint again")
        if setpoint.seq != self.setpoint_seq:  # each new sample checked once: a bad one is no setpoint
            self.setpoint_seq = setpoint.seq
            self.setpoint_good = self.bounds.admits(setpoint.value)
            self.bounds.said(self.log, self.setpoint_good)
        stop = self.stopped or not setpoint.valid or not self.setpoint_good  # a stale or bad setpoint is none
        commands, velocity = self.outputs.wheel_commands, self.outputs.platform_velocity
        self.controller.step(self.zero if stop else setpoint.value, sensors.value, commands.value, velocity.value,
                             stop=stop)
        commands.publish()
        velocity.publish()

    def pausing(self) -> None:
        self._safe()

    def clean(self) -> None:
        self._safe()

    def _controller_params(self) -> PlatformControllerParams:
        """The library's parameters with the composition's values."""
        p = self.params
        return dataclasses.replace(_LIBRARY, **{name: getattr(p, name) for name in type(p).model_fields})

    def _safe(self) -> None:
        if hasattr(self, "controller"):
            self.controller.write_safe_commands(self.outputs.wheel_commands.value)
            self.outputs.wheel_commands.publish()
