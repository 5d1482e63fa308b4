"""Virtual environments felt at the handle: a wall, a spring to a point, a viscous field, workspace limits.

Each effect is a force of the handle's position and velocity alone, in the Falcon's device frame
(``handle.py`` defines the axes, origin at the workspace centre), in newtons from metres and metres
per second. Each has a parameter set and a ``render(params, position, velocity, out)`` that writes the
force into ``out`` on Python floats: at 3-vectors numpy's per-call cost would be most of a 1 kHz cycle,
and floats leave nothing allocated behind. docs/haptic-blocks.md gives the equations.
"""

from __future__ import annotations

import math
from typing import Annotated, Literal

import numpy as np
from annotated_types import Ge, Gt
from numpy.typing import NDArray

from hapticop.parameters import parameters

Vector = tuple[float, float, float]


def _unit(v: Vector, what: str) -> None:
    """Refuse a direction of zero length: it names no direction."""
    if math.hypot(*v) < 1e-9:
        raise ValueError(f"{what} must not be the zero vector")


@parameters
class WallParams:
    """A one-sided plane: it pushes the handle out along its normal, and only while the handle is behind it."""

    point_m: Vector = (0.0, 0.0, -0.02)
    """A point of the plane, device frame."""
    normal: Vector = (0.0, 0.0, 1.0)
    """Direction out of the wall, into free space (any length but zero; the default faces the operator)."""
    kp_n_per_m: Annotated[float, Ge(0)] = 1000.0
    """Stiffness: force per metre of penetration."""
    kd_ns_per_m: Annotated[float, Ge(0)] = 2.0
    """Damping on the normal velocity, only while penetrating; it never pulls the handle into the wall."""

    def __post_init__(self) -> None:
        _unit(self.normal, "the wall's normal")


def render_wall(p: WallParams, position: NDArray[np.float64], velocity: NDArray[np.float64],
                out: NDArray[np.float64]) -> NDArray[np.float64]:
    """``F = max(k·d − b·(v·n), 0)·n`` with depth ``d = (q − p)·n`` for unit normal n, while ``d > 0``; else 0."""
    nx, ny, nz = p.normal
    norm = math.sqrt(nx * nx + ny * ny + nz * nz)
    nx, ny, nz = nx / norm, ny / norm, nz / norm
    qx, qy, qz = p.point_m
    depth = (qx - float(position[0])) * nx + (qy - float(position[1])) * ny + (qz - float(position[2])) * nz
    f = 0.0
    if depth > 0.0:
        along = float(velocity[0]) * nx + float(velocity[1]) * ny + float(velocity[2]) * nz
        f = p.kp_n_per_m * depth - p.kd_ns_per_m * along
        f = f if f > 0.0 else 0.0  # damping slows the way out but never holds the handle in
    out[0], out[1], out[2] = f * nx, f * ny, f * nz
    return out


@parameters
class SpringParams:
    """A spring and damper that pull the handle to an anchor point."""

    anchor_m: Vector = (0.0, 0.0, 0.0)
    """Where the spring is at rest, device frame."""
    kp_n_per_m: Annotated[float, Ge(0)] = 100.0
    """Stiffness, the same on every axis."""
    kd_ns_per_m: Annotated[float, Ge(0)] = 1.0
    """Damping on the handle velocity."""


def render_spring(p: SpringParams, position: NDArray[np.float64], velocity: NDArray[np.float64],
                  out: NDArray[np.float64]) -> NDArray[np.float64]:
    """``F = k·(a − q) − b·v``."""
    ax, ay, az = p.anchor_m
    k, b = p.kp_n_per_m, p.kd_ns_per_m
    out[0] = k * (ax - float(position[0])) - b * float(velocity[0])
    out[1] = k * (ay - float(position[1])) - b * float(velocity[1])
    out[2] = k * (az - float(position[2])) - b * float(velocity[2])
    return out


@parameters
class ViscousParams:
    """A fluid the handle moves through: force against its velocity, everywhere."""

    b_ns_per_m: Annotated[float, Ge(0)] = 5.0
    """Viscosity: newtons per metre per second of handle speed."""


