"""A button (or a dead-man grip) turned into a flag the coordination can react to.

It reads a button bit mask (the Falcon block's `buttons` port: the grip's four buttons,
docs/devices/falcon.md §4.2) and raises `pressed` while the chosen buttons are held; a change
counts only once it has lasted `debounce_s`, so a bouncing contact does not switch modes back and
forth. A stale mask (the Falcon's
frames stopped) reads as released at once: a dead-man switch fails towards "let go".
"""

from __future__ import annotations

from typing import Literal

from pydantic import Field

from hapticop.blocks.base import Block
from hapticop.blocks.interface import Params, Port


class ButtonParams(Params):
    mask: int = Field(0x1, ge=1, le=0xFF, description="the buttons that count, as bits of the mask (Falcon grip: "
                      "1 right or 'plus', 2 forward, 4 centre, 8 left)")
    require: Literal["any", "all"] = Field("any", description="'any': one of the masked buttons held is "
                                           "enough; 'all': every one of them must be held")
    debounce_s: float = Field(0.02, ge=0.0, le=1.0, description="a change counts once it has lasted this long")


class Button(Block):
    """`pressed` (a flag and a port) follows the masked buttons, debounced."""

    Params = ButtonParams
    inputs = {"buttons": Port("uint8", (), "1", "button bit mask (the Falcon block's buttons port)")}
    outputs = {"pressed": Port("uint8", (), "1", "1 while pressed (debounced)")}
    flags_written = {"pressed": "the chosen buttons are held (debounced); false while the mask is stale"}
    running_params = frozenset({"mask", "require", "debounce_s"})

    def create(self) -> None:
        self.pressed = False
        self.changing_since_ns: int | None = None  # when the raw state began to differ from `pressed`

    def compute(self) -> None:
        p, buttons = self.params, self.inputs.buttons
        held = int(buttons.value) & p.mask if buttons.valid else 0
        raw = held == p.mask if p.require == "all" else held != 0
        now = self.clock.now_ns()
        if raw == self.pressed:
            self.changing_since_ns = None
        elif not buttons.valid:
            self._set(False)  # nothing known: released, without waiting
        elif self.changing_since_ns is None:
            self.changing_since_ns = now
        if self.changing_since_ns is not None and now - self.changing_since_ns >= p.debounce_s * 1e9:
            self._set(raw)
        self.outputs.pressed.value[...] = self.pressed
        self.outputs.pressed.publish()

    def _set(self, pressed: bool) -> None:
        self.pressed = self.flags["pressed"] = pressed
        self.changing_since_ns = None

    def pausing(self) -> None:
        self.clean()

    def clean(self) -> None:
        self._set(False)
        self.outputs.pressed.value[...] = 0
        self.outputs.pressed.publish()
