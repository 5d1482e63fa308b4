"""An energy tank on the device's port: the active force may give the hand only energy the tank holds.

docs/teleop.md, after Franken et al. (2011, two-layer approach) and docs/hallway-experiment.md §7.6:
a cue rendered from a delayed, predicted or freshly replaced model can push the hand with energy
nobody put in (a model jump, a stale wall that moved). A passivity observer and controller would
dissipate every joule a warning cue is meant to deliver; a tank instead lets the cue spend a small
budget, refilled by what the hand and the local damper dissipate, and only scales the active force
down when the budget would run below its floor. So, step by step (ΔT the period, v the handle
velocity, F the active force, all in the handle frame, F·v the power given to the hand):

    draw   = F·v·ΔT                            energy the step would give (negative: the hand gives)
    λ      = 1, or (H − H_min)/draw if that would take H below H_min (draw > 0)
    H     ← min(H − λ·draw + b·|v|²·ΔT, H_max) the refill b·|v|²·ΔT is the local damper's dissipation
    F_out  = λ·F

Invariants, for any forces and velocities: H ≥ H_min always, and over any window the net energy
the active force gives the hand is at most H_max − H_min plus the refill in that window.
"""

from __future__ import annotations

from typing import Annotated

import numpy as np
from annotated_types import Ge, Gt
from numpy.typing import NDArray

from hapticop.parameters import parameters


@parameters
class EnergyTankParams:
    """The tank's budget (docs/teleop.md): sized from what the hallway's stopping cue spends (up to 0.2 J
    measured for the aggressive operators, whatever the delay), with room for twice that; it is empty when
    it sits at `min_j` (the cue was being scaled down)."""

    initial_j: Annotated[float, Ge(0)] = 0.4
    """E_0: what the tank holds at the start (and after a reset)."""
    max_j: Annotated[float, Gt(0)] = 0.4
    """E_max: what it holds at most; a refill beyond is dumped, so no unbounded credit builds up."""
    min_j: Annotated[float, Ge(0)] = 0.0
    """E_min: the floor; the active force is scaled down rather than take the tank below it."""
    refill_damping_ns_per_m: Annotated[float, Ge(0)] = 0.2
    """b: the damping whose dissipation b·|v|² refills the tank (the centring PD's own Kd)."""
    period_s: Annotated[float, Gt(0)] = 0.001
    """ΔT: the time between two steps."""

    def __post_init__(self) -> None:
        if not self.min_j <= self.initial_j <= self.max_j:
            raise ValueError("the tank needs min_j <= initial_j <= max_j")


class EnergyTank:
    """The tank's level, step by step; allocation-free."""

    __slots__ = ("params", "level_j", "lowest_j", "scale")

    def __init__(self, params: EnergyTankParams = EnergyTankParams()) -> None:
        self.params = params
        self.reset()

    def reset(self) -> None:
        """Full of its initial budget again."""
        self.level_j = self.lowest_j = self.params.initial_j
        self.scale = 1.0
        """λ of the last step: 1 when the force passed untouched."""

    def step(self, active: NDArray[np.float64], velocity: NDArray[np.float64], out: NDArray[np.float64]) -> float:
        """Write the active force the tank allows into ``out`` (``out`` may be ``active``); returns λ."""
        p = self.params
        fx, fy, fz = float(active[0]), float(active[1]), float(active[2])
        vx, vy, vz = float(velocity[0]), float(velocity[1]), float(velocity[2])
        draw = (fx * vx + fy * vy + fz * vz) * p.period_s
        level = self.level_j
        scale = 1.0
        if draw > 0.0 and level - draw < p.min_j:
            scale = max(0.0, (level - p.min_j) / draw)
        level -= scale * draw
        level += p.refill_damping_ns_per_m * (vx * vx + vy * vy + vz * vz) * p.period_s
        # rounding may land a hair below the floor when the force is scaled to meet it exactly
        level = min(max(level, p.min_j), p.max_j)
        self.level_j = level
        if level < self.lowest_j:
            self.lowest_j = level
        self.scale = scale
        out[0], out[1], out[2] = scale * fx, scale * fy, scale * fz
        return scale
