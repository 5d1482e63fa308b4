"""What the host must do to home a Falcon (docs/devices/falcon.md §6), as a tiny state holder.

Until homed, encoder counts are relative to power-on and any position-dependent force is
meaningless or violent, so the Falcon block runs this in capability configuration:

1. send the homing bit in *every* command frame, and keep sending it after homing
   (libnifalcon: the device stays homed only while it is set);
2. show a red LED and ask the user to pull the grip all the way out, then push it straight
   all the way in; each axis reports its homed flag (status bits 4-6) as it passes its
   reference, and only while the homing bit is set;
3. homed = all three flags (libnifalcon's `isHomed()`; before 2012 it took any one);
   then green LED, forget the FK warm start (the counts just jumped) and allow forces.

Homed is not latched: if the flags vanish (power cycle, firmware reload) forces must stop.
`HomingHand` is the other side: the person who moves the grip out and in (the virtual USB
Falcon's hand, and the simulated operator's while the Falcon's LED is red).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from hapticop.devices.falcon.codec import Flag, Status

__all__ = ["Homing", "HomingHand"]

# As plain ints: IntFlag arithmetic builds enum members, too slow for every 1 ms frame.
_HOMED_FLAGS = int(Flag.HOMING | Flag.LED_GREEN)
_WAITING_FLAGS = int(Flag.HOMING | Flag.LED_RED)
_BLUE = int(Flag.LED_BLUE)


@dataclass(slots=True)
class Homing:
    """Host-side homing bookkeeping: command flags to send and whether forces are allowed."""

    INSTRUCTIONS: ClassVar[str] = (
        "Pull the Falcon grip all the way out, then push it straight all the way in.")

    homed: bool = False
    #: True for exactly the update in which all three flags first appeared.
    just_homed: bool = False
    #: Times the flags vanished after homing.
    lost: int = 0
    #: Homed-flag mask (bit 0 = axis 1) of the last status, for progress display.
    mask: int = 0

    def command_flags(self, extra_leds: int = 0) -> int:
        """Byte-13 flags for the next command: homing always, red while waiting, green once homed."""
        return (_HOMED_FLAGS if self.homed else _WAITING_FLAGS) | (int(extra_leds) & _BLUE)

    def update(self, status: Status) -> bool:
        """Take the latest status; returns whether the device is homed now."""
        now = status.all_homed
        self.mask = status.homed_mask
        self.just_homed = now and not self.homed
        if self.homed and not now:
            self.lost += 1
        self.homed = now
        return now

    @property
    def forces_allowed(self) -> bool:
        """Position-dependent forces only once the counts are absolute."""
        return self.homed

    def missing_axes(self) -> tuple[int, ...]:
        """Axes (1-3: top, right, left seen from the front) still waiting for their flag."""
        return tuple(i + 1 for i in range(3) if not self.mask >> i & 1)


class HomingHand:
    """A person homing the grip (docs/devices/falcon.md §6): out, then straight in, again until homed.

    A spring-damper hand pulls the handle to `out_z` for `out_s`, then pushes it to `in_z` for
    the rest of each `period_s` (absolute device frame, metres).
    """

    def __init__(self, out_z: float = 0.178, in_z: float = 0.075, out_s: float = 0.8, period_s: float = 2.5,
                 stiffness: float = 300.0, damping: float = 20.0) -> None:
        self.out_z, self.in_z, self.out_s, self.period_s = out_z, in_z, out_s, period_s
        self.stiffness, self.damping = stiffness, damping
        self.start: float | None = None
        self._force = [0.0, 0.0, 0.0]

    def push(self, t: float, position: np.ndarray, velocity: np.ndarray, out) -> None:
        """The hand's force (N) into `out`, `t` seconds after it began, on a handle at `position`
        moving at `velocity` (absolute device frame)."""
        target_z = self.out_z if t % self.period_s < self.out_s else self.in_z
        k, c = self.stiffness, self.damping
        px, py, pz = position.tolist()
        vx, vy, vz = velocity.tolist()
        out[0] = k * (0.0 - px) - c * vx
        out[1] = k * (0.0 - py) - c * vy
        out[2] = k * (target_z - pz) - c * vz

    def __call__(self, t: float, falcon) -> list[float]:
        """The force on a `SimulatedFalcon` at time `t`: homing motion until it is homed, then hands off."""
        if falcon.homed.all():
            self._force[:] = (0.0, 0.0, 0.0)
            return self._force
        if self.start is None:
            self.start = t
        self.push(t - self.start, falcon.position, falcon.velocity, self._force)
        return self._force
