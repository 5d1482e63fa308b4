"""A simulated ropod: rigid platform on four trailing-caster smart wheels, driven by wheel currents.

The model is ropod-controller.md §8 "Level 1": the platform is a rigid body (36.5 kg, yaw
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
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from hapticop.devices.ropod.kinematics import Geometry, Inverse3, SmartWheelKinematics
from hapticop.devices.ropod.pdo import Com1, Stat1, rxpdo_view, txpdo_view

__all__ = ["PlantParams", "RopodPlant"]

F64 = NDArray[np.float64]

_THESIS_OFFSETS = (4.691878, 3.224157, 0.028178, 5.856820)
_MODE_MASK = np.uint16(Com1.MODE_MASK)
_MODE_TORQUE = np.uint16(Com1.MODE_TORQUE)
_MODE_VELOCITY = np.uint16(Com1.MODE_VELOCITY)
_ENABLE_BITS = tuple((np.uint16(en | em), np.uint16(en)) for en, em in
                     ((Com1.ENABLE1, Com1.EMERGENCY1), (Com1.ENABLE2, Com1.EMERGENCY2)))
_ENABLED_BITS = (np.uint16(Stat1.ENABLED1), np.uint16(Stat1.ENABLED2))
_ENCODERS_OK = np.uint16(Stat1.ENCODERS_OK)


@dataclass(frozen=True)
class PlantParams:
    """Physical parameters; the inertias and losses are the notes' guesses (§8), not measurements."""

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

    `pose` (x, y, theta in the world), `twist` (vx, vy, wz in the robot frame) and
    `pivot_angles` are views of the state; `wheel_speeds`, `wheel_torques` and
    `currents_hw` hold the last step's values.
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
        self._inverse3 = Inverse3()
        self._offsets = np.array(p.pivot_offsets_rad, np.float64)
        self._inv_s = 1.0 / g.caster_offset_m
        self._ic_s2 = p.unit_yaw_inertia_kgm2 / g.caster_offset_m**2
        self._diag = np.array([p.mass_kg, p.mass_kg, p.yaw_inertia_kgm2])
        self._inv_diag = 1.0 / self._diag
        self._ilim, self._neg_ilim = np.float64(p.drive_current_limit_a), np.float64(-p.drive_current_limit_a)
        # State: pose (3), twist (3), pivot angles (units), wheel angles (wheels), model convention.
        self.state = np.zeros(6 + units + wheels)
        self.pose = self.state[0:3]
        self.twist = self.state[3:6]
        self.pivot_angles = self.state[6:6 + units]
        self.wheel_angles = self.state[6 + units:]
        self.time_ns = 0
        self._setpoint_ns = 0
        # RK4 scratch.
        self._k = np.zeros((4, self.state.size))
        self._y = np.zeros(self.state.size)
        self._m3 = np.zeros((3, 3))
        self._m3_diag = self._m3.reshape(9)[::4]
        self._m3_inv = np.zeros((3, 3))
        self._rhs = np.zeros(3)
        self._t3 = np.zeros(3)
        self._u = np.zeros(units)
        self._q = np.zeros(units)
        # Outputs of the drive model and the measurement.
        self.currents_hw = np.zeros(wheels)  # as the drive reports them (wheel 2 negated)
        self.wheel_torques = np.zeros(wheels)  # model convention
        self.wheel_speeds = np.zeros(wheels)  # model convention
        self.pivot_rates = np.zeros(units)
        self._hw_speed = np.zeros(wheels)
        self._hw_sign = np.tile([1.0, -1.0], units)
        self._noise_w = np.zeros(wheels)
        self._noise_p = np.zeros(units)
        self._enc = np.zeros(units)
        # Drive decoding scratch (per unit and per wheel).
        self._cmd = np.zeros(units, np.uint16)
        self._tmp16 = np.zeros(units, np.uint16)
        self._en = np.zeros(wheels, bool)
        self._en2 = self._en.reshape(-1, 2)
        self._torque_mode = np.zeros(units, bool)
        self._velocity_mode = np.zeros(units, bool)
        self._b = np.zeros(units, bool)
        self._sp = np.zeros(wheels)
        self._lim_p = np.zeros(wheels)
        self._lim_n = np.zeros(wheels)
        self._vel_i = np.zeros(wheels)
        self._status = np.full(units, _ENCODERS_OK, np.uint16)  # healthy, drives not yet enabled
        self._i2 = self.currents_hw.reshape(-1, 2)
        self._vi2 = self._vel_i.reshape(-1, 2)
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
        self._measure()

    # --- the step ------------------------------------------------------------------------
    def step(self, rx_image: NDArray[np.uint8], dt: float, tx_image_out: NDArray[np.uint8]) -> None:
        """Read the commands, run the drives and the body for dt seconds, write the sensors."""
        if rx_image is not self._rx_src:
            self._bind_rx(rx_image)
        if tx_image_out is not self._tx_src:
            self._bind_tx(tx_image_out)
        self._setpoint_ns = self.time_ns
        self._drives()
        if self.params.measurement_delay:
            self._write_sensors()
        h = dt / self.params.substeps
        for _ in range(self.params.substeps):
            self._rk4(h)
        self.time_ns += int(round(dt * 1e9))
        self._measure()
        if not self.params.measurement_delay:
            self._write_sensors()

    def write_sensors(self, tx_image_out: NDArray[np.uint8]) -> None:
        """Report the current state without stepping (to fill the image before the first cycle)."""
        if tx_image_out is not self._tx_src:
            self._bind_tx(tx_image_out)
        self._write_sensors()

    # --- dynamics -----------------------------------------------------------------------
    def _derivative(self, y: F64, dy: F64) -> None:
        """dy = f(y) for the held wheel torques (Level 1 equations, ropod-controller.md §8)."""
        kin, units = self.kinematics, self.units
        v = y[3:6]
        wz = v[2]
        kin.update_jacobian(y[6:6 + units])
        theta = float(y[2])
        c, s = math.cos(theta), math.sin(theta)
        vx, vy = float(v[0]), float(v[1])
        dy[0] = c * vx - s * vy
        dy[1] = s * vx + c * vy
        dy[2] = wz
        ddelta = dy[6:6 + units]
        np.matmul(kin.Q, v, out=self._q)
        self._q *= self._inv_s  # unit yaw rate Omega_i = q_i / s
        np.subtract(self._q, wz, out=ddelta)
        np.matmul(kin.G, v, out=dy[6 + units:])
        p, rhs, t3 = self.params, self._rhs, self._t3
        kin.wrench(self.wheel_torques, out=rhs)
        m, wzf = p.mass_kg, float(wz)
        rhs[0] += m * wzf * vy - p.linear_damping_ns_per_m * vx
        rhs[1] += -m * wzf * vx - p.linear_damping_ns_per_m * vy
        rhs[2] -= p.yaw_damping_nms * wzf
        if p.pivot_damping_nms:
            rhs[2] += p.pivot_damping_nms * float(np.sum(ddelta))
            np.matmul(kin.Q.T, ddelta, out=t3)
            t3 *= p.pivot_damping_nms * self._inv_s
            rhs -= t3
        acc = dy[3:6]
        if self._ic_s2:
            np.matmul(kin.U, v, out=self._u)
            self._u *= ddelta  # u_i * delta_dot_i: the caster's steering "centripetal" term
            np.matmul(kin.Q.T, self._u, out=t3)
            t3 *= self._ic_s2
            rhs += t3
            m3 = self._m3
            np.matmul(kin.Q.T, kin.Q, out=m3)
            m3 *= self._ic_s2
            self._m3_diag += self._diag
            self._inverse3(m3, self._m3_inv)
            np.matmul(self._m3_inv, rhs, out=acc)
        else:
            np.multiply(rhs, self._inv_diag, out=acc)

    def _rk4(self, h: float) -> None:
        y, k, yt = self.state, self._k, self._y
        self._derivative(y, k[0])
        np.multiply(k[0], 0.5 * h, out=yt)
        yt += y
        self._derivative(yt, k[1])
        np.multiply(k[1], 0.5 * h, out=yt)
        yt += y
        self._derivative(yt, k[2])
        np.multiply(k[2], h, out=yt)
        yt += y
        self._derivative(yt, k[3])
        k[1] += k[2]
        k[1] *= 2.0
        k[0] += k[1]
        k[0] += k[3]
        k[0] *= h / 6.0
        y += k[0]

    def _measure(self) -> None:
        kin = self.kinematics
        kin.update_jacobian(self.pivot_angles)
        kin.wheel_speeds(self.twist, out=self.wheel_speeds)
        kin.pivot_rates(self.twist, out=self.pivot_rates)

    # --- drives -------------------------------------------------------------------------
    def _drives(self) -> None:
        """Currents from the command image: the SWMC's modes, enables, emergency bits and limits."""
        cmd1, sp1, sp2, l1p, l1n, l2p, l2n = self._rx
        cmd, t16, supported, en = self._cmd, self._tmp16, self._b, self._en2
        np.copyto(cmd, cmd1)
        np.bitwise_and(cmd, _MODE_MASK, out=t16)
        np.equal(t16, _MODE_TORQUE, out=self._torque_mode)
        np.equal(t16, _MODE_VELOCITY, out=self._velocity_mode)
        np.logical_or(self._torque_mode, self._velocity_mode, out=supported)
        for j, (bits, enable) in enumerate(_ENABLE_BITS):
            np.bitwise_and(cmd, bits, out=t16)
            np.equal(t16, enable, out=en[:, j])  # enabled and no emergency stop
            en[:, j] &= supported
        i, sp = self.currents_hw, self._sp
        np.copyto(sp[0::2], sp1)
        np.copyto(sp[1::2], sp2)
        np.minimum(sp, self._ilim, out=i)  # TORQUE: the setpoints are the currents
        np.maximum(i, self._neg_ilim, out=i)
        if self._velocity_mode.any():
            self._velocity_loop()
        np.multiply(i, self._en, out=i)
        np.multiply(i, self.params.torque_constant_nm_per_a, out=self.wheel_torques)
        self.wheel_torques *= self._hw_sign  # the drive's motor 2 turns the other way
        st = self._status
        st.fill(_ENCODERS_OK)
        for j, bit in enumerate(_ENABLED_BITS):
            np.copyto(t16, en[:, j])
            t16 *= bit
            st |= t16

    def _velocity_loop(self) -> None:
        """VELOCITY mode: a proportional speed loop inside the limit fields (current bounds in this mode)."""
        cmd1, sp1, sp2, l1p, l1n, l2p, l2n = self._rx
        np.copyto(self._lim_p[0::2], l1p)
        np.copyto(self._lim_p[1::2], l2p)
        np.copyto(self._lim_n[0::2], l1n)
        np.copyto(self._lim_n[1::2], l2n)
        for bound in (self._lim_p, self._lim_n):
            np.minimum(bound, self._ilim, out=bound)
            np.maximum(bound, self._neg_ilim, out=bound)
        vi = self._vel_i
        np.subtract(self._sp, self._hw_speed_now(), out=vi)
        vi *= self.params.drive_velocity_gain_a_per_rad_s
        np.minimum(vi, self._lim_p, out=vi)
        np.maximum(vi, self._lim_n, out=vi)
        for j in range(2):
            np.copyto(self._i2[:, j], self._vi2[:, j], where=self._velocity_mode)

    def _hw_speed_now(self) -> F64:
        return np.multiply(self.wheel_speeds, self._hw_sign, out=self._hw_speed)

    # --- sensors ------------------------------------------------------------------------
    def _write_sensors(self) -> None:
        p, f = self.params, self._tx
        speeds = self._hw_speed_now()
        if p.wheel_velocity_noise_rad_s:
            self.rng.standard_normal(out=self._noise_w)
            self._noise_w *= p.wheel_velocity_noise_rad_s
            speeds += self._noise_w
        f["status1"][:] = self._status
        f["status2"].fill(0)
        f["sensor_ts"].fill(self.time_ns)
        f["setpoint_ts"].fill(self._setpoint_ns)
        f["imu_ts"].fill(self.time_ns)
        np.copyto(f["velocity_1"], speeds[0::2])
        np.copyto(f["velocity_2"], speeds[1::2])
        np.copyto(f["encoder_1"], self.wheel_angles[0::2])
        np.negative(self.wheel_angles[1::2], out=self._enc)
        np.copyto(f["encoder_2"], self._enc)
        np.copyto(f["current_1_q"], self.currents_hw[0::2])
        np.copyto(f["current_2_q"], self.currents_hw[1::2])
        # Pivot encoder: delta + offset, wrapped to [-pi, pi).
        enc = self._enc
        np.add(self.pivot_angles, self._offsets, out=enc)
        if p.pivot_noise_rad:
            self.rng.standard_normal(out=self._noise_p)
            self._noise_p *= p.pivot_noise_rad
            enc += self._noise_p
        enc += math.pi
        np.mod(enc, 2.0 * math.pi, out=enc)
        enc -= math.pi
        np.copyto(f["encoder_pivot"], enc)
        np.copyto(f["velocity_pivot"], self.pivot_rates)
        np.add(self.pivot_rates, self.twist[2], out=enc)
        np.copyto(f["gyro_z"], enc)  # the unit's IMU turns with the unit
        f["voltage_bus"].fill(p.bus_voltage_v)
        f["temperature_1"].fill(p.motor_temperature_k)
        f["temperature_2"].fill(p.motor_temperature_k)
        f["accel_z"].fill(9.81)
        f["temperature_imu"].fill(p.motor_temperature_k)
        f["pressure"].fill(101325.0)

    def _bind_rx(self, image: NDArray[np.uint8]) -> None:
        rec = rxpdo_view(image)
        if rec.shape[0] != self.units:
            raise ValueError(f"command image has {rec.shape[0]} wheels, plant has {self.units}")
        self._rx_src = image
        self._rx = tuple(rec[n] for n in ("command1", "setpoint1", "setpoint2",
                                          "limit1_p", "limit1_n", "limit2_p", "limit2_n"))

    def _bind_tx(self, image: NDArray[np.uint8]) -> None:
        rec = txpdo_view(image)
        if rec.shape[0] != self.units:
            raise ValueError(f"sensor image has {rec.shape[0]} wheels, plant has {self.units}")
        self._tx_src = image
        self._tx = {name: rec[name] for name in rec.dtype.names}
