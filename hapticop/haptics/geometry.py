"""Robot footprint and the fixed beam geometry of a scan, shared by the M1 field and the governor.

The thesis models the robot as a point at the LIDAR; the notes (hallway-experiment.md §1 item 4,
§9) measure clearance from the robot's rectangular body instead: for a 0.6 m wide robot a wall
0.3 m beside the scanner is touching. Beam directions depend only on the scan angles, so their
cosines and sines are computed once; a scan then costs a few numpy passes into preallocated
arrays. Robot frame: x forward, y left (REP 103), origin at the footprint centre.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray


@dataclass(frozen=True)
class Footprint:
    """Rectangular robot body and where the LIDAR sits on it (notes §2; replace with the ropod's)."""

    length_m: float = 0.70
    """Along x."""
    width_m: float = 0.60
    """Along y."""
    lidar_x_m: float = 0.25
    """Scanner origin ahead of the footprint centre."""
    lidar_y_m: float = 0.0
    """Scanner origin left of the footprint centre."""


def kth_smallest(work: NDArray[np.float64], k: int) -> float:
    """k-th smallest value of ``work`` (``inf`` if fewer than k finite ones); destroys ``work``.

    A robust minimum (notes §9: "never take a bare max over raw beams"): up to k − 1 outlier
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

    ``angles`` are beam directions in the robot frame (rad, 0 ahead, + left); ranges are measured
    from the scanner origin given by ``footprint``. Per scan: ``load``, then ``corridor_gap`` and
    ``select_sides``; per servo cycle (depends on the robot's velocity): ``side_clearances``.
    Invalid beams (NaN) are parked far away and excluded from every selection, so no NaN
    reaches the arithmetic.
    """

    FAR_M = 1.0e6
    """Where invalid beams are parked."""

    def __init__(self, angles: ArrayLike, footprint: Footprint = Footprint()) -> None:
        a = np.asarray(angles, dtype=np.float64)
        n = a.shape[0]
        self.footprint = footprint
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
        # The side points, left ones first, packed by ``select_sides`` so that ``side_clearances``
        # works on them alone; the views of them are remade when a scan packs another number.
        self._side_px = np.empty(n + 1)  # the last slot takes every point not selected
        self._side_py = np.empty(n + 1)
        self._index = np.empty(n, dtype=np.intp)
        self._m3 = np.empty(n, dtype=bool)
        self._select_sides_views(0, 0)

    def load(self, ranges: NDArray[np.floating]) -> None:
        """Scan points in the robot frame into ``px``, ``py``."""
        fp, r, valid = self.footprint, self.ranges, self._valid
        np.copyto(r, ranges)  # float32 → float64 once, so no ufunc below needs a cast buffer
        np.less(r, self.FAR_M, out=valid)  # False for NaN
        np.logical_not(valid, out=self._m1)
        np.copyto(r, self.FAR_M, where=self._m1)
        np.multiply(r, self.cos, out=self.px)
        self.px += fp.lidar_x_m
        np.multiply(r, self.sin, out=self.py)
        self.py += fp.lidar_y_m
        self._dy_shift = math.nan  # new points: the cached lateral term is stale

    def corridor_gap(self, margin_m: float, k: int) -> float:
        """Robust distance from the footprint's front to the obstacles in the driving corridor.

        Corridor (notes §9.1): ``|p_y| ≤ W/2 + margin`` and ``p_x > L/2``; the gap is the k-th
        smallest ``p_x − L/2`` there, ``inf`` if fewer than k beams hit it.
        """
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
        ``−L/2 − rear ≤ p_x ≤ L/2 + ahead`` (notes §9.1). They are packed, left then right, into
        work arrays of their own, so the per-cycle clearances touch only them.
        """
        win, side, px, py = self._m1, self._m2, self.px, self.py
        np.greater_equal(px, -self.half_length - rear_m, out=win)
        np.less_equal(px, self.half_length + ahead_m, out=side)
        win &= side
        win &= self._valid
        np.greater(py, self.half_width, out=side)
        side &= win
        n_left = self._pack(side, 0)
        np.less(py, -self.half_width, out=side)
        side &= win
        n_right = self._pack(side, n_left)
        self._select_sides_views(n_left, n_right)

    def _pack(self, mask: NDArray[np.bool_], start: int) -> int:
        """Copy the points under ``mask``, in beam order, into the side arrays from ``start`` on.

        Allocation-free packing (``np.compress`` allocates): each selected point's destination is
        a running count; the others all go to the spare last slot. Returns how many were packed.
        """
        index = self._index
        np.copyto(index, mask)
        np.add.accumulate(index, out=index)
        count = int(index[-1])
        index += start - 1
        np.logical_not(mask, out=self._m3)
        np.copyto(index, self.n, where=self._m3)
        np.put(self._side_px, index, self.px)
        np.put(self._side_py, index, self.py)
        return count

    def _select_sides_views(self, n_left: int, n_right: int) -> None:
        self._dy_shift = math.nan  # other points: the cached lateral term is stale
        if (n_left, n_right) == getattr(self, "_sel_counts", None):
            return  # the views of the last scan fit
        self._sel_counts = (n_left, n_right)
        n = n_left + n_right
        self._n_left, self._n_right = n_left, n_right
        self._sel_px, self._sel_py = self._side_px[:n], self._side_py[:n]
        self._sel_dx, self._sel_dy = self._dx[:n], self._dy[:n]
        self._sel_left, self._sel_right = self._work[:n_left], self._work[n_left:n]
        self._sel_work = self._work[:n]

    def side_clearances(self, shift_x_m: float, shift_y_m: float, k: int) -> tuple[float, float]:
        """Robust footprint clearance on the left and the right after the robot translates by a shift.

        The clearance ``‖max(|p − s| − h, 0)‖`` of each selected point is evaluated with the
        points moved by ``−s``: the body's clearance after it translates by ``s``. ``s = v·T_p``
        gives the notes' predicted clearance ``c + T_p·ċ`` exactly for a straight wall (and for a
        parallel wall it stays constant, where a linearisation would not). Returns
        ``(c_left, c_right)``, ``inf`` where fewer than k points are selected.
        """
        dx, dy, work = self._sel_dx, self._sel_dy, self._sel_work
        np.subtract(self._sel_px, shift_x_m, out=dx)
        np.abs(dx, out=dx)
        dx -= self.half_length
        np.maximum(dx, 0.0, out=dx)
        dx *= dx
        if shift_y_m != self._dy_shift:  # the car map never moves sideways: often cached
            np.subtract(self._sel_py, shift_y_m, out=dy)
            np.abs(dy, out=dy)
            dy -= self.half_width
            np.maximum(dy, 0.0, out=dy)
            dy *= dy
            self._dy_shift = shift_y_m
        np.add(dx, dy, out=work)  # squared clearance; the square root is taken of the k-th smallest only
        left = kth_smallest(self._sel_left, k) if self._n_left >= k else math.inf
        right = kth_smallest(self._sel_right, k) if self._n_right >= k else math.inf
        return math.sqrt(left), math.sqrt(right)