def render_viscous(p: ViscousParams, position: NDArray[np.float64], velocity: NDArray[np.float64],
                   out: NDArray[np.float64]) -> NDArray[np.float64]:
    """``F = −b·v``."""
    b = p.b_ns_per_m
    out[0], out[1], out[2] = -b * float(velocity[0]), -b * float(velocity[1]), -b * float(velocity[2])
    return out


@parameters
class BoxLimitParams:
    """An axis-aligned box the handle is held inside by walls on its six faces."""

    centre_m: Vector = (0.0, 0.0, 0.0)
    """The box's centre, device frame."""
    half_size_m: tuple[Annotated[float, Gt(0)], Annotated[float, Gt(0)], Annotated[float, Gt(0)]] = (0.04, 0.04, 0.04)
    """Half its width along x, y and z."""
    kp_n_per_m: Annotated[float, Ge(0)] = 1000.0
    """Stiffness of each face, per metre beyond it."""
    kd_ns_per_m: Annotated[float, Ge(0)] = 2.0
    """Damping of each face, only beyond it; it never pushes the handle outwards."""
    kind: Literal["box"] = "box"


@parameters
class SphereLimitParams:
    """A ball the handle is held inside by a spherical wall."""

    centre_m: Vector = (0.0, 0.0, 0.0)
    """The ball's centre, device frame."""
    radius_m: Annotated[float, Gt(0)] = 0.04
    """Its radius."""
    kp_n_per_m: Annotated[float, Ge(0)] = 1000.0
    """Stiffness of the wall, per metre beyond the radius."""
    kd_ns_per_m: Annotated[float, Ge(0)] = 2.0
    """Damping, only beyond the radius; it never pushes the handle outwards."""
    kind: Literal["sphere"] = "sphere"


WorkspaceLimitParams = BoxLimitParams | SphereLimitParams
"""A workspace limit's shape; ``kind`` names it."""


def _inwards(depth: float, speed_out: float, k: float, b: float) -> float:
    """How hard a limit's face pushes back at ``depth`` beyond it: ``max(k·d + b·v_out, 0)`` while ``d > 0``."""
    if not depth > 0.0:
        return 0.0
    f = k * depth + b * speed_out
    return f if f > 0.0 else 0.0


def render_workspace_limit(p: WorkspaceLimitParams, position: NDArray[np.float64], velocity: NDArray[np.float64],
                           out: NDArray[np.float64]) -> NDArray[np.float64]:
    """Box: per axis ``F_i = −sign(e_i)·max(k·(|e_i| − h_i) + b·v_i·sign(e_i), 0)`` beyond a face, with
    ``e = q − c``. Sphere: ``F = −max(k·(|e| − r) + b·(v·u), 0)·u`` beyond the radius, ``u = e/|e|``."""
    cx, cy, cz = p.centre_m
    k, b = p.kp_n_per_m, p.kd_ns_per_m
    ex, ey, ez = float(position[0]) - cx, float(position[1]) - cy, float(position[2]) - cz
    vx, vy, vz = float(velocity[0]), float(velocity[1]), float(velocity[2])
    if p.kind == "box":
        hx, hy, hz = p.half_size_m  # type: ignore[union-attr]
        out[0] = -math.copysign(_inwards(abs(ex) - hx, vx * math.copysign(1.0, ex), k, b), ex)
        out[1] = -math.copysign(_inwards(abs(ey) - hy, vy * math.copysign(1.0, ey), k, b), ey)
        out[2] = -math.copysign(_inwards(abs(ez) - hz, vz * math.copysign(1.0, ez), k, b), ez)
        return out
    r = math.sqrt(ex * ex + ey * ey + ez * ez)
    f = 0.0
    if r > p.radius_m:  # type: ignore[union-attr]
        ux, uy, uz = ex / r, ey / r, ez / r
        f = _inwards(r - p.radius_m, vx * ux + vy * uy + vz * uz, k, b) / r  # type: ignore[union-attr]
    out[0], out[1], out[2] = -f * ex, -f * ey, -f * ez
    return out
