"""Haptic effects as blocks: a virtual wall, a spring-damper, a viscous field, a workspace limit.

Each reads the handle's position and velocity (the Falcon block's ports, device frame) and writes
one force, at the Falcon's rate; the equations and their parameters are ``hapticop.haptics.effects``.
Their parameters are read every cycle, so a patch changes a wall's stiffness between two cycles.
Without a valid handle position there is nothing to render against: the force is zero.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import ClassVar, Literal

import numpy as np
from pydantic import Field

from hapticop.blocks.base import Block
from hapticop.blocks.bounds import Bounds
from hapticop.blocks.interface import Interface, Params, Port, RateRange
from hapticop.haptics.effects import (
    SphereLimitParams,
    SpringParams,
    ViscousParams,
    WallParams,
    WorkspaceLimitParams,
    render_spring,
    render_viscous,
    render_wall,
    render_workspace_limit,
)

HANDLE_RATE = RateRange(500.0, 2000.0, "a stiff effect is rendered stably only near the Falcon's 1 kHz")


class Effect(Block):
    """One effect: the handle's state in, its force out. A subclass names its parameter set and equation."""

    effect: ClassVar[str]  # the parameter that holds the effect's parameter set
    render: ClassVar[Callable]
    inputs = {
        "position": Port("float64", (3,), "m", "handle position, device frame"),
        "velocity": Port("float64", (3,), "m/s", "handle velocity, device frame (unconnected: at rest)",
                         required=False),
    }
    outputs = {"force": Port("float64", (3,), "N", "the effect's force on the handle, device frame")}
    rate = HANDLE_RATE

    def create(self) -> None:
        self.at_rest = np.zeros(3)

    def compute(self) -> None:
        inputs, force = self.inputs, self.outputs.force
        if inputs.position.valid:
            velocity = inputs.velocity.value if inputs.velocity.valid else self.at_rest
            type(self).render(getattr(self.params, self.effect), inputs.position.value, velocity, force.value)
        else:
            force.value.fill(0.0)
        force.publish()

    def pausing(self) -> None:
        self.clean()

    def clean(self) -> None:
        force = self.outputs.force
        force.value.fill(0.0)
        force.publish()


class VirtualWallParams(Params):
    wall: WallParams = Field(default_factory=WallParams)


class VirtualWall(Effect):
    """A one-sided plane wall: stiffness and damping while the handle is behind it, nothing in front."""

    Params = VirtualWallParams
    effect, render = "wall", staticmethod(render_wall)
    running_params = frozenset({"wall"})


class SpringDamperParams(Params):
    spring: SpringParams = Field(default_factory=SpringParams)
    anchor: Literal["parameter", "input"] = Field(
        "parameter", description="where the spring's anchor comes from: 'parameter' is spring.anchor_m; 'input' adds "
        "the inputs 'anchor' (and, optional, 'anchor_velocity'), e.g. another device's handle")


ANCHOR_INPUTS = {
    "anchor": Port("float64", (3,), "m", "where the spring pulls to, device frame (stale or out of range: no force)",
                   range=(-10.0, 10.0)),
    "anchor_velocity": Port("float64", (3,), "m/s", "the anchor's velocity, damped against the handle's "
                            "(unconnected: at rest)", required=False, range=(-100.0, 100.0)),
}


class SpringDamper(Effect):
    """A spring and damper pulling the handle to a point: ``F = k·(a − q) − b·(v − v_a)``. The anchor a is
    the parameter ``spring.anchor_m`` (v_a = 0), or with ``anchor: input`` what the input 'anchor' says."""

    Params = SpringDamperParams
    effect, render = "spring", staticmethod(render_spring)
    running_params = frozenset({"spring"})

    @classmethod
    def interface(cls, params: SpringDamperParams) -> Interface:
        interface = super().interface(params)
        if params.anchor == "input":
            interface.inputs.update(ANCHOR_INPUTS)
        return interface

    def create(self) -> None:
        super().create()
        if self.params.anchor == "input":
            self.bounds = {name: Bounds(port, f"{self.name}.{name}") for name, port in ANCHOR_INPUTS.items()}
            self.seqs = dict.fromkeys(ANCHOR_INPUTS, -1)
            self.good = dict.fromkeys(ANCHOR_INPUTS, True)

    def _admitted(self, name: str) -> bool:
        """Whether this anchor input's latest sample is in range and finite (each new sample checked once)."""
        port = getattr(self.inputs, name)
        if port.seq != self.seqs[name]:
            self.seqs[name] = port.seq
            good = self.good[name] = self.bounds[name].admits(port.value)
            self.bounds[name].said(self.log, good)
        return self.good[name]

    def compute(self) -> None:
        if self.params.anchor == "parameter":
            super().compute()
            return
        inputs, force = self.inputs, self.outputs.force
        anchor, anchor_velocity = inputs.anchor, inputs.anchor_velocity
        va = self.at_rest
        if anchor_velocity.valid:
            va = anchor_velocity.value if self._admitted("anchor_velocity") else None
        if inputs.position.valid and anchor.valid and self._admitted("anchor") and va is not None:
            q, a, p = inputs.position.value, anchor.value, self.params.spring
            v = inputs.velocity.value if inputs.velocity.valid else self.at_rest
            k, b, out = p.kp_n_per_m, p.kd_ns_per_m, force.value
            out[0] = k * (float(a[0]) - float(q[0])) - b * (float(v[0]) - float(va[0]))
            out[1] = k * (float(a[1]) - float(q[1])) - b * (float(v[1]) - float(va[1]))
            out[2] = k * (float(a[2]) - float(q[2])) - b * (float(v[2]) - float(va[2]))
        else:
            force.value.fill(0.0)
        force.publish()


class ViscousFieldParams(Params):
    viscosity: ViscousParams = Field(default_factory=ViscousParams)


class ViscousField(Effect):
    """A force against the handle's velocity everywhere, as if it moved through a fluid."""

    Params = ViscousFieldParams
    effect, render = "viscosity", staticmethod(render_viscous)
    inputs = {
        "position": Port("float64", (3,), "m", "handle position, device frame (the force is zero while it is stale)"),
        "velocity": Port("float64", (3,), "m/s", "handle velocity, device frame"),
    }
    running_params = frozenset({"viscosity"})


class WorkspaceLimitBlockParams(Params):
    limit: WorkspaceLimitParams = Field(
        default_factory=SphereLimitParams, discriminator="kind",
        description="the space the handle is kept in: 'kind' box or sphere, and that shape's parameters")


class WorkspaceLimit(Effect):
    """Walls that keep the handle inside a box or a sphere: nothing inside, a stiff push back outside."""

    Params = WorkspaceLimitBlockParams
    effect, render = "limit", staticmethod(render_workspace_limit)
    running_params = frozenset({"limit"})
