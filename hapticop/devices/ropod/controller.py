"""The ropod platform velocity controller: one 1 kHz cycle from sensor image to command image.

The "kinematic controller with torque distribution" of the thesis (§5.1, §7.3), in the
order of ropod-controller.md §7: read the smart wheels, condition the setpoint, estimate
the twist (forward kinematics), three platform controllers -> wrench, distribute it over
the wheels, add the eight damping wheel controllers on the inverse-kinematics speed error,
convert torque to current and write the drive commands. The platform loop tracks; the wheel
loop only damps, and its torque is added after the distribution, not fed through it.

The two controller stages take independent inputs, so their 3 + 8 channels run as one
11-channel bank. All state and scratch is allocated here once; `step` allocates nothing.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal

import numpy as np
from numpy.typing import NDArray

from hapticop.devices.ropod.controllers import (
    THESIS_PLATFORM_THETA, THESIS_PLATFORM_XY, THESIS_WHEEL, ControllerBank, LinearControllerParams,
)
from hapticop.devices.ropod.kinematics import Geometry, SmartWheelKinematics, distribute_qp
from hapticop.devices.ropod.pdo import Com1, Stat1, rxpdo_view, txpdo_view

__all__ = ["PlatformControllerParams", "PlatformVelocityController", "THESIS_PIVOT_OFFSETS_RAD"]

F64 = NDArray[np.float64]

THESIS_PIVOT_OFFSETS_RAD = (4.691878, 3.224157, 0.028178, 5.856820)


@dataclass(frozen=True)
class PlatformControllerParams:
    """Controller configuration; defaults are the thesis's (Appendix D, §7.3) on the ropod's geometry."""

    platform_xy: LinearControllerParams = THESIS_PLATFORM_XY
    platform_theta: LinearControllerParams = THESIS_PLATFORM_THETA
    wheel: LinearControllerParams = THESIS_WHEEL
    geometry: Geometry = field(default_factory=Geometry)
    ts_s: float = 0.001
    torque_constant_nm_per_a: float = 0.28
    # Per-motor current limit: written to the limit fields (as the ropod did) and, unless
    # `clip_current` is off, also enforced here (in TORQUE mode the drive may not enforce it).
    current_limit_a: float = 10.0
    clip_current: bool = True
    # +- value written to limit1/2_p/n. None: current_limit_a, as the ropod did (§2.3), although the
    # drive documentation calls these velocity bounds in TORQUE mode (others write 0: "unused").
    command_limits: float | None = None
    # Per-wheel torque bound of the distribution; None means current_limit_a * Kt (2.8 Nm).
    tau_max_nm: float | None = None
    pivot_offsets_rad: tuple[float, ...] = THESIS_PIVOT_OFFSETS_RAD
    units_enabled: tuple[bool, ...] = (True, True, True, True)
    # Setpoint conditioning (§7 step 2): per-axis clip, and an optional per-axis rate limit.
    max_velocity: tuple[float, float, float] | None = (2.0, 2.0, 1.6)
    max_acceleration: tuple[float, float, float] | None = None
    distribution: Literal["pinv", "qp"] = "pinv"  # "qp" allocates every cycle
    flip_kmax: float = 1.0  # 1 = normal mode: flip compensation is the identity
    flip_force_threshold_n: float = 10.0
    use_timestamp: bool = False  # sets COM1 USE_TS; the caller then passes timestamp_ns
    # A unit takes part while its status has all `required_status` bits and none of `fault_status`.
    required_status: int = int(Stat1.ENCODERS_OK)
    fault_status: int = int(Stat1.FAULTS)

    @property
    def tau_max(self) -> float:
        return self.current_limit_a * self.torque_constant_nm_per_a if self.tau_max_nm is None else self.tau_max_nm


class PlatformVelocityController:
    """Platform twist setpoint in, smart-wheel current commands out, at a fixed 1 kHz period.

    `step(v_sp, tx_image, rx_image_out, out_platform_velocity, stop=False)` runs one cycle on
    the raw process-data images. `update(v_sp, delta, phidot, unit_enable, stop)` is the same
    cycle on decoded model quantities (no PDO), for tests and other transports. The last
    cycle's intermediate values stay readable as attributes (wrench, tau_dist, tau_wheel,
    tau, current, current_hw, scale, operational).

    `stop` holds a zero velocity setpoint: the platform is braked actively and held, the
    drives stay enabled. With fewer than two healthy units, or after `disable()`, the
    controller writes safe commands instead: drives disabled, zero currents, integrators reset.
    """

    def __init__(self, params: PlatformControllerParams = PlatformControllerParams()):
        self.params = p = params
        units, wheels = p.geometry.units, p.geometry.wheels
        if len(p.pivot_offsets_rad) != units or len(p.units_enabled) != units:
            raise ValueError("pivot_offsets_rad and units_enabled need one entry per unit")
        self.units, self.wheels = units, wheels
        self.kinematics = SmartWheelKinematics(p.geometry)
        self.bank = ControllerBank(
            LinearControllerParams.stack([p.platform_xy, p.platform_xy, p.platform_theta] + [p.wheel] * wheels),
            p.ts_s,
        )
        self._tau_max = p.tau_max
        self._inv_kt = 1.0 / p.torque_constant_nm_per_a
        self._ilim, self._neg_ilim = np.float64(p.current_limit_a), np.float64(-p.current_limit_a)
        self._limit_fields = p.current_limit_a if p.command_limits is None else p.command_limits
        # The per-unit clip is a no-op after the uniformly scaled pseudo-inverse in normal mode.
        self._needs_unit_clip = p.distribution != "pinv" or p.flip_kmax != 1.0
        self._offsets = np.array(p.pivot_offsets_rad, np.float64)
        self._configured = np.array(p.units_enabled, np.float64)
        self._vmax = None if p.max_velocity is None else np.array(p.max_velocity, np.float64)
        self._neg_vmax = None if self._vmax is None else -self._vmax
        self._dvmax = None if p.max_acceleration is None else np.array(p.max_acceleration, np.float64) * p.ts_s
        self._neg_dvmax = None if self._dvmax is None else -self._dvmax
        self._required = np.uint16(p.required_status)
        self._faults = np.uint16(p.fault_status)
        self._command = np.uint16(Com1.ENABLE1 | Com1.ENABLE2 | Com1.MODE_TORQUE
                                  | (Com1.USE_TS if p.use_timestamp else 0))
        # Decoded sensors.
        self.delta = np.zeros(units)
        self.phidot = np.zeros(wheels)
        self.unit_enable = np.zeros(units)
        self._healthy = np.zeros(units, bool)
        self._ok = np.zeros(units, bool)
        self._status = np.zeros(units, np.uint16)
        # Cycle values.
        self.v_sp = np.zeros(3)  # conditioned setpoint
        self.v_meas = np.zeros(3)
        self.wheel_speed_sp = np.zeros(wheels)
        self._err = np.zeros(3 + wheels)
        self._y = np.zeros(3 + wheels)
        self._reset = np.zeros(3 + wheels, bool)
        self.wrench = self._y[:3]
        self.tau_wheel = self._y[3:]
        self.tau_dist = np.zeros(wheels)
        self.tau = np.zeros(wheels)
        self.current = np.zeros(wheels)  # model convention [A]
        self.current_hw = np.zeros(wheels)  # as sent: wheel 2 of each unit negated
        self._hw_sign = np.tile([1.0, -1.0], units)
        self.scale = 1.0
        self.operational = False
        self._enabled = True
        self._dv = np.zeros(3)
        self._mask8 = self.kinematics.mask
        self._tx_src: np.ndarray | None = None
        self._rx_src: np.ndarray | None = None

    # --- life cycle ---------------------------------------------------------------------
    def reset(self) -> None:
        """Controller states and the setpoint history to zero (start of running)."""
        self.bank.reset()
        self.v_sp.fill(0.0)

    def enable(self) -> None:
        self._enabled = True

    def disable(self) -> None:
        """From the next cycle on, write safe commands (drives off) until `enable()`."""
        self._enabled = False

    # --- the cycle ----------------------------------------------------------------------
    def step(self, velocity_setpoint: F64, tx_image: NDArray[np.uint8], rx_image_out: NDArray[np.uint8],
             out_platform_velocity: F64, stop: bool = False, timestamp_ns: int = 0) -> None:
        """One cycle on the process-data images: read sensors, control, write commands.

        `out_platform_velocity` receives the measured twist (forward kinematics), [m/s, m/s, rad/s].
        The field views of an image are built when a new image object is first seen: pass the same
        arrays every cycle.
        """
        if tx_image is not self._tx_src:
            self._bind_tx(tx_image)
        if rx_image_out is not self._rx_src:
            self._bind_rx(rx_image_out)
        self._read_sensors()
        self.update(velocity_setpoint, self.delta, self.phidot, self.unit_enable, stop)
        np.copyto(out_platform_velocity, self.v_meas)
        self._write_commands(timestamp_ns)

    def update(self, velocity_setpoint: F64, delta: F64, phidot: F64, unit_enable: F64, stop: bool = False) -> None:
        """The cycle on model quantities: pivot angles [rad], model wheel speeds [rad/s], 0/1 per unit.

        Units also need `params.units_enabled`; the drives of the units taking part get enable bits.
        """
        kin, mask8 = self.kinematics, self._mask8
        unit_enable = np.multiply(unit_enable, self._configured, out=self.unit_enable)
        np.greater(unit_enable, 0.0, out=self._healthy)  # these drives get enable bits
        self.operational = self._enabled and float(unit_enable.sum()) >= 2.0
        if not self.operational:
            self._safe_outputs()
            return
        self._condition(velocity_setpoint, stop)
        kin.update(delta, unit_enable)
        kin.twist(phidot, out=self.v_meas)
        err = self._err
        np.subtract(self.v_sp, self.v_meas, out=err[:3])
        kin.wheel_speeds(self.v_sp, out=self.wheel_speed_sp)
        np.subtract(self.wheel_speed_sp, phidot, out=err[3:])
        err[3:] *= mask8
        self.bank.step(err, self._y, self._reset)
        self._distribute()
        np.add(self.tau_dist, self.tau_wheel, out=self.tau)
        self.tau *= mask8
        np.multiply(self.tau, self._inv_kt, out=self.current)
        np.multiply(self.current, self._hw_sign, out=self.current_hw)  # the drive's wheel 2 turns the other way
        if self.params.clip_current:
            np.minimum(self.current_hw, self._ilim, out=self.current_hw)
            np.maximum(self.current_hw, self._neg_ilim, out=self.current_hw)

    def write_safe_commands(self, rx_image_out: NDArray[np.uint8]) -> None:
        """Drives disabled, zero current setpoints (for pausing and cleaning up)."""
        if rx_image_out is not self._rx_src:
            self._bind_rx(rx_image_out)
        self._healthy.fill(False)
        self.current_hw.fill(0.0)
        self._write_commands(0)

    # --- pieces ---------------------------------------------------------------------------
    def _condition(self, velocity_setpoint: F64, stop: bool) -> None:
        v = self.v_sp
        if self._dvmax is None:
            if stop:
                v.fill(0.0)
            else:
                np.copyto(v, velocity_setpoint)
            if self._vmax is not None:
                np.minimum(v, self._vmax, out=v)
                np.maximum(v, self._neg_vmax, out=v)
            return
        dv = self._dv
        if stop:
            dv.fill(0.0)
        else:
            np.copyto(dv, velocity_setpoint)
        if self._vmax is not None:
            np.minimum(dv, self._vmax, out=dv)
            np.maximum(dv, self._neg_vmax, out=dv)
        dv -= v
        np.minimum(dv, self._dvmax, out=dv)
        np.maximum(dv, self._neg_dvmax, out=dv)
        v += dv

    def _distribute(self) -> None:
        kin, p = self.kinematics, self.params
        if p.distribution == "qp":
            tau, self.scale = distribute_qp(kin.G, self.wrench, self.unit_enable, self._tau_max)
            np.copyto(self.tau_dist, tau)
        else:
            self.scale = kin.distribute(self.wrench, self._tau_max, out=self.tau_dist)
        if self._needs_unit_clip:
            kin.flip_compensate(self.tau_dist, p.flip_kmax, p.flip_force_threshold_n)
            kin.clip_per_unit(self.tau_dist, self._tau_max)

    def _safe_outputs(self) -> None:
        self.bank.reset()
        self.v_sp.fill(0.0)
        self.v_meas.fill(0.0)
        for a in (self._y, self.tau_dist, self.tau, self.current, self.current_hw):
            a.fill(0.0)
        self._healthy.fill(False)

    def _bind_tx(self, image: NDArray[np.uint8]) -> None:
        rec = txpdo_view(image)
        if rec.shape[0] != self.units:
            raise ValueError(f"sensor image has {rec.shape[0]} wheels, controller has {self.units}")
        self._tx_src = image
        self._tx = (rec["status1"], rec["encoder_pivot"], rec["velocity_1"], rec["velocity_2"])

    def _bind_rx(self, image: NDArray[np.uint8]) -> None:
        rec = rxpdo_view(image)
        if rec.shape[0] != self.units:
            raise ValueError(f"command image has {rec.shape[0]} wheels, controller has {self.units}")
        self._rx_src = image
        self._rx = tuple(rec[name] for name in ("command1", "command2", "setpoint1", "setpoint2",
                                                "limit1_p", "limit1_n", "limit2_p", "limit2_n", "timestamp"))

    def _read_sensors(self) -> None:
        status, pivot, vel1, vel2 = self._tx
        healthy, ok, tmp = self._healthy, self._ok, self._status
        np.bitwise_and(status, self._required, out=tmp)
        np.equal(tmp, self._required, out=healthy)
        np.bitwise_and(status, self._faults, out=tmp)
        np.equal(tmp, 0, out=ok)
        healthy &= ok
        np.copyto(self.unit_enable, healthy)
        np.subtract(pivot, self._offsets, out=self.delta)  # no re-wrapping: only sin/cos are used
        np.copyto(self.phidot[0::2], vel1)
        np.negative(vel2, out=self.phidot[1::2])  # model wheel 2 = -velocity_2

    def _write_commands(self, timestamp_ns: int) -> None:
        cmd1, cmd2, sp1, sp2, l1p, l1n, l2p, l2n, ts = self._rx
        lim = self._limit_fields
        cmd1.fill(0)
        np.copyto(cmd1, self._command, where=self._healthy)
        cmd2.fill(0)
        np.copyto(sp1, self.current_hw[0::2])
        np.copyto(sp2, self.current_hw[1::2])
        l1p.fill(lim)
        l1n.fill(-lim)
        l2p.fill(lim)
        l2n.fill(-lim)
        ts.fill(timestamp_ns)
