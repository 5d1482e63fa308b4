"""The scan rendered once, beside the haptic loop: filtered ranges and obstacle points in the robot frame.

What the force models and the governor take from a scan depends on the scan alone: the per-beam
filter, and each filtered beam's point in the robot frame. At 15 Hz this is a few hundred
microseconds' worth of numpy passes that, done in the 1 kHz loop, landed in one cycle of every
66 and made the loop's tail. ``ScanField`` does it where the scan arrives (the LIDAR's thread) and
writes a fixed ``(4, n)`` float64 array, one column per raw beam so its size never changes:

``RANGE``  the filtered range (m), NaN where invalid and in the padding
``ANGLE``  the filtered beam's angle (rad, robot frame; 0 in the padding)
``X, Y``   the filtered beam's point in the robot frame (m), ``BeamGeometry.FAR_M`` where invalid

A filter that shortens the scan (the moving average: n → n − w + 1) leaves its last columns as
padding, which every reader treats as a beam that saw nothing. The points are ``BeamGeometry.load``'s
own, so a reader that takes them (``BeamGeometry.load_points``) holds exactly what loading the
filtered ranges itself would give.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from hapticop.devices.ropod.body import Body
from hapticop.haptics.geometry import BeamGeometry
from hapticop.haptics.scan_filter import ScanFilterParams, make_scan_filter

RANGE, ANGLE, X, Y = 0, 1, 2, 3
ROWS = 4


class ScanField:
    """Filter a raw scan and place its points in the robot frame, into a fixed ``(4, n)`` array."""

    def __init__(self, params: ScanFilterParams, raw_angles: ArrayLike, body: Body = Body()) -> None:
        raw = np.asarray(raw_angles, dtype=np.float64)
        self.raw_angles = np.array(raw_angles)  # as given: a reader compares the next scan's with them
        self.n = n = raw.shape[0]
        self.filter = make_scan_filter(params)
        filtered_angles = self.filter.configure(raw)
        self.m = m = filtered_angles.shape[0]  # filtered beams; columns m.. are padding
        self.field = np.zeros((ROWS, n))
        self.field[RANGE].fill(np.nan)
        self.field[ANGLE, :m] = filtered_angles
        self.beams = BeamGeometry(self.field[ANGLE], body)
        self.field[X] = self.beams.px
        self.field[Y] = self.beams.py

    def apply(self, ranges: NDArray[np.floating]) -> NDArray[np.float64]:
        """Render one raw scan (n ranges, NaN where invalid) into ``self.field`` and return it."""
        field, beams = self.field, self.beams
        field[RANGE, : self.m] = self.filter.apply(ranges)
        beams.load(field[RANGE])
        np.copyto(field[X], beams.px)
        np.copyto(field[Y], beams.py)
        return field
