"""The fixed beam geometry of a scan seen from the robot's body, shared by the M1 field and the governor.

The thesis models the robot as a point at the LIDAR; docs/hallway-experiment.md (docs/hallway-experiment.md §1 item 4,
§9) measure clearance from the robot's rectangular body instead: for a 0.6 m wide robot a wall
0.3 m beside the scanner is touching. The body (footprint and LIDAR mount) is the robot's one
description in ``hapticop.devices.ropod.body``. Beam directions depend only on the scan angles,
so their cosines and sines are computed once; a scan then costs a few numpy passes into
preallocated arrays, or one C loop each where ``beam_loops`` is compiled. Robot frame: x forward,
y left (REP 103), origin at the footprint centre.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike, NDArray

from hapticop.devices.ropod.body import Body
from hapticop.haptics import beam_loops


def kth_smallest(work: NDArray[np.float64], k: int) -> float:
    """k-th smallest value of ``work`` (``inf`` if fewer than k finite ones); destroys ``work``.

    A robust minimum (docs/hallway-experiment.md §9: "never take a bare max over raw beams"): up to k − 1 outlier
    beams cannot set it. Non-members must already be ``inf`` in ``work``. k passes of argmin:
    for the small k used here this beats ``ndarray.partition``, which allocates per call.
    """
    value = math.inf
    for _ in range(k):
        i = int(work.argmin())
        value = float(work[i])
        work[i] = math.inf
    return value


class BeamGeometry:
    """Points of one scan in the robot frame and the clearances M1 and S1 need.

    ``angles`` are beam directions in the robot frame (rad, 0 ahead, + left: the mount's yaw is
    already in them); ranges are measured from the scanner origin, ``body.lidar``. Per scan:
    ``load``, then ``corridor_gap`` and ``select_sides``; per servo cycle (depends on the robot's
    velocity): ``side_clearances``.
    Invalid beams (NaN) are parked far away and excluded from every selection, so no NaN
    reaches the arithmetic.
    """

    FAR_M = 1.0e6
    """Where invalid beams are parked."""

    def __init__(self, angles: ArrayLike, body: Body = Body()) -> None:
        a = np.asarray(angles, dtype=np.float64)
        n = a.shape[0]
        self.body = body
        footprint = body.footprint
        self.n = n
        self.half_length = footprint.length_m / 2.0
        self.half_width = footprint.width_m / 2.0
        self.cos = np.cos(a)
        self.sin = np.sin(a)
        self.ranges = np.full(n, self.FAR_M)
        self.px = np.full(n, self.FAR_M)  # no scan yet: nothing near
        self.py = np.full(n, self.FAR_M)
        self._dx = np.empty(n)
        self._dy = np.empty(n)
        self._work = np.empty(n)
        self._valid = np.empty(n, dtype=bool)
        self._m1 = np.empty(n, dtype=bool)
        self._m2 = np.empty(n, dtype=bool)
        self._dy_shift = math.nan
        self._corridor = (math.nan, 0, math.inf)
        self._left_penalty = np.full(n, math.inf)
        self._right_penalty = np.full(n, math.inf)
        # With the scanner on the body (|lidar_y| < W/2), a point left of the body (p_y > W/2) lies on
        # a beam with sin > 0 and one right of it on a beam with sin < 0: each side's k-th smallest
        # need only search the span of beams that can hold its points (half a scan, ascending angles).
        left, right = self._span(self.sin > 0.0), self._span(self.sin < 0.0)
        if not abs(body.lidar.y_m) < self.half_width:
            left = right = slice(0, n)
        self._side_views = tuple((self._dx[span], penalty[span], self._work[span])
                                 for span, penalty in ((left, self._left_penalty), (right, self._right_penalty)))
        self._side_spans = ((left.start, left.stop), (right.start, right.stop))
        self._loops = (beam_loops.BeamBuffers(self.px, self.py, self._valid.view(np.uint8), self._work,
                                              self._left_penalty, self._right_penalty)
                       if beam_loops.COMPILED else None)
        """The compiled passes over these arrays, or None for numpy's: the same bits either way
        (tests/test_compiled_kernels.py)."""

    @staticmethod
    def _span(beams: NDArray[np.bool_]) -> slice:
        """The smallest slice holding every True beam (empty if none)."""
        where = np.flatnonzero(beams)
        return slice(int(where[0]), int(where[-1]) + 1) if where.size else slice(0, 0)

    def load(self, ranges: NDArray[np.floating]) -> None:
        """Scan points in the robot frame into ``px``, ``py``."""
        lidar, r, valid = self.body.lidar, self.ranges, self._valid
        np.copyto(r, ranges)  # float32 → float64 once, so no ufunc below needs a cast buffer
        np.less(r, self.FAR_M, out=valid)  # False for NaN
        np.logical_not(valid, out=self._m1)
        np.copyto(r, self.FAR_M, where=self._m1)
        np.multiply(r, self.cos, out=self.px)
        if lidar.x_m:
            self.px += lidar.x_m
        np.multiply(r, self.sin, out=self.py)
        if lidar.y_m:  # usually on the centre line: nothing to add
            self.py += lidar.y_m
        self._forget()

    def load_points(self, field: NDArray[np.float64]) -> None:
        """Take points another ``BeamGeometry`` loaded (a ``hapticop.haptics.scan_field`` array: rows
        range, angle, x, y): what ``load`` of its ranges would give, for the price of two copies."""
        np.less(field[0], self.FAR_M, out=self._valid)  # False for NaN
        np.copyto(self.px, field[2])
        np.copyto(self.py, field[3])
        self._forget()

    def _forget(self) -> None:
        """New points: what was cached of the last ones is stale."""
        self._dy_shift = math.nan  # the cached lateral term
        self._corridor = (math.nan, 0, math.inf)  # (margin, k, gap) of the last corridor_gap: none yet

    def corridor_gap(self, margin_m: float, k: int) -> float:
        """Robust distance from the footprint's front to the obstacles in the driving corridor.

        Corridor (docs/hallway-experiment.md §9.1): ``|p_y| ≤ W/2 + margin`` and ``p_x > L/2``; the gap is the k-th
        smallest ``p_x − L/2`` there, ``inf`` if fewer than k beams hit it. Kept per scan: the
        braking field and the governor usually ask for the same corridor.
        """
        last_margin, last_k, last_gap = self._corridor
        if margin_m == last_margin and k == last_k:
            return last_gap
        if self._loops is not None:
            gap = self._loops.corridor_kth(self.half_width + margin_m, self.half_length, k)
        else:
            gap = self._corridor_numpy(margin_m, k)
        self._corridor = (margin_m, k, gap)
        return gap

    def _corridor_numpy(self, margin_m: float, k: int) -> float:
        inside, ahead, work = self._m1, self._m2, self._work
        np.abs(self.py, out=self._dx)
        np.less_equal(self._dx, self.half_width + margin_m, out=inside)
        np.greater(self.px, self.half_length, out=ahead)
        inside &= ahead
        inside &= self._valid
        np.logical_not(inside, out=inside)
        np.subtract(self.px, self.half_length, out=work)
        np.copyto(work, math.inf, where=inside)
        return kth_smallest(work, k)

    def select_sides(self, rear_m: float, ahead_m: float) -> None:
        """Choose the side points for ``side_clearances``: beside or diagonal to the body now.

        Left: ``p_y > W/2``, right: ``p_y < −W/2``, both inside the window
        ``−L/2 − rear ≤ p_x ≤ L/2 + ahead`` (docs/hallway-experiment.md §9.1). Stored as additive penalties
        (0 selected, inf not), so the per-cycle selection is one addition.
        """
        if self._loops is not None:
            self._loops.select_sides(-self.half_length - rear_m, self.half_length + ahead_m, self.half_width)
            return
        win, side, px, py = self._m1, self._m2, self.px, self.py
        np.greater_equal(px, -self.half_length - rear_m, out=win)
        np.less_equal(px, self.half_length + ahead_m, out=side)
        win &= side
        win &= self._valid
        np.greater(py, self.half_width, out=side)
        side &= win
        self._left_penalty.fill(math.inf)
        np.copyto(self._left_penalty, 0.0, where=side)
        np.less(py, -self.half_width, out=side)
        side &= win
        self._right_penalty.fill(math.inf)
        np.copyto(self._right_penalty, 0.0, where=side)

    def side_clearances(self, shift_x_m: float, shift_y_m: float, k: int) -> tuple[float, float]:
        """Robust footprint clearance on the left and the right after the robot translates by a shift.

        The clearance ``‖max(|p − s| − h, 0)‖`` of each selected point is evaluated with the
        points moved by ``−s``: the body's clearance after it translates by ``s``. ``s = v·T_p``
        gives docs/hallway-experiment.md's predicted clearance ``c + T_p·ċ`` exactly for a straight wall (and for a
        parallel wall it stays constant, where a linearisation would not). Returns
        ``(c_left, c_right)``, ``inf`` where fewer than k points are selected.
        """
        dx, dy, hl, hw = self._dx, self._dy, self.half_length, self.half_width
        loops = self._loops
        if loops is not None:
            (left_lo, left_hi), (right_lo, right_hi) = self._side_spans
            left = loops.side_kth_squared(True, left_lo, left_hi, shift_x_m, shift_y_m, hl, hw, k)
            right = loops.side_kth_squared(False, right_lo, right_hi, shift_x_m, shift_y_m, hl, hw, k)
            return math.sqrt(left), math.sqrt(right)
        # How far each point lies beyond the moved body along x: p − clip(p, s − h, s + h), which is
        # max(|p − s| − h, 0) with its sign, in three passes instead of four.
        np.maximum(self.px, shift_x_m - hl, out=dx)
        np.minimum(dx, shift_x_m + hl, out=dx)
        np.subtract(self.px, dx, out=dx)
        dx *= dx
        if shift_y_m != self._dy_shift:  # the car map never moves sideways: the governor's is cached
            np.maximum(self.py, shift_y_m - hw, out=dy)
            np.minimum(dy, shift_y_m + hw, out=dy)
            np.subtract(self.py, dy, out=dy)
            dy *= dy
            self._dy_shift = shift_y_m
        dx += dy  # squared clearance; the square root is taken of the k-th smallest only
        (left_dx, left_penalty, left_work), (right_dx, right_penalty, right_work) = self._side_views
        np.add(left_dx, left_penalty, out=left_work)
        left = kth_smallest(left_work, k) if left_work.shape[0] else math.inf
        np.add(right_dx, right_penalty, out=right_work)
        right = kth_smallest(right_work, k) if right_work.shape[0] else math.inf
        return math.sqrt(left), math.sqrt(right)
