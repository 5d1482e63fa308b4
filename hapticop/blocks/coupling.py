"""Two devices coupled, and a force of the world brought to the handle: blocks for bilateral set-ups.

`coupling` ties a leader and a follower by a spring-damper on the difference of their positions
(position-position bilateral teleoperation); `contact_to_handle` turns a force measured in the world
(a contact, a push) into a force on the handle, in the device frame. Both compute on Python floats
into preallocated arrays, as the desk effects do: nothing is allocated per cycle. docs/haptic-blocks.md
gives the equations.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Literal

import numpy as np
from pydantic import Field

from hapticop.blocks.base import Block
from hapticop.blocks.bounds import Bounds
from hapticop.blocks.interface import Interface, Params, Port, RateRange

HANDLE_RATE = RateRange(500.0, 2000.0, "forces for the Falcon: a stiff coupling is stable only near 1 kHz")
POSITION_RANGE = (-10.0, 10.0)  # m: far beyond any desk device; a sample outside is a fault, not a position
VELOCITY_RANGE = (-100.0, 100.0)  # m/s
FORCE_RANGE = (-1.0e4, 1.0e4)  # N, a force measured in a simulated or real world


def _clip_norm(x: float, y: float, z: float, limit: float, out: np.ndarray) -> None:
    """Write (x, y, z) into `out`, scaled down to norm `limit` if it is longer (its direction kept)."""
    norm = math.sqrt(x * x + y * y + z * z)
    if norm > limit:
        s = limit / norm
        x, y, z = x * s, y * s, z * s
    out[0], out[1], out[2] = x, y, z


class CouplingParams(Params):
    kp_n_per_m: float = Field(200.0, ge=0.0, le=1.0e4, description="stiffness of the coupling, N per m of "
                              "leader-follower position difference")
    kd_ns_per_m: float = Field(2.0, ge=0.0, le=100.0, description="damping on the velocity difference, N s/m")
    scale: float = Field(1.0, gt=0.0, le=100.0, description="position scaling: the follower's position and "
                         "velocity are multiplied by it before they are compared with the leader's")
    leader_max_n: float = Field(8.0, ge=0.0, le=1.0e3, description="norm limit of the leader's force, N")
    follower_max_n: float = Field(8.0, ge=0.0, le=1.0e3, description="norm limit of the follower's force, N")


class Coupling(Block):
    """A spring-damper between two devices: ``F_l = −K(x_l − s·x_f) − B(v_l − s·v_f)``, ``F_f = −F_l``,
    each side then limited by norm. Without a valid position on both sides, or with a sample out of
    range or not finite (counted, said once per burst), both forces are zero."""

    Params = CouplingParams
    running_params = frozenset({"kp_n_per_m", "kd_ns_per_m", "scale", "leader_max_n", "follower_max_n"})
    inputs = {
        "leader_position": Port("float64", (3,), "m", "leader handle position", range=POSITION_RANGE),
        "leader_velocity": Port("float64", (3,), "m/s", "leader handle velocity (unconnected: at rest)",
                                required=False, range=VELOCITY_RANGE),
        "follower_position": Port("float64", (3,), "m", "follower handle position", range=POSITION_RANGE),
        "follower_velocity": Port("float64", (3,), "m/s", "follower handle velocity (unconnected: at rest)",
                                  required=False, range=VELOCITY_RANGE),
    }
    outputs = {
        "leader_force": Port("float64", (3,), "N", "the coupling's force on the leader"),
        "follower_force": Port("float64", (3,), "N", "the coupling's force on the follower (minus the leader's, "
                               "before each side's limit)"),
    }
    rate = HANDLE_RATE

    def create(self) -> None:
        self.at_rest = np.zeros(3)
        ports = self.interface(self.params).inputs
        self.bounds = {name: Bounds(port, f"{self.name}.{name}") for name, port in ports.items()}
        self.seqs = dict.fromkeys(ports, -1)
        self.good = dict.fromkeys(ports, True)

    def _admitted(self, name: str) -> bool:
        """Whether this input's latest sample is in range and finite (each new sample checked once)."""
        port = getattr(self.inputs, name)
        if port.seq != self.seqs[name]:
            self.seqs[name] = port.seq
            bounds = self.bounds[name]
            good = self.good[name] = bounds.admits(port.value)
            bounds.said(self.log, good)
        return self.good[name]

    def _velocity(self, name: str) -> np.ndarray | None:
        """The velocity to use: at rest when none arrived or it is stale; None when its sample is refused."""
        port = getattr(self.inputs, name)
        if not port.valid:
            return self.at_rest
        return port.value if self._admitted(name) else None

    def compute(self) -> None:
        inputs, p = self.inputs, self.params
        leader, follower = self.outputs.leader_force, self.outputs.follower_force
        vl, vf = self._velocity("leader_velocity"), self._velocity("follower_velocity")
        xl, xf = inputs.leader_position, inputs.follower_position
        if (xl.valid and xf.valid and self._admitted("leader_position") and self._admitted("follower_position")
                and vl is not None and vf is not None):
            xl, xf, k, b, s = xl.value, xf.value, p.kp_n_per_m, p.kd_ns_per_m, p.scale
            fx = -k * (float(xl[0]) - s * float(xf[0])) - b * (float(vl[0]) - s * float(vf[0]))
            fy = -k * (float(xl[1]) - s * float(xf[1])) - b * (float(vl[1]) - s * float(vf[1]))
            fz = -k * (float(xl[2]) - s * float(xf[2])) - b * (float(vl[2]) - s * float(vf[2]))
            _clip_norm(fx, fy, fz, p.leader_max_n, leader.value)
            _clip_norm(-fx, -fy, -fz, p.follower_max_n, follower.value)
        else:
            leader.value.fill(0.0)
            follower.value.fill(0.0)
        leader.publish()
        follower.publish()

    def pausing(self) -> None:
        self.clean()

    def clean(self) -> None:
        for out in (self.outputs.leader_force, self.outputs.follower_force):
            out.value.fill(0.0)
            out.publish()


