# cython: boundscheck=False, wraparound=False, annotation_typing=False
"""``BeamGeometry``'s passes over the beams as single loops, for the compiled build.

numpy makes each pass over a scan a few whole-array operations, each a C loop of its own behind a
Python call; at 811 beams the calls cost more than the arithmetic. Compiled (``beam_loops.pxd``), each
pass here is one C loop with no call inside, over buffers bound once (no view is made per call, so
nothing is allocated). Interpreted, these loops would be far slower than numpy, so ``BeamGeometry``
uses them only when this module is compiled (``COMPILED``), and numpy otherwise.

Both ways give the same bits (tests/test_compiled_kernels.py): every value is the same IEEE double
operation in the same order as numpy's, a NaN point or shift gives a NaN clearance, and the k-th
smallest is found by the same k passes of a first-minimum ``argmin`` in which a NaN is smallest.
"""

from __future__ import annotations

import importlib.machinery
import math

COMPILED = __file__.endswith(tuple(importlib.machinery.EXTENSION_SUFFIXES))
"""Whether this module runs compiled: only then is it faster than numpy."""

_INF = math.inf  # a C double when compiled, not a lookup in `math` per beam


def _beyond(v: float, low: float, high: float) -> float:
    """How far ``v`` lies outside ``[low, high]``, with its sign: ``v − clip(v, low, high)``. A NaN value
    or bound gives NaN, as numpy's passes do."""
    clipped = v if v >= low else low
    clipped = clipped if clipped <= high else high
    return v - clipped


class BeamBuffers:
    """The arrays one ``BeamGeometry`` keeps, bound once: points ``px``, ``py``, which are ``valid``
    (a ``np.bool_`` array's bytes, viewed as ``np.uint8``), a scratch ``work`` and the side selections
    ``left`` and ``right`` (0 selected, inf not). All contiguous, of one length; the passes write
    ``work`` and the selections in place."""

    def __init__(self, px, py, valid, work, left, right) -> None:
        n = px.shape[0]
        if any(array.shape[0] != n for array in (py, valid, work, left, right)):
            raise ValueError(f"every beam buffer must hold the {n} points")
        self.n = n
        self.px, self.py, self.valid, self.work, self.left, self.right = px, py, valid, work, left, right

    def kth_smallest(self, lo: int, hi: int, k: int) -> float:
        """The k-th smallest of ``work[lo:hi]`` (``inf`` if the span holds fewer than k values), taking each
        smallest out as ``geometry.kth_smallest`` does: k passes of a first-minimum argmin, NaN smallest."""
        if lo < 0 or hi > self.n:
            raise IndexError(f"span {lo}:{hi} outside {self.n} beams")
        work = self.work
        value = _INF
        for _ in range(k):
            if hi <= lo:
                return _INF
            best = lo
            low = work[lo]
            if low == low:
                for i in range(lo + 1, hi):
                    v = work[i]
                    if v != v:
                        best, low = i, v
                        break
                    if v < low:
                        best, low = i, v
            value = low
            work[best] = _INF
        return value

    def corridor_kth(self, limit_y: float, half_length: float, k: int) -> float:
        """The k-th smallest ``p_x − L/2`` of the valid points with ``|p_y| ≤ limit_y`` and ``p_x > L/2``."""
        px, py, valid, work = self.px, self.py, self.valid, self.work
        for i in range(self.n):
            x = px[i]
            if valid[i] and abs(py[i]) <= limit_y and x > half_length:
                work[i] = x - half_length
            else:
                work[i] = _INF
        return self.kth_smallest(0, self.n, k)

    def select_sides(self, x_low: float, x_high: float, half_width: float) -> None:
        """0 in ``left`` (``right``) for each valid point in the window ``x_low ≤ p_x ≤ x_high`` beyond the
        body's left (right) side, ``inf`` elsewhere."""
        px, py, valid, left, right = self.px, self.py, self.valid, self.left, self.right
        for i in range(self.n):
            x, y = px[i], py[i]
            inside = valid[i] and x >= x_low and x <= x_high
            left[i] = 0.0 if inside and y > half_width else _INF
            right[i] = 0.0 if inside and y < -half_width else _INF

    def side_kth_squared(self, left_side: bool, lo: int, hi: int, shift_x: float, shift_y: float,
                         half_length: float, half_width: float, k: int) -> float:
        """The k-th smallest squared clearance of the selected points ``lo:hi`` of one side from the body
        moved by the shift: ``geometry.BeamGeometry.side_clearances`` for that side."""
        if lo < 0 or hi > self.n:
            raise IndexError(f"span {lo}:{hi} outside {self.n} beams")
        px, py, work = self.px, self.py, self.work
        penalty = self.left if left_side else self.right
        x_low, x_high = shift_x - half_length, shift_x + half_length
        y_low, y_high = shift_y - half_width, shift_y + half_width
        for i in range(lo, hi):
            ex = _beyond(px[i], x_low, x_high)
            ey = _beyond(py[i], y_low, y_high)
            work[i] = (ex * ex + ey * ey) + penalty[i]
        return self.kth_smallest(lo, hi, k)
