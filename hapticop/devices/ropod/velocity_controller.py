"""The ropod platform velocity controller: one 1 kHz cycle from sensor image to command image.

The "kinematic controller with torque distribution" of the thesis (§5.1, §7.3), in the
order of docs/devices/ropod.md §7: read the smart wheels, condition the setpoint, estimate
the twist (forward kinematics), three platform controllers -> wrench, distribute it over
the wheels, add the eight damping wheel controllers on the inverse-kinematics speed error,
convert torque to current and write the drive commands. The platform loop tracks; the wheel
loop only damps, and its torque is added after the distribution, not fed through it.

The two controller stages take independent inputs, so their 3 + 8 channels run as one
11-channel bank. A cycle is a few hundred multiplications, so it runs on Python floats in
lists allocated here once (numpy's per-call overhead would cost more than the arithmetic);
the images are read and written with precompiled structs. `step` allocates nothing that stays.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from typing import Literal

import numpy as np
from numpy.typing import NDArray

from hapticop.devices.ropod.controller_params import (
    THESIS_PLATFORM_THETA,
    THESIS_PLATFORM_XY,
    THESIS_WHEEL,
    LinearControllerParams,
)
from hapticop.devices.ropod.geometry import Geometry
from hapticop.devices.ropod.kinematics import SmartWheelKinematics, distribute_qp
from hapticop.devices.ropod.linear_bank import ControllerBank
from hapticop.devices.ropod.pdo import (
    RXPDO_BYTES,
    RXPDO_DTYPE,
    TXPDO_DTYPE,
    Com1,
    Stat1,
    record_struct,
    rxpdo_view,
    txpdo_view,
)

__all__ = ["PlatformControllerParams", "PlatformVelocityController", "THESIS_PIVOT_OFFSETS_RAD"]

F64 = NDArray[np.float64]

THESIS_PIVOT_OFFSETS_RAD = (4.691878, 3.224157, 0.028178, 5.856820)

# What the controller reads of each wheel's sensors (in offset order), and its whole command record.
_SENSORS = record_struct(TXPDO_DTYPE, ("status1", "velocity_1", "velocity_2", "encoder_pivot"))
_COMMANDS = record_struct(RXPDO_DTYPE, RXPDO_DTYPE.names)


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
    # Standstill hold: with a zero setpoint and the measured translation and turn slower than this
    # (m/s, rad/s), the platform integrators are held at zero. Braking winds them up against the motion;
    # kept at a standstill, that wind-up drives the robot backwards until it has integrated away
    # (the hallway run drifted 4 cm at up to 2.8 cm/s after stopping). None: the thesis's plain PI.
    hold_below: float | None = None
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
    cycle's values stay readable as attributes: `scale` and `operational`, and as arrays made
    on access v_sp, v_meas, delta, phidot, unit_enable, wheel_speed_sp, wrench, tau_dist,
    tau_wheel, tau, current and current_hw.

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
            [p.platform_xy, p.platform_xy, p.platform_theta] + [p.wheel] * wheels,
            p.ts_s,
        )
        self._tau_max = p.tau_max
        self._inv_kt = 1.0 / p.torque_constant_nm_per_a
        self._ilim = float(p.current_limit_a) if p.clip_current else math.inf
        self._limit_fields = float(p.current_limit_a if p.command_limits is None else p.command_limits)
        # The per-unit clip is a no-op after the uniformly scaled pseudo-inverse in normal mode.
        self._needs_unit_clip = p.distribution != "pinv" or p.flip_kmax != 1.0
        self._qp = p.distribution == "qp"
        self._offsets = tuple(float(o) for o in p.pivot_offsets_rad)
        self._configured = tuple(1.0 if e else 0.0 for e in p.units_enabled)
        self._vmax = None if p.max_velocity is None else tuple(float(v) for v in p.max_velocity)
        self._dvmax = None if p.max_acceleration is None else tuple(float(a) * p.ts_s for a in p.max_acceleration)
        self._hold_below = p.hold_below
        self._hold_reset = (True, True, True) + (False,) * wheels  # the platform channels only
        self._required = int(p.required_status)
        self._faults = int(p.fault_status)
        self._command = int(Com1.ENABLE1 | Com1.ENABLE2 | Com1.MODE_TORQUE | (Com1.USE_TS if p.use_timestamp else 0))
        # Decoded sensors.
        self._delta = [0.0] * units
        self._phidot = [0.0] * wheels
        self._enable = [0.0] * units
        self._healthy = [False] * units  # these drives get enable bits
        # Cycle values: setpoint (conditioned), measured twist, wheel speed setpoints, the bank's
        # errors and outputs (3 platform channels, then the wheels), torques and currents.
        self._v_sp = [0.0] * 3
        self._v_meas = (0.0, 0.0, 0.0)
        self._ws_sp = [0.0] * wheels
        self._err = [0.0] * (3 + wheels)
        self._y = [0.0] * (3 + wheels)
        self._tau_dist = [0.0] * wheels
        self._tau = [0.0] * wheels
        self._current_hw = [0.0] * wheels  # as sent: wheel 2 of each unit negated
        self.scale = 1.0
        self.operational = False
        self._enabled = True
        self._tx_src: np.ndarray | None = None
        self._rx_src: np.ndarray | None = None

    # --- the last cycle's values, as arrays (diagnostics and tests) ---------------------------
    v_sp = property(lambda self: np.array(self._v_sp), doc="conditioned setpoint")
    v_meas = property(lambda self: np.array(self._v_meas), doc="measured twist (forward kinematics)")
    delta = property(lambda self: np.array(self._delta), doc="pivot angles [rad]")
    phidot = property(lambda self: np.array(self._phidot), doc="model wheel speeds [rad/s]")
    unit_enable = property(lambda self: np.array(self._enable), doc="0/1 per unit taking part")
    wheel_speed_sp = property(lambda self: np.array(self._ws_sp), doc="wheel speeds of the setpoint [rad/s]")
    wrench = property(lambda self: np.array(self._y[:3]), doc="platform controllers' wrench [N, N, Nm]")
    tau_wheel = property(lambda self: np.array(self._y[3:]), doc="wheel controllers' torques [Nm]")
    tau_dist = property(lambda self: np.array(self._tau_dist), doc="distributed wrench [Nm]")
    tau = property(lambda self: np.array(self._tau), doc="total wheel torques [Nm]")
    current = property(lambda self: np.array(self._tau) * self._inv_kt, doc="motor currents, model convention [A]")
    current_hw = property(lambda self: np.array(self._current_hw), doc="current setpoints as sent [A]")

    # --- life cycle ---------------------------------------------------------------------
    def reset(self) -> None:
        """Controller states and the setpoint history to zero (start of running)."""
        self.bank.reset()
        _zero(self._v_sp)

    def retune(self, params: PlatformControllerParams) -> None:
        """New platform and wheel controller gains from the next cycle on, states kept (bumpless).
        Anything else in `params` (geometry, limits, distribution) needs a new controller."""
        unchanged = dataclasses.replace(params, platform_xy=self.params.platform_xy,
                                        platform_theta=self.params.platform_theta, wheel=self.params.wheel)
        if unchanged != self.params:
            raise ValueError("only the platform and wheel controller gains retune; build a new controller")
        self.bank.retune([params.platform_xy, params.platform_xy, params.platform_theta] + [params.wheel] * self.wheels)
        self.params = params

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
        The images are checked when a new image object is first seen: pass the same arrays every cycle.
        """
        if tx_image is not self._tx_src:
            self._bind_tx(tx_image)
        if rx_image_out is not self._rx_src:
            self._bind_rx(rx_image_out)
        self._read_sensors()
        vx, vy, wz = velocity_setpoint.tolist()
        self._cycle(vx, vy, wz, stop)
        out_platform_velocity[0], out_platform_velocity[1], out_platform_velocity[2] = self._v_meas
        self._write_commands(timestamp_ns)

    def update(self, velocity_setpoint: F64, delta: F64, phidot: F64, unit_enable: F64, stop: bool = False) -> None:
        """The cycle on model quantities: pivot angles [rad], model wheel speeds [rad/s], 0/1 per unit.

        Units also need `params.units_enabled`; the drives of the units taking part get enable bits.
        """
        sizes = {"velocity_setpoint": 3, "delta": self.units, "phidot": self.wheels, "unit_enable": self.units}
        arrays = {name: np.asarray(value, np.float64) for name, value in
                  zip(sizes, (velocity_setpoint, delta, phidot, unit_enable))}
        for name, array in arrays.items():
            if array.shape != (sizes[name],):
                raise ValueError(f"{name} needs {sizes[name]} values, got shape {array.shape}")
        self._delta[:] = arrays["delta"].tolist()
        self._phidot[:] = arrays["phidot"].tolist()
        for i, (e, configured) in enumerate(zip(arrays["unit_enable"].tolist(), self._configured)):
            self._enable[i] = e * configured
            self._healthy[i] = e * configured > 0.0
        vx, vy, wz = arrays["velocity_setpoint"].tolist()
        self._cycle(vx, vy, wz, stop)

    def write_safe_commands(self, rx_image_out: NDArray[np.uint8]) -> None:
        """Drives disabled, zero current setpoints (for pausing and cleaning up)."""
        if rx_image_out is not self._rx_src:
            self._bind_rx(rx_image_out)
        _zero(self._healthy, False)
        _zero(self._current_hw)
        self._write_commands(0)

    # --- pieces ---------------------------------------------------------------------------
    def _cycle(self, vx: float, vy: float, wz: float, stop: bool) -> None:
        """§7 steps 2-8 on the decoded sensors (`_delta`, `_phidot`, `_enable`, `_healthy`)."""
        enable = self._enable
        self.operational = self._enabled and sum(enable) >= 2.0
        if not self.operational:
            self._safe_outputs()
            return
        v_sp = self._condition(vx, vy, wz, stop)
        kin, phidot, err, y = self.kinematics, self._phidot, self._err, self._y
        kin.evaluate(self._delta, enable)
        mx, my, mw = self._v_meas = kin.twist_of(phidot)
        sx, sy, sw = v_sp
        err[0], err[1], err[2] = sx - mx, sy - my, sw - mw
        ws_sp = self._ws_sp
        kin.wheel_speeds_into(sx, sy, sw, ws_sp)
        mask = kin.unit_mask
        for i, m in enumerate(mask):  # the wheel loop damps the inverse-kinematics speed error
            j = 2 * i
            err[3 + j] = (ws_sp[j] - phidot[j]) * m
            err[4 + j] = (ws_sp[j + 1] - phidot[j + 1]) * m
        hold = self._hold_below
        if hold is not None and sx == 0.0 and sy == 0.0 and sw == 0.0 and abs(mx) < hold and abs(my) < hold \
                and abs(mw) < hold:
            self.bank.step_values(err, y, self._hold_reset)
        else:
            self.bank.step_values(err, y)
        self._distribute()
        inv_kt, ilim = self._inv_kt, self._ilim
        tau_dist, tau, current_hw = self._tau_dist, self._tau, self._current_hw
        for i, m in enumerate(mask):
            j = 2 * i
            t1, t2 = (tau_dist[j] + y[3 + j]) * m, (tau_dist[j + 1] + y[4 + j]) * m
            tau[j], tau[j + 1] = t1, t2
            i1, i2 = t1 * inv_kt, -(t2 * inv_kt)  # the drive's wheel 2 turns the other way
            current_hw[j] = ilim if i1 > ilim else -ilim if i1 < -ilim else i1
            current_hw[j + 1] = ilim if i2 > ilim else -ilim if i2 < -ilim else i2

    def _condition(self, vx: float, vy: float, wz: float, stop: bool) -> list[float]:
        """§7 step 2: the setpoint clipped per axis and, optionally, rate limited; zero while stopping.
        A NaN is zero (infinity is clipped): nothing the setpoint holds makes the robot exceed its limits."""
        v, vmax, dvmax = self._v_sp, self._vmax, self._dvmax
        for axis, wanted in enumerate((0.0, 0.0, 0.0) if stop else (vx, vy, wz)):
            if wanted != wanted:  # NaN passes every clip below: no setpoint on that axis
                wanted = 0.0
            if vmax is not None:
                limit = vmax[axis]
                wanted = limit if wanted > limit else -limit if wanted < -limit else wanted
            if dvmax is not None:
                limit, previous = dvmax[axis], v[axis]
                change = wanted - previous
                change = limit if change > limit else -limit if change < -limit else change
                wanted = previous + change
            v[axis] = wanted
        return v

    def _distribute(self) -> None:
        kin, y, tau = self.kinematics, self._y, self._tau_dist
        if self._qp:
            result, self.scale = distribute_qp(kin.G, np.array(y[:3]), np.array(self._enable), self._tau_max)
            tau[:] = result.tolist()
        else:
            self.scale = kin.distribute_into(y[0], y[1], y[2], self._tau_max, tau)
        if self._needs_unit_clip:
            p = self.params
            kin.flip_compensate_list(tau, p.flip_kmax, p.flip_force_threshold_n)
            kin.clip_per_unit_list(tau, self._tau_max)

    def _safe_outputs(self) -> None:
        self.bank.reset()
        self._v_meas = (0.0, 0.0, 0.0)
        for values in (self._v_sp, self._y, self._tau_dist, self._tau, self._current_hw):
            _zero(values)
        _zero(self._healthy, False)

    def _bind_tx(self, image: NDArray[np.uint8]) -> None:
        rec = txpdo_view(image)
        if rec.shape[0] != self.units:
            raise ValueError(f"sensor image has {rec.shape[0]} wheels, controller has {self.units}")
        self._tx_src = image

    def _bind_rx(self, image: NDArray[np.uint8]) -> None:
        rec = rxpdo_view(image)
        if rec.shape[0] != self.units:
            raise ValueError(f"command image has {rec.shape[0]} wheels, controller has {self.units}")
        self._rx_src = image

    def _read_sensors(self) -> None:
        """§7 step 1: a unit takes part while healthy and configured; pivot angles without the encoder
        offsets (no re-wrapping: only sin/cos are used); model wheel 2 = -velocity_2."""
        required, faults = self._required, self._faults
        delta, phidot, enable, healthy = self._delta, self._phidot, self._enable, self._healthy
        for i, ((status, vel1, vel2, pivot), offset, configured) in enumerate(
                zip(_SENSORS.iter_unpack(self._tx_src), self._offsets, self._configured)):
            ok = status & required == required and not status & faults
            enable[i] = configured if ok else 0.0
            healthy[i] = ok and configured > 0.0
            delta[i] = pivot - offset
            phidot[2 * i] = vel1
            phidot[2 * i + 1] = -vel2

    def _write_commands(self, timestamp_ns: int) -> None:
        lim, command, current_hw, image, pack = self._limit_fields, self._command, self._current_hw, self._rx_src, \
            _COMMANDS.pack_into
        for i, healthy in enumerate(self._healthy):
            pack(image, i * RXPDO_BYTES, command if healthy else 0, 0, current_hw[2 * i], current_hw[2 * i + 1],
                 lim, -lim, lim, -lim, timestamp_ns)


def _zero(values: list, zero: float | bool = 0.0) -> None:
    for j in range(len(values)):
        values[j] = zero
