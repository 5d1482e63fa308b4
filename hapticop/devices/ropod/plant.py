"""A simulated ropod: rigid platform on four trailing-caster smart wheels, driven by wheel currents.

The model is docs/devices/ropod.md §8 "Level 1": the platform is a rigid body (36.5 kg, yaw
inertia I_z) and each smart-wheel unit adds its yaw inertia I_c about the pivot; the
wheels roll without slip and the axles do not skid sideways. A unit's yaw rate is then
tied to the platform twist (Omega_i = q_i/s), which makes the mass matrix depend on the
pivot angles, `M + sum (I_c/s^2) Q_i^T Q_i`: steering a caster across the direction of
motion costs real effort, as on the robot. With I_c = 0 it is Level 0, exactly the
controller's own model. Lateral tyre slip (Level 2, the candidate cause of the thesis's
0.8 m/s resonance) is not modelled.

The drives are modelled as ideal current sources: TORQUE mode applies the commanded
currents (clipped to the drive limit), VELOCITY mode runs a proportional speed loop inside
the current limits (the ropod's start-up spin); other modes, missing enable bits and the
emergency bits give zero current. The simulator reads the RxPDO image and writes the TxPDO
image exactly as a smart wheel would, including the hardware sign of wheel 2, the pivot
encoder offsets and wrapping, and the status bits. By default the sensors are sampled at
the start of each step, i.e. one sample old when the controller uses them (EtherCAT).
Deterministic: noise, if enabled, comes from the generator passed in.

The state is a few dozen numbers, so one step works on Python floats (numpy's per-call overhead
would cost more than the arithmetic) and publishes `state` once at its end; the images are
read and written with precompiled structs (`record_struct`). The equations of motion and their
RK4 step are `platform_dynamics`, compiled when the package is built with Cython.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from hapticop.devices.ropod.geometry import Geometry
from hapticop.devices.ropod.kinematics import SmartWheelKinematics
from hapticop.devices.ropod.pdo import (
    RXPDO_DTYPE,
    TXPDO_BYTES,
    TXPDO_DTYPE,
    Com1,
    Stat1,
    record_struct,
    rxpdo_view,
    txpdo_view,
)
from hapticop.devices.ropod.platform_dynamics import PlatformDynamics

__all__ = ["PlantParams", "RopodPlant"]

F64 = NDArray[np.float64]

_THESIS_OFFSETS = (4.691878, 3.224157, 0.028178, 5.856820)
_MODE_MASK = int(Com1.MODE_MASK)
_MODE_TORQUE = int(Com1.MODE_TORQUE)
_MODE_VELOCITY = int(Com1.MODE_VELOCITY)
_ENABLE1, _ENABLE1_BITS = int(Com1.ENABLE1), int(Com1.ENABLE1 | Com1.EMERGENCY1)
_ENABLE2, _ENABLE2_BITS = int(Com1.ENABLE2), int(Com1.ENABLE2 | Com1.EMERGENCY2)
_ENABLED1, _ENABLED2 = int(Stat1.ENABLED1), int(Stat1.ENABLED2)
_ENCODERS_OK = int(Stat1.ENCODERS_OK)
_TWO_PI = 2.0 * math.pi

# A wheel's whole command record, and the sensor fields the model has, in offset order; the
# unmodelled ones (d/u/v/w currents, motor voltages, accel_x/y, gyro_x/y) are written as zero.
_COMMANDS = record_struct(RXPDO_DTYPE, RXPDO_DTYPE.names)
_SENSORS = record_struct(TXPDO_DTYPE, (
    "status1", "status2", "sensor_ts", "setpoint_ts", "encoder_1", "velocity_1", "current_1_q", "temperature_1",
    "encoder_2", "velocity_2", "current_2_q", "temperature_2", "encoder_pivot", "velocity_pivot", "voltage_bus",
    "imu_ts", "accel_z", "gyro_z", "temperature_imu", "pressure"))


@dataclass(frozen=True)
class PlantParams:
    """Physical parameters; the inertias and losses are docs/devices/ropod.md's guesses (§8), not measurements."""

    geometry: Geometry = field(default_factory=Geometry)
    mass_kg: float = 36.5
    yaw_inertia_kgm2: float = 2.6  # platform I_z, m (a^2 + b^2)/12 with a = b = 0.65 m
    unit_yaw_inertia_kgm2: float = 0.011  # I_c per smart-wheel unit about its pivot; 0 = Level 0
    pivot_damping_nms: float = 0.0  # b_p, viscous friction of each pivot bearing
    linear_damping_ns_per_m: float = 2.0
    yaw_damping_nms: float = 0.5
    torque_constant_nm_per_a: float = 0.28
    drive_current_limit_a: float = 10.0
    drive_velocity_gain_a_per_rad_s: float = 0.5  # VELOCITY mode's speed loop
    pivot_offsets_rad: tuple[float, ...] = _THESIS_OFFSETS
    bus_voltage_v: float = 24.0
    motor_temperature_k: float = 300.0
    measurement_delay: int = 1  # 1: sensors sampled at the start of the step; 0: at its end
    substeps: int = 1  # RK4 steps per `step`; 1 kHz is ample without tyre slip
    wheel_velocity_noise_rad_s: float = 0.0
    pivot_noise_rad: float = 0.0
    initial_pose: tuple[float, float, float] = (0.0, 0.0, 0.0)
    initial_twist: tuple[float, float, float] = (0.0, 0.0, 0.0)
    initial_pivot_angles_rad: tuple[float, ...] = (0.0, 0.0, 0.0, 0.0)


