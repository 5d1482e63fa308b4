"""A hand on the simulated Falcon that follows a script: the desk scene's operator, with no world around it.

It homes the Falcon as a person does (grip out, then in, while the LED is red); once the LED turns
green it guides the grip to a start point (homing leaves it against the front end stop), and from
then on pushes on the grip with the force its script gives at each instant (keyframes, linearly
interpolated, the last one held) and holds the buttons the script says. Its force goes to the
Falcon simulator's `hand_force`, its buttons to the simulator's `buttons`. When the script's last
keyframe has passed it raises `finished`, which a composition's net may take as the end of the run.
A script of zero forces is a hands-off operator.
"""

from __future__ import annotations

from typing import Annotated

import numpy as np
from annotated_types import Ge, Le
from pydantic import BaseModel, ConfigDict, Field, field_validator

from hapticop.blocks.base import Block
from hapticop.blocks.interface import Params, Port
from hapticop.devices.falcon import WORKSPACE_CENTRE_M, Flag
from hapticop.devices.falcon.homing import HomingHand

#: The hand's stiffness and damping while it places the grip, as the homing hand's (N/m, N s/m).
HAND_KP, HAND_KD = 300.0, 20.0


class Keyframe(BaseModel):
    """What the hand does at one instant of its script."""

    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)
    t_s: float = Field(ge=0.0, description="seconds since the script began (homed, then settle_s later)")
    force_n: tuple[Annotated[float, Ge(-20.0), Le(20.0)], Annotated[float, Ge(-20.0), Le(20.0)],
                   Annotated[float, Ge(-20.0), Le(20.0)]] = Field(
        (0.0, 0.0, 0.0), description="the hand's force on the grip, device frame (interpolated to the next keyframe)")
    buttons: int = Field(0, ge=0, le=0xF, description="grip buttons held from here to the next keyframe (bit mask)")


#: Push down onto a floor below the homed handle, hold, let go: the default script.
PUSH_HOLD_RELEASE = (
    Keyframe(t_s=0.0, force_n=(0.0, 0.0, 0.0), buttons=1),
    Keyframe(t_s=0.5, force_n=(0.0, -4.0, 0.0), buttons=1),
    Keyframe(t_s=2.0, force_n=(0.0, -4.0, 0.0), buttons=1),
    Keyframe(t_s=2.2, force_n=(0.0, 0.0, 0.0)),
    Keyframe(t_s=2.5, force_n=(0.0, 0.0, 0.0)),
)


class ScriptedHandParams(Params):
    start_m: tuple[float, float, float] = Field(
        (0.0, 0.0, 0.0), description="where the hand brings the grip after homing, device frame from the "
        "workspace centre")
    settle_s: float = Field(0.5, ge=0.0, le=10.0,
                            description="how long it takes to get there; the script begins then")
    script: tuple[Keyframe, ...] = Field(
        PUSH_HOLD_RELEASE, min_length=1, description="keyframes in increasing time; the default holds button 1, "
        "pushes down up to 4 N by 0.5 s, holds 4 N until 2.0 s, lets go by 2.2 s and finishes at 2.5 s")

    @field_validator("script")
    @classmethod
    def _in_time_order(cls, script: tuple[Keyframe, ...]) -> tuple[Keyframe, ...]:
        for before, after in zip(script, script[1:], strict=False):
            if not after.t_s > before.t_s:
                raise ValueError(f"keyframes must be in increasing time: {after.t_s} s comes after {before.t_s} s")
        return script


class ScriptedHand(Block):
    """Homing, then the grip placed, then the script: the force and buttons of a hand on the simulated Falcon."""

    Params = ScriptedHandParams
    simulator = True
    inputs = {
        "handle_position": Port("float64", (3,), "m", "true handle position, device frame, from the workspace centre"),
        "handle_velocity": Port("float64", (3,), "m/s", "true handle velocity, device frame"),
        "leds": Port("uint8", (), "1", "the Falcon's LEDs (codec Flag bits): red asks for homing, green says homed"),
    }
    outputs = {
        "hand_force": Port("float64", (3,), "N", "the hand's force on the grip, device frame"),
        "buttons": Port("uint8", (), "1", "the grip buttons the hand holds (bit mask)"),
    }
    flags_written = {"finished": "the script's last keyframe has passed"}

    def create(self) -> None:
        self.homing = HomingHand()
        self.red, self.green = int(Flag.LED_RED), int(Flag.LED_GREEN)
        self.centre = np.asarray(WORKSPACE_CENTRE_M, dtype=float)
        self.absolute = np.zeros(3)  # the handle in the device's own frame, for the homing motion
        self.homing_since_ns: int | None = None
        self.homed_since_ns: int | None = None
        self.keyframe = 0  # the script's keyframe at or before the last instant played

    def configure_resources(self) -> None:
        self.keyframe = 0  # a patched script is played from its own first keyframe on

    def compute(self) -> None:
        now = self.clock.now_ns()
        hand = self.outputs.hand_force.value
        leds = int(self.inputs.leds.value)
        if leds & self.red and not leds & self.green:  # the Falcon asks to be homed
            self._home(now, hand)
        else:
            self.homing_since_ns = None
            if leds & self.green and self.homed_since_ns is None:
                self.homed_since_ns = now
                self.log.info("homed: the hand takes the grip to its start point")
            t = -1.0 if self.homed_since_ns is None else (now - self.homed_since_ns) / 1e9 - self.params.settle_s
            if t >= 0.0:
                self._play(t, hand)
            elif self.homed_since_ns is not None:
                self._settle(hand)
            else:
                hand.fill(0.0)
                self.outputs.buttons.value[...] = 0
        self.outputs.hand_force.publish()
        self.outputs.buttons.publish()

    def _home(self, now: int, hand: np.ndarray) -> None:
        if self.homing_since_ns is None:
            self.homing_since_ns = now
        np.add(self.inputs.handle_position.value, self.centre, out=self.absolute)
        self.homing.push((now - self.homing_since_ns) / 1e9, self.absolute, self.inputs.handle_velocity.value, hand)

    def _settle(self, hand: np.ndarray) -> None:
        """A hand's spring and damper towards the start point (a person placing the grip)."""
        sx, sy, sz = self.params.start_m
        position, velocity = self.inputs.handle_position.value, self.inputs.handle_velocity.value
        hand[0] = HAND_KP * (sx - float(position[0])) - HAND_KD * float(velocity[0])
        hand[1] = HAND_KP * (sy - float(position[1])) - HAND_KD * float(velocity[1])
        hand[2] = HAND_KP * (sz - float(position[2])) - HAND_KD * float(velocity[2])
        self.outputs.buttons.value[...] = 0

    def _play(self, t: float, hand: np.ndarray) -> None:
        """The script at `t` seconds: the force interpolated between its two keyframes, their first's buttons."""
        script = self.params.script
        i = self.keyframe
        while i + 1 < len(script) and script[i + 1].t_s <= t:
            i += 1
        self.keyframe = i
        now = script[i]
        if i + 1 < len(script) and t > now.t_s:
            after = script[i + 1]
            w = (t - now.t_s) / (after.t_s - now.t_s)
            (ax, ay, az), (bx, by, bz) = now.force_n, after.force_n
            hand[0], hand[1], hand[2] = ax + w * (bx - ax), ay + w * (by - ay), az + w * (bz - az)
        else:
            hand[0], hand[1], hand[2] = now.force_n
            if i + 1 == len(script) and t >= now.t_s and not self.flags["finished"]:
                self.flags["finished"] = True
                self.log.info("the script is over")
        self.outputs.buttons.value[...] = now.buttons
