"""A force limited in size and in how fast it may change: what the hand may be asked to feel.

The rate limit keeps a step in the commanded force (a wall touched at speed, an effect switched on,
a stale input dropped to zero) from reaching the hand as a blow; the norm limit keeps the sum of
effects within what the device and the operator should get. The rate limit moves the last output
at most ``rate·dt`` towards the target, then the norm limit projects onto the ball of radius
``max_norm``: a projection onto a ball that holds the last output moves no point further from it,
so both bounds hold together (docs/haptic-blocks.md).
"""

from __future__ import annotations

import math
from typing import Annotated

import numpy as np
from annotated_types import Gt
from numpy.typing import NDArray

from hapticop.parameters import parameters


@parameters
class ForceLimitParams:
    """Bounds on the force sent to the device."""

    max_norm_n: Annotated[float, Gt(0)] = 8.0
    """The largest force, by its Euclidean norm."""
    max_rate_n_per_s: Annotated[float, Gt(0)] = 2000.0
    """The fastest change of the force vector, by its norm (2 N in a 1 ms cycle by default)."""


class ForceLimit:
    """The limited force, step by step, from the one it gave last (zero to begin with)."""

    __slots__ = ("last",)

    def __init__(self) -> None:
        self.last = (0.0, 0.0, 0.0)

    def reset(self) -> None:
        """Start again from zero force (after a pause: the force ramps up again)."""
        self.last = (0.0, 0.0, 0.0)

    def step(self, p: ForceLimitParams, target: NDArray[np.float64], dt_s: float,
             out: NDArray[np.float64]) -> NDArray[np.float64]:
        """Write into ``out`` the force ``dt_s`` after the last one, heading for ``target``.

        A target with a component that is not finite counts as zero: nothing is known to render.
        """
        tx, ty, tz = float(target[0]), float(target[1]), float(target[2])
        if not (math.isfinite(tx) and math.isfinite(ty) and math.isfinite(tz)):
            tx = ty = tz = 0.0
        lx, ly, lz = self.last
        dx, dy, dz = tx - lx, ty - ly, tz - lz
        step = math.sqrt(dx * dx + dy * dy + dz * dz)
        most = p.max_rate_n_per_s * (dt_s if dt_s > 0.0 else 0.0)
        if step > most:
            scale = most / step
            dx, dy, dz = dx * scale, dy * scale, dz * scale
        fx, fy, fz = lx + dx, ly + dy, lz + dz
        size = math.sqrt(fx * fx + fy * fy + fz * fz)
        if size > p.max_norm_n:
            scale = p.max_norm_n / size
            fx, fy, fz = fx * scale, fy * scale, fz * scale
        self.last = (fx, fy, fz)
        out[0], out[1], out[2] = fx, fy, fz
        return out
