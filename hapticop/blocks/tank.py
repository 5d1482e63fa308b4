"""An energy tank on the device's force port: what model jumps and stale cues may inject, bounded.

Between the haptic controller and the Falcon: the controller's force goes through, its active part
(the environmental cue) scaled down only when the tank would run below its floor (docs/teleop.md).
The level is a stream of its own, so a run's recording shows how close the tank came to empty.
"""

from __future__ import annotations

import numpy as np
from pydantic import Field

from hapticop.blocks.base import Block
from hapticop.blocks.interface import Interface, Params, Port, RateRange
from hapticop.haptics.energy_tank import EnergyTank, EnergyTankParams


class EnergyTankBlockParams(Params):
    tank: EnergyTankParams = Field(default_factory=EnergyTankParams)
    active_input: bool = Field(
        True, description="the active part of the force comes on its own input 'active' (a part of 'demand'), "
        "and only it is scaled; false: the whole demand is active")


class EnergyTankBlock(Block):
    """The demanded force with its active part limited by an energy tank; publishes the tank's level (J)
    and the scale it applied."""

    Params = EnergyTankBlockParams
    period_params = frozenset({"tank.period_s"})

    @classmethod
    def interface(cls, params: EnergyTankBlockParams) -> Interface:
        inputs = {"demand": Port("float64", (3,), "N", "the force asked for, device frame"),
                  "velocity": Port("float64", (3,), "m/s", "the handle's velocity, device frame")}
        if params.active_input:
            inputs["active"] = Port("float64", (3,), "N", "the active part of the demand (an environmental cue)")
        return Interface(
            inputs=inputs,
            outputs={"force": Port("float64", (3,), "N", "the force allowed, device frame"),
                     "level": Port("float64", (), "J", "the energy the tank holds"),
                     "scale": Port("float64", (), "1", "the factor the active force got (1: untouched)")},
            rate=RateRange(500.0, 2000.0, "a port's energy is accounted for at the device's rate"))

    def create(self) -> None:
        self.tank = EnergyTank(self.params.tank)
        self.active = np.zeros(3)
        self.allowed = np.zeros(3)
        self.still = np.zeros(3)

    def compute(self) -> None:
        inputs, out = self.inputs, self.outputs
        demand = inputs.demand
        force = out.force.value
        if not demand.valid:
            force.fill(0.0)
        else:
            active = self.active
            if self.params.active_input:
                if inputs.active.valid:
                    np.copyto(active, inputs.active.value)
                else:
                    active.fill(0.0)
            else:
                np.copyto(active, demand.value)
            velocity = inputs.velocity.value if inputs.velocity.valid else self.still
            self.tank.step(active, velocity, self.allowed)
            # the passive part as asked, the active part as allowed
            np.subtract(demand.value, active, out=force)
            np.add(force, self.allowed, out=force)
        out.level.value[...] = self.tank.level_j
        out.scale.value[...] = self.tank.scale
        out.force.publish()
        out.level.publish()
        out.scale.publish()

    def clean(self) -> None:
        self.log.info("energy tank: lowest level %.4f J", self.tank.lowest_j)
        self.outputs.force.value.fill(0.0)
        self.outputs.force.publish()
