"""S2, shared control: a control-barrier-function filter on the operator's velocity command.

docs/hallway-experiment.md §10.2: the robot adds its own avoidance to what the operator asks,
from its own scan. Each scan point p at clearance d from the body (the footprint's nearest
point to p, along the unit normal n from the body to p) gives one barrier h = d − margin, and
the filter keeps the translation v = (vx, vy) inside

    n·v ≤ α·max(d − margin, 0)          (ḣ ≥ −α·h, with h held at 0 once inside the margin)

so a clearance may shrink at most at a rate proportional to what is left of it, and a point
already inside the margin is never approached. The executed v is the command projected onto
these half-planes (a few passes onto the most violated one: it slides along a wall instead of
stopping), then scaled towards zero until every constraint holds exactly. Every right-hand side
is ≥ 0, so standing still is always allowed and the scaling always ends feasible; projection onto
sets holding the origin never lengthens v, so the filter never adds speed.

Between scans (15 Hz) each clearance is predicted from the filter's own outputs since the scan,
integrated cycle by cycle. (Multiplying the last output by the scan's age instead closes a loop
within the cycle: a sideways slide that shortens the predicted clearance shrinks the next output,
which lengthens it again, and the robot's sideways speed rings at the scan rate.) The turn rate
passes unchanged: the swept corners of a turn are not modelled (the governor bounds turning near
the side walls). Work is split as elsewhere:
``update_scan`` once per scan, ``filter`` every cycle, both into preallocated arrays.
"""

from __future__ import annotations

import math
from typing import Annotated

import numpy as np
from annotated_types import Ge, Gt
from numpy.typing import ArrayLike, NDArray

from hapticop.devices.ropod.body import Body
from hapticop.haptics.geometry import BeamGeometry
from hapticop.haptics.handle import TWIST_VX, TWIST_VY, TWIST_WZ
from hapticop.parameters import parameters

F64 = NDArray[np.float64]


@parameters
class SafetyFilterParams:
    """S2, the shared-control filter (docs/hallway-experiment.md §10.2): the robot keeps its own margin
    from whatever its scan sees, whatever the operator commands."""

    margin_m: Annotated[float, Ge(0)] = 0.30
    """Clearance from the body the filter never lets the robot approach closer than."""
    gain_per_s: Annotated[float, Gt(0)] = 2.0
    """alpha: a clearance d may shrink at most at alpha * (d - margin) per second."""
    influence_m: Annotated[float, Gt(0)] = 1.5
    """Points farther than this from the body never constrain."""
    lateral: bool = True
    """Slide the robot sideways along an obstacle (the ropod is holonomic); false: only slow it."""
    passes: Annotated[int, Ge(0)] = 6
    """Projections onto the most violated constraint before the final scaling."""


