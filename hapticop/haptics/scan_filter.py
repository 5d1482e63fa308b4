"""Per-beam denoising of a LIDAR scan: the thesis's moving average, and a 5-beam median.

Thesis §5.3.2: "a small moving average filter with a window of 3 samples (truncated endpoint)
... resulting in a data output size of 809 points per scan ... and a small offset in the
scanning angle". Truncated endpoints means only full windows are kept (811 − 3 + 1 = 809).
Output ``i`` averages beams ``i .. i+w−1``, so it belongs to the centre beam ``i + (w−1)/2``.
Pairing it with ``angles[i]`` (the first 809 angles) is the angle offset the thesis mentions:
``(w−1)/2`` beam steps, 0.333° for the TiM561. ``MovingAverage.angles`` gives the centres.

Invalid beams are NaN (the LIDAR block's convention). A window averages only its valid beams;
it is NaN when fewer than ``min_valid`` are valid, so one dropout neither erases nor invents
an obstacle.

Both filters work into preallocated arrays: ``configure`` once per scan geometry (it returns the
filtered points' angles), then ``apply`` per scan allocates nothing. Their parameter sets are
told apart by ``kind``; ``make_scan_filter`` builds the one they name.
"""

from __future__ import annotations

from typing import Annotated, Literal

import numpy as np
from annotated_types import Ge, Predicate
from numpy.typing import ArrayLike, NDArray

from hapticop.parameters import parameters


def odd(n: int) -> bool:
    return n % 2 == 1


@parameters
class MovingAverageParams:
    """The thesis's moving average (§5.3.2): n beams give n − window + 1 points."""

    window: Annotated[int, Ge(1)] = 3
    """Beams per window (811 beams give 809 points with 3)."""
    min_valid: Annotated[int, Ge(1)] = 1
    """A window with fewer valid beams is NaN (no obstacle); at most ``window``."""
    kind: Literal["moving_average"] = "moving_average"
    """Names this filter where several may be chosen."""

    def __post_init__(self) -> None:
        if self.min_valid > self.window:
            raise ValueError(f"min_valid {self.min_valid} is more than the window {self.window}")


@parameters
class MovingMedianParams:
    """A running median that keeps the scan length and rejects single-beam outliers (docs/hallway-experiment.md §9)."""

    window: Annotated[int, Ge(1), Predicate(odd)] = 5
    """Beams per window, odd; the window // 2 beams at each end have no full window and read as invalid."""
    kind: Literal["moving_median"] = "moving_median"
    """Names this filter where several may be chosen."""


ScanFilterParams = MovingAverageParams | MovingMedianParams
"""The parameters of one scan filter; their ``kind`` says which."""


