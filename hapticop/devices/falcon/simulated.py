"""A simulated Falcon that answers command frames with status frames, through the real codec.

It sits at the byte stream after the FTDI chip (docs/devices/falcon.md §7): one 16-byte status
frame per valid command frame, no reply to a malformed one. Inside, the motor commands
become thigh torques (tau = command / -10000 N m, libnifalcon's scale inverted), the
torques a handle force (F = J^-T tau, the same kinematics the host uses), and a point-mass
handle with viscous damping moves under that force plus the operator's. Its position goes
back through IK and the encoder model to counts.

What docs/devices/falcon.md say the firmware does, and the sim therefore does:
- motor commands saturate at +-4095 and are held 100 ms, then dropped to zero;
- counts are int16, relative to power-on until the axis is homed, then absolute
  (count 0 = 35 deg), with the jump that implies;
- an axis homes when, with the homing bit set, its thigh first goes beyond `homing_out_deg`
  (grip pulled out) and then back below `homing_reference_deg` (pushed in); homed flags are
  reported only while the host sets the homing bit, but the homing itself persists.
The two angles are our choice (the real reference position is not documented), as are the
hard end stop (a step that leaves the reachable workspace is refused, velocity zeroed) and
the default damping. The default handle mass is the thesis's 0.89 kg (chapter 4.3).
Deterministic: the only randomness is the power-on pose, drawn from `rng`. The state is
kept in Python floats and the maths is the kinematics' float-level API: at 3-vectors numpy's
per-call overhead would be most of the cost of a 1 ms step.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike, NDArray

from hapticop.devices.falcon.codec import MOTOR_LIMIT, Command, Flag, FrameCodec, FrameError, new_frame
from hapticop.devices.falcon.kinematics import FalconKinematics
from hapticop.devices.falcon.legs import Pose
from hapticop.devices.falcon.mechanism import WORKSPACE_CENTRE_M, Drive, Geometry

__all__ = ["SimulatedFalcon"]

_HOMING = int(Flag.HOMING)  # a plain int: IntFlag arithmetic builds enum members, too slow per substep


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
        self.kinematics = k = FalconKinematics(geometry, drive)
        self.mass = float(handle_mass_kg)
        self.damping = float(damping)
        self.motor_limit = int(motor_limit)
        self.command_hold_s = float(command_hold_s)
        self.max_step_s = float(max_step_s)
        self._out_rad = math.radians(homing_out_deg)
        self._ref_rad = math.radians(homing_reference_deg)
        self._motor_per_nm = float(k.drive.motor_per_nm)  # tau = command / motor_per_nm
        self._rng = rng if isinstance(rng, np.random.Generator) else np.random.default_rng(rng or 0)
        if initial_position is None:
            jitter = self._rng.uniform(-power_on_jitter_m, power_on_jitter_m, 3)
            initial_position = np.asarray(WORKSPACE_CENTRE_M) + jitter
        start = np.array(initial_position, dtype=np.float64).reshape(3)
        x, y, z = start.tolist()
        pose = k.pose(x, y, z)
        if pose is None:
            raise ValueError(f"initial position {start} is outside the workspace")
        self._p, self._v = (x, y, z), (0.0, 0.0, 0.0)
        self._pose: Pose = pose  # IK at _p: thigh angles are pose[axis][0]
        self._power_on = tuple(k.count(leg[0]) for leg in pose)
        self._homed = [bool(homed)] * 3
        self._armed = [False] * 3
        self._fext = (0.0, 0.0, 0.0)
        self._codec = FrameCodec()
        self._command = Command()
        self._motor = (0, 0, 0)  # saturated commands of the last valid frame
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
        return np.array(self._p)

    @property
    def velocity(self) -> NDArray[np.float64]:
        return np.array(self._v)

    def copy_state(self, out_position: NDArray[np.float64], out_velocity: NDArray[np.float64]) -> None:
        """`position` and `velocity` into caller arrays, for a caller's 1 kHz cycle."""
        out_position[0], out_position[1], out_position[2] = self._p
        out_velocity[0], out_velocity[1], out_velocity[2] = self._v

    @property
    def homed(self) -> NDArray[np.bool_]:
        return np.array(self._homed)

    @property
    def leds(self) -> int:
        return self.flags & int(Flag.LED_GREEN | Flag.LED_BLUE | Flag.LED_RED)

    @property
    def motor(self) -> NDArray[np.int64]:
        """Motor commands in force now (after saturation; zero once the hold expired)."""
        return np.array(self._motor if self._holding() else (0, 0, 0), dtype=np.int64)

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
            limit = self.motor_limit
            a, b, c = self._command.motor.tolist()
            self._motor = (min(max(a, -limit), limit), min(max(b, -limit), limit), min(max(c, -limit), limit))
            self.flags = self._command.flags
            self._last_command_s = self.time_s
        self.step(dt, external_force)
        if not valid:
            return None
        self.frames_out += 1
        target = self._reply if out is None else out
        self._codec.encode_status(self._status_counts(), self._homed_mask(), self.buttons, target)
        return self._reply.tobytes() if out is None else out

    def _status_counts(self) -> tuple[int, int, int]:
        """Encoder counts as the firmware reports them: relative until each axis is homed."""
        count, (leg1, leg2, leg3) = self.kinematics.count, self._pose
        (h1, h2, h3), (z1, z2, z3) = self._homed, self._power_on
        return (count(leg1[0]) - (0 if h1 else z1), count(leg2[0]) - (0 if h2 else z2),
                count(leg3[0]) - (0 if h3 else z3))

    def _homed_mask(self) -> int:
        """Homed flags are reported only while the host asks for homing."""
        if not self.flags & _HOMING:
            return 0
        h1, h2, h3 = self._homed
        return h1 | h2 << 1 | h3 << 2

    # ------------------------------------------------------------ physics
    def step(self, dt: float, external_force: ArrayLike = (0.0, 0.0, 0.0)) -> None:
        """Advance `dt` seconds without a frame (the motor command holds, then drops)."""
        a, b, c = external_force.tolist() if isinstance(external_force, np.ndarray) else external_force
        self._fext = (float(a), float(b), float(c))
        n = max(1, math.ceil(dt / self.max_step_s - 1e-9))
        h = dt / n
        for _ in range(n):
            self._substep(h)

    def _substep(self, h: float) -> None:
        force = None
        if self._holding():
            (m1, m2, m3), k = self._motor, self._motor_per_nm
            force = self.kinematics.pose_force(self._pose, m1 / k, m2 / k, m3 / k)
        f1, f2, f3 = force if force is not None else (0.0, 0.0, 0.0)
        e1, e2, e3 = self._fext
        (x, y, z), (v1, v2, v3) = self._p, self._v
        # semi-implicit Euler: m a = F_motor + F_operator - c v
        c, hm = -self.damping, h / self.mass
        v1, v2, v3 = v1 + (v1 * c + f1 + e1) * hm, v2 + (v2 * c + f2 + e2) * hm, v3 + (v3 * c + f3 + e3) * hm
        x, y, z = v1 * h + x, v2 * h + y, v3 * h + z
        pose = self.kinematics.pose(x, y, z)
        if pose is not None:
            self._p, self._v, self._pose = (x, y, z), (v1, v2, v3), pose
        else:  # end stop: the mechanism refuses to leave its workspace
            self._v = (0.0, 0.0, 0.0)
        self.time_s += h
        if self.flags & _HOMING:
            self._home()

    def _home(self) -> None:
        """Per-axis homing: armed beyond the out angle, homed when back past the reference."""
        armed, homed = self._armed, self._homed
        for axis, leg in enumerate(self._pose):
            theta = leg[0]
            armed[axis] = armed[axis] or theta >= self._out_rad
            homed[axis] = homed[axis] or (theta <= self._ref_rad and armed[axis])