class SafetyFilter:
    """The filter for one scan geometry (``angles`` in the robot frame, ranges from ``body.lidar``)."""

    FAR_M = 1.0e6
    """The clearance of a point out of influence: its bound never binds (finite, so no inf - inf)."""

    def __init__(self, angles: ArrayLike, params: SafetyFilterParams = SafetyFilterParams(),
                 body: Body = Body()) -> None:
        self.params = params
        self.beams = BeamGeometry(angles, body)
        n = self.beams.n
        self.clearance = np.full(n, self.FAR_M)  # d per point, FAR_M for points out of influence
        self.nx = np.zeros(n)  # unit normal from the body to the point
        self.ny = np.zeros(n)
        self.bound = np.zeros(n)  # this cycle's right-hand side alpha * max(d_now - margin, 0)
        self.excess = np.zeros(n)  # this cycle's n.v - bound
        self._work = np.zeros(n)
        self._mask = np.zeros(n, dtype=bool)
        self.executed = np.zeros(3)  # the last output, for the prediction between scans
        self.moved = np.zeros(2)  # how far the outputs since the scan have moved the robot, x and y
        self.scan_age_s = 0.0  # the scan's age at the last cycle

    def update_scan(self, ranges: NDArray[np.floating]) -> None:
        """A new scan: each point's clearance from the body and its normal (15 Hz)."""
        b = self.beams
        b.load(ranges)  # invalid beams parked far away
        hl, hw = b.half_length, b.half_width
        ex, ey, d = self.nx, self.ny, self.clearance
        np.clip(b.px, -hl, hl, out=ex)
        np.subtract(b.px, ex, out=ex)  # how far beyond the body along x (0 beside it)
        np.clip(b.py, -hw, hw, out=ey)
        np.subtract(b.py, ey, out=ey)
        np.hypot(ex, ey, out=d)
        inside = self._mask
        np.equal(d, 0.0, out=inside)  # a point on or in the body: push away from the centre
        if inside.any():
            np.copyto(ex, b.px, where=inside)
            np.copyto(ey, b.py, where=inside)
            np.hypot(ex, ey, out=self._work)
            np.maximum(self._work, 1e-9, out=self._work)
            np.divide(ex, self._work, out=ex, where=inside)
            np.divide(ey, self._work, out=ey, where=inside)
        np.maximum(d, 1e-12, out=self._work)
        np.logical_not(inside, out=inside)
        np.divide(ex, self._work, out=ex, where=inside)
        np.divide(ey, self._work, out=ey, where=inside)
        np.greater(d, self.params.influence_m, out=inside)
        np.copyto(d, self.FAR_M, where=inside)  # out of influence: never binding
        self.moved[:] = 0.0
        self.scan_age_s = 0.0

    def filter(self, command: F64, out: F64, scan_age_s: float = 0.0) -> F64:
        """The executed twist for a commanded one (``out`` may be ``command``)."""
        p = self.params
        vx, vy, wz = float(command[TWIST_VX]), float(command[TWIST_VY]), float(command[TWIST_WZ])
        nx, ny, bound, excess = self.nx, self.ny, self.bound, self.excess
        # Clearances now: those of the scan less what the outputs since have driven towards each point,
        # each held for its cycle (the first from the scan's stamp: what came before it is in the scan).
        held = scan_age_s - self.scan_age_s
        if held > 0.0:
            self.moved[0] += float(self.executed[TWIST_VX]) * held
            self.moved[1] += float(self.executed[TWIST_VY]) * held
            self.scan_age_s = scan_age_s
        np.multiply(nx, float(self.moved[0]), out=bound)
        np.multiply(ny, float(self.moved[1]), out=excess)
        bound += excess
        np.subtract(self.clearance, bound, out=bound)
        bound -= p.margin_m
        np.maximum(bound, 0.0, out=bound)
        bound *= p.gain_per_s
        if p.lateral:  # otherwise the scaling alone: the robot only slows
            for _ in range(p.passes):
                k = self._excess(vx, vy)
                s = float(excess[k])
                if not s > 1e-12:
                    break
                vx -= s * float(nx[k])
                vy -= s * float(ny[k])
        # The exact finish: scale towards zero until no constraint is violated (every bound is >= 0).
        k = self._excess(vx, vy)
        if float(excess[k]) > 0.0:
            np.add(excess, bound, out=excess)  # n.v
            np.maximum(excess, 1e-300, out=self._work)
            np.divide(bound, self._work, out=self._work)  # the scale each constraint allows
            np.less_equal(excess, 0.0, out=self._mask)
            np.copyto(self._work, math.inf, where=self._mask)
            scale = min(max(float(self._work.min()), 0.0), 1.0)
            vx, vy = vx * scale, vy * scale
        out[TWIST_VX], out[TWIST_VY], out[TWIST_WZ] = vx, vy, wz
        self.executed[:] = out
        return out

    def _excess(self, vx: float, vy: float) -> int:
        """Fill ``excess`` with n.v - bound for v and return the most violated point."""
        excess, work = self.excess, self._work
        np.multiply(self.nx, vx, out=excess)
        np.multiply(self.ny, vy, out=work)
        excess += work
        excess -= self.bound
        return int(excess.argmax())