class MovingAverage:
    """NaN-aware moving average with truncated endpoints (n beams → n − w + 1)."""

    def __init__(self, window: int = 3, min_valid: int = 1) -> None:
        if window < 1:
            raise ValueError("window must be at least 1")
        if not 1 <= min_valid <= window:
            raise ValueError("min_valid must be in 1..window")
        self.window = window
        self.min_valid = min_valid
        self.angles: NDArray[np.float64] = np.zeros(0)
        self.out: NDArray[np.float64] = np.zeros(0)

    @property
    def size(self) -> int:
        """Number of filtered points (809 for an 811-beam scan and w = 3)."""
        return self.out.shape[0]

    @property
    def centre_shift_beams(self) -> float:
        """Output ``i`` is centred on input beam ``i + centre_shift_beams``: (w − 1)/2."""
        return (self.window - 1) / 2.0

    @property
    def angle_offset_rad(self) -> float:
        """Angle error made by pairing output ``i`` with ``angles[i]``: (w − 1)/2 beam steps."""
        return self._offset

    def configure(self, angles: ArrayLike) -> NDArray[np.float64]:
        """Fix the scan geometry; returns the filtered points' angles (window centres)."""
        a = np.asarray(angles, dtype=np.float64)
        n = a.shape[0]
        w = self.window
        if n < w:
            raise ValueError(f"a scan of {n} beams is shorter than the window {w}")
        m = n - w + 1
        self.n = n
        self.angles = _window_mean(a, w)
        self._offset = float(self.angles[0] - a[0])
        self.out = np.empty(m)
        self._values = np.empty(n)
        self._valid = np.empty(n)
        self._isnan = np.empty(n, dtype=bool)
        self._count = np.empty(m)
        self._empty = np.empty(m, dtype=bool)
        # The windows' j-th members as views, made once: slicing per scan costs more than adding.
        self._shifted = [(self._values[j : j + m], self._valid[j : j + m]) for j in range(w)]
        return self.angles

    def apply(self, ranges: NDArray[np.floating]) -> NDArray[np.float64]:
        """Filter one scan; returns ``self.out`` (overwritten by the next call)."""
        vals, valid, isnan, out, count = self._values, self._valid, self._isnan, self.out, self._count
        np.copyto(vals, ranges)
        np.isnan(vals, out=isnan)
        np.copyto(valid, isnan)  # 1.0 where invalid ...
        np.subtract(1.0, valid, out=valid)  # ... and now where valid
        np.copyto(vals, 0.0, where=isnan)
        (first_vals, first_valid), *rest = self._shifted
        np.copyto(out, first_vals)
        np.copyto(count, first_valid)
        for shifted_vals, shifted_valid in rest:
            out += shifted_vals
            count += shifted_valid
        np.less(count, self.min_valid - 0.5, out=self._empty)
        np.maximum(count, 1.0, out=count)
        out /= count
        np.copyto(out, np.nan, where=self._empty)
        return out


class MovingMedian:
    """5-beam (odd ``window``) running median that keeps the scan length: rejects single-beam outliers.

    docs/hallway-experiment.md §9 "common preprocessing". The ``window // 2`` beams at each end have
    no full window, so they are NaN (no return): passed through, a phantom there went unvoted and,
    inside the robot's own footprint, stopped a safety filter dead (§10.2). NaN sorts last, so a
    window is NaN when most of it is invalid; with a minority of NaN the result is an upper median
    of the valid beams.
    """

    def __init__(self, window: int = 5) -> None:
        if window < 1 or window % 2 == 0:
            raise ValueError("window must be odd and positive")
        self.window = window
        self.out: NDArray[np.float64] = np.zeros(0)

    def configure(self, angles: ArrayLike) -> NDArray[np.float64]:
        """Allocate for scans of these beams; returns their angles (the scan keeps its length)."""
        a = np.array(angles, dtype=np.float64)
        n = a.shape[0]
        if n < self.window:
            raise ValueError(f"a scan of {n} beams is shorter than the window {self.window}")
        self.out = np.empty(n)
        self._rows = np.empty((n - self.window + 1, self.window))
        return a

    def apply(self, ranges: NDArray[np.floating]) -> NDArray[np.float64]:
        """Filter one scan; returns ``self.out`` (overwritten by the next call)."""
        w, h, out, rows = self.window, self.window // 2, self.out, self._rows
        m = rows.shape[0]
        np.copyto(out, ranges)
        if w == 1:
            return out
        for j in range(w):
            np.copyto(rows[:, j], out[j : j + m])
        rows.partition(h, axis=1)
        np.copyto(out[h : h + m], rows[:, h])
        out[:h] = np.nan
        out[h + m :] = np.nan
        return out


def make_scan_filter(params: ScanFilterParams) -> MovingAverage | MovingMedian:
    """The filter its parameters name."""
    if isinstance(params, MovingMedianParams):
        return MovingMedian(params.window)
    return MovingAverage(params.window, params.min_valid)


def _window_mean(a: NDArray[np.float64], w: int) -> NDArray[np.float64]:
    m = a.shape[0] - w + 1
    acc = a[:m].copy()
    for j in range(1, w):
        acc += a[j : j + m]
    return acc / w
