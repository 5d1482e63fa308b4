"""The thesis's 3-sample moving average (811 → 809, angle offset, NaN beams) and the 5-beam median."""

import math

import numpy as np
import pytest

from hapticop.haptics.scan_filter import MovingAverage, MovingMedian

from .scans import tim561_angles
from .test_haptics_handle import assert_no_allocation

RAW = tim561_angles(811)
STEP = RAW[1] - RAW[0]


def configured(window=3, min_valid=1):
    f = MovingAverage(window, min_valid)
    f.configure(RAW)
    return f


def test_811_beams_give_809_points_each_the_mean_of_three_neighbours():
    f = configured()
    ranges = np.random.default_rng(1).uniform(0.05, 10.0, 811)
    out = f.apply(ranges)
    assert f.size == out.shape[0] == f.angles.shape[0] == 809
    np.testing.assert_allclose(out, (ranges[:-2] + ranges[1:-1] + ranges[2:]) / 3.0)


def test_the_points_sit_at_the_window_centres_and_the_thesis_offset_is_one_beam():
    f = configured()
    np.testing.assert_allclose(f.angles, RAW[1:-1], atol=1e-12)
    assert f.centre_shift_beams == 1.0
    assert f.angle_offset_rad == pytest.approx(STEP)
    assert math.degrees(f.angle_offset_rad) == pytest.approx(270.0 / 810.0)  # 0.333°
    # A single near return at beam j shows up at the output whose centre is beam j.
    j = 400
    ranges = np.full(811, 3.0)
    ranges[j] = 0.0
    out = f.apply(ranges)
    spread = np.flatnonzero(out < 3.0)
    np.testing.assert_array_equal(spread, [j - 2, j - 1, j])
    assert f.angles[j - 1] == pytest.approx(RAW[j])


def test_wider_windows_truncate_more_and_shift_further():
    f = configured(window=5)
    assert f.size == 807
    assert f.angle_offset_rad == pytest.approx(2 * STEP)
    one = configured(window=1)
    r = np.linspace(1, 2, 811)
    np.testing.assert_array_equal(one.apply(r), r)


def test_invalid_beams_are_left_out_of_the_mean():
    f = configured()
    r = np.full(811, 2.0)
    r[10] = 1.0
    r[11] = np.nan
    out = f.apply(r)
    assert out[9] == pytest.approx((2.0 + 1.0) / 2)  # beams 9, 10, (11 invalid)
    assert out[10] == pytest.approx((1.0 + 2.0) / 2)  # beams 10, (11), 12
    assert out[11] == pytest.approx(2.0)  # beams (11), 12, 13
    r[100:103] = np.nan
    out = f.apply(r)
    assert np.isnan(out[100]) and not np.isnan(out[99]) and not np.isnan(out[101])
    assert np.isnan(out).sum() == 1


def test_min_valid_marks_thin_windows_invalid():
    f = configured(min_valid=2)
    r = np.full(811, 2.0)
    r[[50, 51]] = np.nan
    out = f.apply(r)
    assert np.isnan(out[49]) and np.isnan(out[50])  # windows 49..51 and 50..52 have one valid beam
    assert out[48] == pytest.approx(2.0)
    assert out[51] == pytest.approx(2.0)


def test_float32_scans_are_accepted():
    f = configured()
    out = f.apply(np.full(811, 1.5, dtype=np.float32))
    assert out.dtype == np.float64
    np.testing.assert_allclose(out, 1.5)


def test_median_rejects_single_beam_outliers_and_keeps_the_scan_length():
    m = MovingMedian(5)
    m.configure(RAW)
    r = np.full(811, 4.0)
    r[300] = 0.4  # spurious return
    r[1] = 0.07  # a phantom at the end of the scan: no full window votes for it
    out = m.apply(r)
    assert out.shape == (811,)
    assert out[300] == 4.0
    assert np.isnan(out[:2]).all() and np.isnan(out[-2:]).all() and out[2] == 4.0 and out[-3] == 4.0
    r[500:503] = 1.0  # three beams: a real (thin) object survives
    assert m.apply(r)[501] == 1.0


def test_median_is_nan_only_where_most_of_the_window_is_invalid():
    m = MovingMedian(5)
    m.configure(RAW)
    r = np.full(811, 4.0)
    r[200] = np.nan
    r[400:403] = np.nan
    out = m.apply(r)
    assert out[200] == 4.0
    assert np.isnan(out[401])
    assert not np.isnan(out[399]) and not np.isnan(out[403])


def test_the_filters_allocate_nothing_per_scan():
    f = configured()
    scan = np.random.default_rng(2).uniform(0.05, 10.0, 811).astype(np.float32)
    scan[::7] = np.nan
    assert_no_allocation(lambda: f.apply(scan))
    m = MovingMedian()
    m.configure(RAW)
    # numpy's partition allocates a ~3 kB temporary itself; no growth (runs once per scan).
    assert_no_allocation(lambda: m.apply(scan), peak_limit=4096)
