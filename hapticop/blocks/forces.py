"""Forces combined and bounded: a sum of effects, and a limit on the force the device gets.

An application adds its effects with `force_sum` and sends the sum through `force_limit` to the
Falcon, so what the hand feels is bounded whatever the effects ask for (docs/haptic-blocks.md).
"""

from __future__ import annotations

import numpy as np
from pydantic import Field

from hapticop.blocks.base import Block
from hapticop.blocks.interface import Interface, Params, Port, RateRange
from hapticop.haptics.force_limit import ForceLimit as Limiter
from hapticop.haptics.force_limit import ForceLimitParams

HANDLE_RATE = RateRange(500.0, 2000.0, "forces for the Falcon: its loop runs near 1 kHz")


class ForceSumParams(Params):
    inputs: int = Field(2, ge=2, le=8, description="how many forces are added: the block has input ports "
                        "force_1 .. force_<inputs>, each of which must be connected")


class ForceSum(Block):
    """The sum of its input forces. A stale input (its stream's `max_age` passed) counts as zero."""

    Params = ForceSumParams

    @classmethod
    def interface(cls, params: ForceSumParams) -> Interface:
        inputs = {f"force_{i}": Port("float64", (3,), "N", f"force {i}, device frame")
                  for i in range(1, params.inputs + 1)}
        return Interface(inputs=inputs, outputs={"force": Port("float64", (3,), "N", "their sum")},
                         rate=HANDLE_RATE)

    def create(self) -> None:
        self.ports = tuple(vars(self.inputs).values())

    def compute(self) -> None:
        total = self.outputs.force
        value = total.value
        value.fill(0.0)
        for port in self.ports:
            if port.valid:
                np.add(value, port.value, out=value)
        total.publish()


class ForceLimitBlockParams(Params):
    limit: ForceLimitParams = Field(default_factory=ForceLimitParams)
    dead_man: bool = Field(False, description="add an 'enable' input (a button block's 'pressed'): while it is "
                           "0 or stale the force ramps down to zero, as when the operator lets go")


class ForceLimit(Block):
    """The input force bounded by norm and by rate of change: it starts from zero, ramps to the input at
    most `max_rate_n_per_s`, never exceeds `max_norm_n`, and ramps back to zero while the input is stale
    (or, with `dead_man`, while `enable` is 0 or stale)."""

    Params = ForceLimitBlockParams
    running_params = frozenset({"limit"})

    @classmethod
    def interface(cls, params: ForceLimitBlockParams) -> Interface:
        inputs = {"demand": Port("float64", (3,), "N", "the force asked for, device frame")}
        if params.dead_man:
            inputs["enable"] = Port("uint8", (), "1", "nonzero while the force may be rendered (a dead-man grip)")
        bounded = Port("float64", (3,), "N", "the force bounded, device frame")
        return Interface(inputs=inputs, outputs={"force": bounded}, rate=HANDLE_RATE)

    def create(self) -> None:
        self.limiter = Limiter()
        self.nothing = np.zeros(3)
        self.last_ns: int | None = None

    def compute(self) -> None:
        now = self.clock.now_ns()
        dt_s = 0.0 if self.last_ns is None else (now - self.last_ns) / 1e9
        self.last_ns = now
        inputs, out = self.inputs, self.outputs.force
        asked = inputs.demand
        allowed = asked.valid and (not self.params.dead_man or (inputs.enable.valid and int(inputs.enable.value)))
        self.limiter.step(self.params.limit, asked.value if allowed else self.nothing, dt_s, out.value)
        out.publish()

    def pausing(self) -> None:
        """While paused the device gets nothing; running again, the force ramps up from zero."""
        self.limiter.reset()
        self.last_ns = None
        self.clean()

    def clean(self) -> None:
        out = self.outputs.force
        out.value.fill(0.0)
        out.publish()
