"""The blind operator as an activity: it homes the Falcon when the LED asks, then drives when told.

It holds the simulated Falcon's grip (`sim/operator.py`'s `BlindOperator`): from the true handle
state and the obstacle force the haptic controller renders it computes the hand's force on the
grip, which the Falcon simulator adds to its motors'. Before driving it does what a person does
with a Falcon: while the LED is red it pulls the grip out and pushes it in (`HomingHand`) until
the LED turns green; then its hands rest until the flag `operator_go` says the haptic loop runs.
Driving, it publishes how long it has driven and whether it believes the task is over, which the
world's judge reads.
"""

from __future__ import annotations

from typing import Literal

import numpy as np
from pydantic import Field

from hapticop.blocks.base import Block
from hapticop.blocks.interface import Params, Port
from hapticop.devices.falcon import WORKSPACE_CENTRE_M, Flag
from hapticop.devices.falcon.homing import HomingHand
from hapticop.sim.operator import BlindOperator
from hapticop.sim.world_share import publish_operator


class OperatorParams(Params):
    variant: Literal["cautious", "nominal", "aggressive", "tremor", "hands_off"] = Field(
        "nominal", description="which synthetic operator: one of three profiles, 'tremor' (nominal with a 9 Hz "
        "tremor) or 'hands_off' (nominal, letting go at 5 s for 2 s)")
    variation: int | None = Field(None, ge=0, description="seed of a varied operator (each profile parameter "
                                  "scaled by up to 10 %); none: the exact profile")
    time_limit_s: float = Field(90.0, gt=0, description="the operator gives up here (and says it is done)")


class Operator(Block):
    Params = OperatorParams
    simulator = True
    provides = frozenset({"operator"})
    inputs = {
        "handle_position": Port("float64", (3,), "m", "true handle position, device frame, from the workspace centre"),
        "handle_velocity": Port("float64", (3,), "m/s", "true handle velocity, device frame"),
        "leds": Port("uint8", (), "1", "the Falcon's LEDs (codec Flag bits): red asks for homing, green says homed"),
        "environment_force": Port("float64", (3,), "N", "the obstacle part of the rendered force: what the "
                                  "operator feels (the centring spring is learned, not information)", required=False),
    }
    outputs = {
        "hand_force": Port("float64", (3,), "N", "the hand's force on the grip, device frame"),
        "driving_time": Port("float64", (), "s", "seconds since the operator started driving (published from then on)"),
        "done": Port("uint8", (), "1", "1 once the operator believes the task is over (stopped a while, or gave up)"),
        "hand_mass": Port("float64", (), "kg", "the mass of the hand on the grip: the profile's while it holds the "
                          "grip, 0 while it has let go (the device simulator moves it with the handle)"),
    }
    flags_read = {"operator_go": "the haptic loop runs: the operator may start driving"}
    awaits = frozenset({"operator_go"})

    def create(self) -> None:
        self.homing = HomingHand()
        self.red, self.green = int(Flag.LED_RED), int(Flag.LED_GREEN)
        self.centre = np.asarray(WORKSPACE_CENTRE_M, dtype=float)
        self.absolute = np.zeros(3)  # the handle in the device's own frame, for the homing motion
        self.nothing = np.zeros(3)  # felt while the haptic controller has said nothing yet
        self.homing_since_ns: int | None = None
        self.driving_since_ns: int | None = None
        self.operator: BlindOperator | None = None  # from resource configuration on

    def configure_resources(self) -> None:
        """The operator the parameters describe (again after a patch: another one takes the grip)."""
        p = self.params
        self.operator = BlindOperator.variant(p.variant, seed=p.variation, t_max_s=p.time_limit_s)
        self._publish_mass()
        publish_operator(self.run_dir, self.name, {"variant": p.variant, "variation": p.variation})

    def compute(self) -> None:
        now = self.clock.now_ns()
        hand = self.outputs.hand_force.value
        if self.driving_since_ns is None and self.flags["operator_go"]:
            self.driving_since_ns = now
            self.log.info("the operator starts driving")
        leds = int(self.inputs.leds.value)
        if leds & self.red and not leds & self.green:  # the Falcon asks to be homed (again, if it lost it)
            self._home(now, hand)
        else:
            self.homing_since_ns = None
            if self.driving_since_ns is not None:
                self._drive(now, hand)
            else:
                hand.fill(0.0)  # hands resting on the grip: nothing asked yet, or homed and waiting to drive
        self.outputs.hand_force.publish()
        self._publish_mass()

    def _publish_mass(self) -> None:
        """The hand's mass follows the grip: a released handle moves on its own mass alone."""
        mass = self.outputs.hand_mass
        mass.value[...] = self.operator.mass_kg
        mass.publish()

    def _home(self, now: int, hand: np.ndarray) -> None:
        """Grip out, then straight in, again, until the LED turns green: how a Falcon is homed."""
        if self.homing_since_ns is None:
            self.homing_since_ns = now
        np.add(self.inputs.handle_position.value, self.centre, out=self.absolute)
        self.homing.push((now - self.homing_since_ns) / 1e9, self.absolute, self.inputs.handle_velocity.value, hand)

    def _drive(self, now: int, hand: np.ndarray) -> None:
        inputs, out = self.inputs, self.outputs
        t = (now - self.driving_since_ns) / 1e9
        force = inputs.environment_force
        self.operator.step(t, force.value if force.valid else self.nothing, inputs.handle_position.value, hand,
                           inputs.handle_velocity.value)
        out.driving_time.value[...] = t
        out.done.value[...] = self.operator.done(t)
        out.driving_time.publish()
        out.done.publish()