class ContactToHandleParams(Params):
    yaw_rad: float = Field(0.0, ge=-math.pi, le=math.pi, description="rotation from the world frame to the "
                           "device frame: yaw about z, applied last (R = Rz(yaw)·Ry(pitch)·Rx(roll))")
    pitch_rad: float = Field(0.0, ge=-math.pi, le=math.pi, description="pitch about y")
    roll_rad: float = Field(0.0, ge=-math.pi, le=math.pi, description="roll about x, applied first")
    gain: float = Field(1.0, ge=0.0, le=100.0, description="newtons on the handle per newton in the world")
    dead_band_n: float = Field(0.0, ge=0.0, le=1.0e3, description="world forces up to this norm are not felt; "
                               "above it, the norm is reduced by it (no jump at the edge), N")
    max_n: float = Field(8.0, ge=0.0, le=1.0e3, description="norm limit of the force on the handle, N")
    measured: Literal["force", "planar_wrench"] = Field(
        "force", description="what 'world_force' carries: 'force' [fx, fy, fz] (N); 'planar_wrench' [fx, fy, torque "
        "about z] (N, N, N m) as a planar robot's contact wrench (scene_world's), of which the torque is not felt")


def rotation(yaw: float, pitch: float, roll: float) -> tuple[float, ...]:
    """``Rz(yaw)·Ry(pitch)·Rx(roll)``, row by row: the nine floats of a rotation from world to device."""
    cy, sy, cp, sp = math.cos(yaw), math.sin(yaw), math.cos(pitch), math.sin(pitch)
    cr, sr = math.cos(roll), math.sin(roll)
    return (cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr,
            sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr,
            -sp, cp * sr, cp * cr)


class ContactToHandle(Block):
    """A force measured in the world felt at the handle: ``F = min(g·(|f| − d)⁺, F_max)·R f/|f|``, with R the
    world-to-device rotation, g the gain, d the dead-band. Stale or never received: zero. Out of range or
    not finite: zero, counted and said once per burst."""

    Params = ContactToHandleParams
    running_params = frozenset({"yaw_rad", "pitch_rad", "roll_rad", "gain", "dead_band_n", "max_n"})
    inputs = {"world_force": Port("float64", (3,), "N", "the force measured in the world, world frame",
                                  range=FORCE_RANGE)}
    outputs = {"force": Port("float64", (3,), "N", "the force on the handle, device frame")}
    rate = HANDLE_RATE

    @classmethod
    def interface(cls, params: ContactToHandleParams) -> Interface:
        base = super().interface(params)
        if params.measured == "planar_wrench":
            port = dataclasses.replace(base.inputs["world_force"], unit="N, N, N m",
                                       doc="a planar wrench measured in the world, world frame: its force is felt")
            base = dataclasses.replace(base, inputs={"world_force": port})
        return base

    def create(self) -> None:
        self.planar = self.params.measured == "planar_wrench"
        self.bounds = Bounds(self.inputs.world_force.spec, f"{self.name}.world_force")
        self.seq, self.good = -1, True
        self.retune(frozenset())

    def retune(self, changed: frozenset[str]) -> None:
        p = self.params
        self.r = rotation(p.yaw_rad, p.pitch_rad, p.roll_rad)

    @property
    def refused(self) -> int:
        """World forces refused so far (not finite or out of range)."""
        return self.bounds.refused

    def compute(self) -> None:
        measured, out, p = self.inputs.world_force, self.outputs.force, self.params
        if measured.seq != self.seq:
            self.seq = measured.seq
            self.good = self.bounds.admits(measured.value)
            self.bounds.said(self.log, self.good)
        x = y = z = 0.0
        if measured.valid and self.good:
            f = measured.value
            wx, wy, wz = float(f[0]), float(f[1]), 0.0 if self.planar else float(f[2])
            norm = math.sqrt(wx * wx + wy * wy + wz * wz)
            if norm > p.dead_band_n:
                s = p.gain * (norm - p.dead_band_n) / norm
                r = self.r
                x = s * (r[0] * wx + r[1] * wy + r[2] * wz)
                y = s * (r[3] * wx + r[4] * wy + r[5] * wz)
                z = s * (r[6] * wx + r[7] * wy + r[8] * wz)
        _clip_norm(x, y, z, p.max_n, out.value)
        out.publish()

    def pausing(self) -> None:
        self.clean()

    def clean(self) -> None:
        out = self.outputs.force
        out.value.fill(0.0)
        out.publish()