class RopodPlant:
    """`step(rx_image, dt, tx_image_out)`: apply the commands for dt seconds, report the sensors.

    `pose` (x, y, theta in the world), `twist` (vx, vy, wz in the robot frame), `pivot_angles`
    and `wheel_angles` are views of `state`, published at the end of each step (change the state
    through `reset_state`); `wheel_speeds`, `pivot_rates`, `wheel_torques` and `currents_hw`
    are the last step's values (arrays made on access).
    """

    def __init__(self, params: PlantParams = PlantParams(), rng: np.random.Generator | None = None):
        self.params = p = params
        g = p.geometry
        units, wheels = g.units, g.wheels
        if p.measurement_delay not in (0, 1) or p.substeps < 1:
            raise ValueError("measurement_delay must be 0 or 1 and substeps >= 1")
        if len(p.pivot_offsets_rad) != units or len(p.initial_pivot_angles_rad) != units:
            raise ValueError("pivot offsets and initial pivot angles need one entry per unit")
        self.units, self.wheels = units, wheels
        self.rng = rng if rng is not None else np.random.default_rng(0)
        self.kinematics = SmartWheelKinematics(g)
        self._rows = self.kinematics.unit_rows
        self._offsets = tuple(float(o) for o in p.pivot_offsets_rad)
        self._inv_r, self._k = 1.0 / g.wheel_radius_m, g.k
        self._k_inv_r = g.k * self._inv_r
        self._inv_s = 1.0 / g.caster_offset_m
        self._body = PlatformDynamics(units, self._rows, self._inv_r, self._k, self._inv_s,
                                      p.unit_yaw_inertia_kgm2 / g.caster_offset_m**2, p.mass_kg,
                                      p.yaw_inertia_kgm2, p.pivot_damping_nms, p.linear_damping_ns_per_m,
                                      p.yaw_damping_nms)
        self._ilim = float(p.drive_current_limit_a)
        # State: pose (3), twist (3), pivot angles (units), wheel angles (wheels), model convention.
        # `_y` is the working copy, `state` the published one.
        size = 6 + units + wheels
        self.state = np.zeros(size)
        self.pose = self.state[0:3]
        self.twist = self.state[3:6]
        self.pivot_angles = self.state[6:6 + units]
        self.wheel_angles = self.state[6 + units:]
        self._y = [0.0] * size
        self.time_ns = 0
        self._setpoint_ns = 0
        # Drive model outputs (hardware convention for currents, model convention for torques) and
        # the measurement (model convention), per wheel / per unit.
        self._currents_hw = [0.0] * wheels
        self._torques = [0.0] * wheels
        self._torque_sum = self._body.torque_sum  # (t1 + t2) / r per unit: the wrench is sum A U_i + B Q_i
        self._torque_diff = self._body.torque_diff  # k (t2 - t1) / r
        self._speeds = [0.0] * wheels
        self._rates = [0.0] * units
        self._status = [_ENCODERS_OK] * units  # healthy, drives not yet enabled
        self._noise_w = np.zeros(wheels)
        self._noise_p = np.zeros(units)
        self._rx_src: np.ndarray | None = None
        self._tx_src: np.ndarray | None = None
        self.reset_state(p.initial_pose, p.initial_twist, p.initial_pivot_angles_rad)

    def reset_state(self, pose=(0.0, 0.0, 0.0), twist=(0.0, 0.0, 0.0), pivot_angles=None) -> None:
        """Put the robot somewhere, moving at a twist, with the casters at given angles (set-up only)."""
        self.state.fill(0.0)
        self.pose[:] = pose
        self.twist[:] = twist
        if pivot_angles is not None:
            self.pivot_angles[:] = pivot_angles
        self._y[:] = self.state.tolist()
        self._measure()

    @property
    def external(self) -> list[float]:
        """The external force and torque on the platform (N, N, N m in its frame), held over a step: what
        the world's contacts push back with (a box being pushed, a wall). Set its three items in place."""
        return self._body.external

    # --- read-outs of the last step -------------------------------------------------------
    wheel_speeds = property(lambda self: np.array(self._speeds), doc="wheel speeds [rad/s]")
    pivot_rates = property(lambda self: np.array(self._rates), doc="pivot rates [rad/s]")
    wheel_torques = property(lambda self: np.array(self._torques), doc="wheel torques [Nm]")
    currents_hw = property(lambda self: np.array(self._currents_hw), doc="as the drive reports them (wheel 2 negated)")

    # --- the step ------------------------------------------------------------------------
    def step(self, rx_image: NDArray[np.uint8], dt: float, tx_image_out: NDArray[np.uint8]) -> None:
        """Read the commands, run the drives and the body for dt seconds, write the sensors."""
        if rx_image is not self._rx_src:
            self._bind_rx(rx_image)
        if tx_image_out is not self._tx_src:
            self._bind_tx(tx_image_out)
        self._setpoint_ns = self.time_ns
        self._drives()
        delayed = self.params.measurement_delay
        if delayed:
            self._write_sensors()
        substeps = self.params.substeps
        h = dt / substeps
        for _ in range(substeps):
            self._body.rk4(self._y, h)
        self.state[:] = self._y
        self.time_ns += int(round(dt * 1e9))
        self._measure()
        if not delayed:
            self._write_sensors()

    def write_sensors(self, tx_image_out: NDArray[np.uint8]) -> None:
        """Report the current state without stepping (to fill the image before the first cycle)."""
        if tx_image_out is not self._tx_src:
            self._bind_tx(tx_image_out)
        self._write_sensors()

    def _measure(self) -> None:
        """Wheel speeds and pivot rates of the current state (what the sensors will report)."""
        y, speeds, rates = self._y, self._speeds, self._rates
        vx, vy, wz = y[3], y[4], y[5]
        inv_s, inv_r, k = self._inv_s, self._inv_r, self._k
        for i, (ua, ub, qa, qb) in enumerate(self._rows):
            ci, si = math.cos(y[6 + i]), math.sin(y[6 + i])
            q = -si * vx + ci * vy + (ci * qa + si * qb) * wz
            u = ci * vx + si * vy + (ci * ua + si * ub) * wz
            rates[i] = q * inv_s - wz
            speeds[2 * i] = (u - k * q) * inv_r
            speeds[2 * i + 1] = (u + k * q) * inv_r

    # --- drives -------------------------------------------------------------------------
    def _drives(self) -> None:
        """Currents from the command image: the SWMC's modes, enables, emergency bits and limits."""
        p = self.params
        ilim, kt, inv_r, k_inv_r = self._ilim, p.torque_constant_nm_per_a, self._inv_r, self._k_inv_r
        gain, speeds = p.drive_velocity_gain_a_per_rad_s, self._speeds
        currents, torques, status = self._currents_hw, self._torques, self._status
        for i, (cmd1, _, sp1, sp2, l1p, l1n, l2p, l2n, _) in enumerate(_COMMANDS.iter_unpack(self._rx_src)):
            mode = cmd1 & _MODE_MASK
            supported = mode == _MODE_TORQUE or mode == _MODE_VELOCITY
            en1 = supported and cmd1 & _ENABLE1_BITS == _ENABLE1
            en2 = supported and cmd1 & _ENABLE2_BITS == _ENABLE2
            if mode == _MODE_VELOCITY:  # a P speed loop inside the limit fields (current bounds in this mode)
                i1 = _velocity_loop(sp1, speeds[2 * i], gain, _clip(l1p, ilim), _clip(l1n, ilim))
                i2 = _velocity_loop(sp2, -speeds[2 * i + 1], gain, _clip(l2p, ilim), _clip(l2n, ilim))
            else:  # TORQUE: the setpoints are the currents
                i1, i2 = _clip(sp1, ilim), _clip(sp2, ilim)
            if not en1:
                i1 *= 0.0
            if not en2:
                i2 *= 0.0
            currents[2 * i], currents[2 * i + 1] = i1, i2
            t1, t2 = i1 * kt, i2 * kt * -1.0  # the drive's motor 2 turns the other way
            torques[2 * i], torques[2 * i + 1] = t1, t2
            self._torque_sum[i] = (t1 + t2) * inv_r
            self._torque_diff[i] = (t2 - t1) * k_inv_r
            status[i] = _ENCODERS_OK | (_ENABLED1 if en1 else 0) | (_ENABLED2 if en2 else 0)

    # --- sensors ------------------------------------------------------------------------
    def _write_sensors(self) -> None:
        p, y, image, units = self.params, self._y, self._tx_src, self.units
        speeds, rates, currents = self._speeds, self._rates, self._currents_hw
        noisy_wheels, noisy_pivots = p.wheel_velocity_noise_rad_s, p.pivot_noise_rad
        if noisy_wheels:
            self.rng.standard_normal(out=self._noise_w)
        if noisy_pivots:
            self.rng.standard_normal(out=self._noise_p)
        now, setpoint_ns, wz = self.time_ns, self._setpoint_ns, y[5]
        volts, temp, pack = p.bus_voltage_v, p.motor_temperature_k, _SENSORS.pack_into
        for i in range(units):
            v1, v2 = speeds[2 * i], -speeds[2 * i + 1]  # hardware convention: wheel 2 negated
            if noisy_wheels:
                v1 += float(self._noise_w[2 * i]) * noisy_wheels
                v2 += float(self._noise_w[2 * i + 1]) * noisy_wheels
            # Pivot encoder: delta + offset, wrapped to [-pi, pi).
            enc = y[6 + i] + self._offsets[i]
            if noisy_pivots:
                enc += float(self._noise_p[i]) * noisy_pivots
            enc = (enc + math.pi) % _TWO_PI - math.pi
            phi1, phi2 = y[6 + units + 2 * i], y[7 + units + 2 * i]
            pack(image, i * TXPDO_BYTES, self._status[i], 0, now, setpoint_ns,
                 phi1, v1, currents[2 * i], temp, -phi2, v2, currents[2 * i + 1], temp,
                 enc, rates[i], volts, now, 9.81, rates[i] + wz, temp, 101325.0)  # the unit's IMU turns with it

    def _bind_rx(self, image: NDArray[np.uint8]) -> None:
        rec = rxpdo_view(image)
        if rec.shape[0] != self.units:
            raise ValueError(f"command image has {rec.shape[0]} wheels, plant has {self.units}")
        self._rx_src = image

    def _bind_tx(self, image: NDArray[np.uint8]) -> None:
        rec = txpdo_view(image)
        if rec.shape[0] != self.units:
            raise ValueError(f"sensor image has {rec.shape[0]} wheels, plant has {self.units}")
        self._tx_src = image


def _clip(value: float, limit: float) -> float:
    """value within +-limit (NaN stays NaN, as np.clip leaves it)."""
    return limit if value > limit else -limit if value < -limit else value


def _velocity_loop(setpoint: float, speed: float, gain: float, upper: float, lower: float) -> float:
    """The drive's VELOCITY mode: gain * (setpoint - speed), bounded by the (clipped) limit fields."""
    current = (setpoint - speed) * gain
    if current > upper:
        current = upper
    if current < lower:
        current = lower
    return current
