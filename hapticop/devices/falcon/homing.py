"""What the host must do to home a Falcon (falcon-protocol.md §6), as a tiny state holder.

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
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

from hapticop.devices.falcon.codec import Flag, Status

__all__ = ["Homing"]

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
