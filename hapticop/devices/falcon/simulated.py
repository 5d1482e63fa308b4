"""A simulated Falcon that answers command frames with status frames, through the real codec.

It sits at the byte stream after the FTDI chip (falcon-protocol.md §7): one 16-byte status
frame per valid command frame, no reply to a malformed one. Inside, the motor commands
become thigh torques (tau = command / -10000 N m, libnifalcon's scale inverted), the
torques a handle force (F = J^-T tau, the same kinematics the host uses), and a point-mass
handle with viscous damping moves under that force plus the operator's. Its position goes
back through IK and the encoder model to counts.

What the notes say the firmware does, and the sim therefore does:
- motor commands saturate at +-4095 and are held 100 ms, then dropped to zero;
- counts are int16, relative to power-on until the axis is homed, then absolute
  (count 0 = 35 deg), with the jump that implies;
- an axis homes when, with the homing bit set, its thigh first goes beyond `homing_out_deg`
  (grip pulled out) and then back below `homing_reference_deg` (pushed in); homed flags are
  reported only while the host sets the homing bit, but the homing itself persists.
The two angles are our choice (the real reference position is not documented), as are the
hard end stop (a step that leaves the reachable workspace is refused, velocity zeroed) and
the default damping. The default handle mass is the thesis's 0.89 kg (chapter 4.3).
Deterministic: the only randomness is the power-on pose, drawn from `rng`.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike, NDArray

from hapticop.devices.falcon.codec import MOTOR_LIMIT, Command, Flag, FrameCodec, FrameError, new_frame
from hapticop.devices.falcon.kinematics import WORKSPACE_CENTRE_M, Drive, FalconKinematics, Geometry

__all__ = ["SimulatedFalcon"]


class SimulatedFalcon:
    """Handle dynamics and firmware behaviour behind the 16-byte frame protocol."""

    def __init__(self, geometry: Geometry | None = None, handle_mass_kg: float = 0.89,
                 damping: float = 2.0, rng: np.random.Generator | int | None = None, *,
                 drive: Drive | None = None, initial_position: ArrayLike | None = None,
                 power_on_jitter_m: float = 0.005, homed: bool = False,
                 motor_limit: int = MOTOR_LIMIT, command_hold_s: float = 0.1,
                 homing_out_deg: float = 60.0, homing_reference_deg: float = -5.0,
                 max_step_s: float = 0.001) -> None:
        if handle_mass_kg <= 0.0:
            raise ValueError("handle_mass_kg must be positive")
        self.kinematics = FalconKinematics(geometry, drive)
        self.mass = float(handle_mass_kg)
        self.damping = float(damping)
        self.motor_limit = int(motor_limit)
        self.command_hold_s = float(command_hold_s)
        self.max_step_s = float(max_step_s)
        self._out_rad = math.radians(homing_out_deg)
        self._ref_rad = math.radians(homing_reference_deg)
        self._rng = rng if isinstance(rng, np.random.Generator) else np.random.default_rng(rng or 0)
        if initial_position is None:
            jitter = self._rng.uniform(-power_on_jitter_m, power_on_jitter_m, 3)
            initial_position = np.asarray(WORKSPACE_CENTRE_M) + jitter
        self._p = np.array(initial_position, dtype=np.float64).reshape(3)
        self._v = np.zeros(3)
        self._theta = np.zeros(3)
        self._counts = np.zeros(3, dtype=np.int64)
        if not self.kinematics.inverse(self._p, self._theta):
            raise ValueError(f"initial position {self._p} is outside the workspace")
        self._power_on = np.zeros(3, dtype=np.int64)
        self.kinematics.counts_from_angles(self._theta, self._power_on)
        self._homed = np.full(3, bool(homed))
        self._armed = np.zeros(3, dtype=np.bool_)
        self._cmp = np.zeros(3, dtype=np.bool_)
        self._codec = FrameCodec()
        self._command = Command()
        self._motor = np.zeros(3, dtype=np.int64)
        self._tau, self._force, self._fext, self._acc = np.zeros(3), np.zeros(3), np.zeros(3), np.zeros(3)
        self._trial = np.zeros(3)
        self._reply = new_frame()
        self.flags = 0  # last command's Flag bits (homing, LEDs)
        self.buttons = 0  # Button bits the "user" presses; scriptable
        self.time_s = 0.0
        self._last_command_s = -math.inf
        self.frames_in = self.frames_out = self.malformed = 0

    # ------------------------------------------------------------ observation
    @property
    def position(self) -> NDArray[np.float64]:
        """True handle position (m), device frame: what an operator's hand feels."""
        return self._p.copy()

    @property
    def velocity(self) -> NDArray[np.float64]:
        return self._v.copy()

    @property
    def homed(self) -> NDArray[np.bool_]:
        return self._homed.copy()

    @property
    def leds(self) -> int:
        return self.flags & int(Flag.LED_GREEN | Flag.LED_BLUE | Flag.LED_RED)

    @property
    def motor(self) -> NDArray[np.int64]:
        """Motor commands in force now (after saturation; zero once the hold expired)."""
        return self._motor.copy() if self._holding() else np.zeros(3, dtype=np.int64)

    def _holding(self) -> bool:
        return self.time_s - self._last_command_s <= self.command_hold_s

    # ------------------------------------------------------------ protocol
    def exchange(self, command_frame: bytes | bytearray | memoryview | NDArray[np.uint8], dt: float,
                 external_force: ArrayLike = (0.0, 0.0, 0.0),
                 out: NDArray[np.uint8] | bytearray | None = None) -> bytes | NDArray[np.uint8] | bytearray | None:
        """Apply one command frame, advance `dt` seconds, return the status frame.

        `external_force` (N) is the operator's push on the handle during `dt`. A malformed
        command is ignored (the previous one keeps its 100 ms hold), time still passes and
        the reply is None. With `out` the reply is written there (no allocation) and `out`
        returned; otherwise it is returned as bytes.
        """
        valid = True
        try:
            self._codec.decode_command(command_frame, self._command)
        except FrameError:
            valid = False
            self.malformed += 1
        if valid:
            self.frames_in += 1
            np.clip(self._command.motor, -self.motor_limit, self.motor_limit, out=self._motor)
            self.flags = self._command.flags
            self._last_command_s = self.time_s
        self.step(dt, external_force)
        if not valid:
            return None
        self.frames_out += 1
        self._status_counts()
        mask = int(self._homed[0]) | int(self._homed[1]) << 1 | int(self._homed[2]) << 2
        if not self.flags & Flag.HOMING:
            mask = 0  # flags are reported only while the host asks for homing
        target = self._reply if out is None else out
        self._codec.encode_status(self._counts, mask, self.buttons, target)
        return self._reply.tobytes() if out is None else out

    def _status_counts(self) -> None:
        """Encoder counts as the firmware reports them: relative until each axis is homed."""
        self.kinematics.counts_from_angles(self._theta, self._counts)
        np.logical_not(self._homed, out=self._cmp)
        np.subtract(self._counts, self._power_on, out=self._counts, where=self._cmp)

    # ------------------------------------------------------------ physics
    def step(self, dt: float, external_force: ArrayLike = (0.0, 0.0, 0.0)) -> None:
        """Advance `dt` seconds without a frame (the motor command holds, then drops)."""
        np.copyto(self._fext, external_force)
        n = max(1, math.ceil(dt / self.max_step_s - 1e-9))
        h = dt / n
        for _ in range(n):
            self._substep(h)

    def _substep(self, h: float) -> None:
        k, acc = self.kinematics, self._acc
        if self._holding():
            np.divide(self._motor, k.drive.motor_per_nm, out=self._tau)
            if not k.torques_to_force(self._p, self._tau, self._force):
                self._force.fill(0.0)
        else:
            self._force.fill(0.0)
        # semi-implicit Euler: m a = F_motor + F_operator - c v
        np.multiply(self._v, -self.damping, out=acc)
        np.add(acc, self._force, out=acc)
        np.add(acc, self._fext, out=acc)
        np.multiply(acc, h / self.mass, out=acc)
        np.add(self._v, acc, out=self._v)
        np.multiply(self._v, h, out=self._trial)
        np.add(self._trial, self._p, out=self._trial)
        if k.inverse(self._trial, self._theta):
            np.copyto(self._p, self._trial)
        else:  # end stop: the mechanism refuses to leave its workspace
            self._v.fill(0.0)
            k.inverse(self._p, self._theta)
        self.time_s += h
        self._home(self._theta)

    def _home(self, theta: NDArray[np.float64]) -> None:
        """Per-axis homing: armed beyond the out angle, homed when back past the reference."""
        if not self.flags & Flag.HOMING:
            return
        np.greater_equal(theta, self._out_rad, out=self._cmp)
        np.logical_or(self._armed, self._cmp, out=self._armed)
        np.less_equal(theta, self._ref_rad, out=self._cmp)
        np.logical_and(self._cmp, self._armed, out=self._cmp)
        np.logical_or(self._homed, self._cmp, out=self._homed)
