"""Centring PD, per-axis saturation, dead zone and the car-driving map (thesis §5.2, §5.3.1)."""

import math

import numpy as np
import pytest

from hapticop.haptics.handle import (
    HANDLE_Z,
    TWIST_VX,
    TWIST_VY,
    TWIST_WZ,
    CentringParams,
    CentringPD,
    DrivingParams,
    dead_zone,
    handle_to_twist,
    saturate,
)
from hapticop.testing import allocation_stats


def test_pd_pulls_the_handle_back_to_its_origin_with_the_thesis_gains():
    pd = CentringPD()
    out = np.zeros(3)
    pd.compute(np.array([0.01, -0.002, -0.02]), out, velocity=np.zeros(3))
    np.testing.assert_allclose(out, [-0.55, 0.11, 1.10])  # Kp = 55 N/m, towards the origin
    pd.compute(np.zeros(3), out, velocity=np.zeros(3))
    np.testing.assert_array_equal(out, 0.0)


def test_pd_damps_the_handle_velocity_in_ns_per_m():
    pd = CentringPD()
    out = np.zeros(3)
    pd.compute(np.zeros(3), out, velocity=np.array([0.1, 0.0, -0.5]))
    np.testing.assert_allclose(out, [-0.02, 0.0, 0.1])  # Kd = 0.2 N·s/m


def test_pd_differences_positions_when_no_velocity_is_given():
    pd = CentringPD(CentringParams(period_s=0.001))
    out = np.zeros(3)
    pd.compute(np.array([0.0, 0.0, 0.0]), out)  # first sample: no velocity yet
    np.testing.assert_array_equal(out, 0.0)
    pd.compute(np.array([0.0, 0.0, -0.001]), out)  # -1 m/s along z
    np.testing.assert_allclose(out[HANDLE_Z], 55 * 0.001 + 0.2 * 1.0)
    pd.reset()
    pd.compute(np.array([0.0, 0.0, -0.001]), out)
    np.testing.assert_allclose(out[HANDLE_Z], 55 * 0.001)


def test_pd_saturates_each_axis_separately_after_adding_the_environmental_force():
    pd = CentringPD()
    out = np.zeros(3)
    pd.compute(np.array([0.5, 0.01, -0.05]), out, velocity=np.zeros(3), env_force=np.array([0.0, 0.0, 8.0]))
    np.testing.assert_allclose(out, [-10.0, -0.55, 10.0])  # x and z clip at 10 N, y untouched
    f = np.array([12.0, -15.0, 3.0])
    saturate(f, 10.0)
    np.testing.assert_array_equal(f, [10.0, -10.0, 3.0])


def test_pd_holds_a_configurable_origin():
    pd = CentringPD(origin=(0.0, 0.0, 0.125))
    out = np.zeros(3)
    pd.compute(np.array([0.0, 0.0, 0.125]), out, velocity=np.zeros(3))
    np.testing.assert_array_equal(out, 0.0)


@pytest.mark.parametrize("subtractive", [True, False])
def test_dead_zone_is_zero_up_to_and_including_its_edge(subtractive):
    for u in (0.0, 0.004, 0.005, -0.005, -0.0049):
        assert dead_zone(u, 0.005, subtractive) == 0.0


def test_subtractive_dead_zone_is_continuous_and_the_thesis_one_jumps_by_its_width():
    eps = 1e-9
    assert dead_zone(0.005 + eps, 0.005) == pytest.approx(eps, abs=1e-15)
    assert dead_zone(-0.005 - eps, 0.005) == pytest.approx(-eps, abs=1e-15)
    assert dead_zone(0.02, 0.005) == pytest.approx(0.015)
    assert dead_zone(0.005 + eps, 0.005, subtractive=False) == pytest.approx(0.005)  # the jump
    assert dead_zone(-0.02, 0.005, subtractive=False) == -0.02


def twist(x=0.0, y=0.0, z=0.0, params=DrivingParams()):
    return handle_to_twist(np.array([x, y, z]), np.full(3, np.nan), params)


def test_pushing_the_handle_away_drives_forward_and_pulling_it_drives_backward():
    assert twist(z=-0.015)[TWIST_VX] == pytest.approx(28 * 0.010)  # forward = -z, k1 = 28
    assert twist(z=+0.015)[TWIST_VX] == pytest.approx(-28 * 0.010)
    assert twist(z=-0.015)[TWIST_WZ] == 0.0
    thesis = DrivingParams(subtractive_dead_zone=False)
    assert twist(z=-0.015, params=thesis)[TWIST_VX] == pytest.approx(28 * 0.015)  # eq. 5.3 literally


def test_handle_right_turns_right_which_is_clockwise_in_the_robot_frame():
    # Thesis fig. 5.5: x > 0 turns right; the robot twist is counter-clockwise positive.
    assert twist(x=+0.015)[TWIST_WZ] == pytest.approx(-10 * 0.010)
    assert twist(x=-0.015)[TWIST_WZ] == pytest.approx(+10 * 0.010)
    assert twist(x=-0.015)[TWIST_VX] == 0.0


def test_the_map_never_commands_sideways_motion_and_ignores_y():
    t = twist(x=0.03, y=0.04, z=-0.03)
    assert t[TWIST_VY] == 0.0
    np.testing.assert_allclose(t, [28 * 0.025, 0.0, -10 * 0.025])


def test_the_dead_zone_edges_give_no_motion():
    for x, z in [(0.005, 0.0), (0.0, -0.005), (-0.005, 0.005), (0.0049, -0.0049)]:
        np.testing.assert_array_equal(twist(x=x, z=z), 0.0)
    assert twist(z=-0.0051)[TWIST_VX] == pytest.approx(28 * 0.0001)


def test_workspace_edge_speeds():
    t = twist(x=-0.05, z=-0.05)
    assert t[TWIST_VX] == pytest.approx(1.26)
    assert t[TWIST_WZ] == pytest.approx(0.45)
    assert math.copysign(1, t[TWIST_WZ]) > 0  # left


def test_pd_and_map_allocate_nothing_per_cycle():
    pd = CentringPD()
    f, v, env, tw = np.zeros(3), np.zeros(3), np.zeros(3), np.zeros(3)
    p = np.array([0.01, 0.0, -0.02])

    def cycle():
        pd.compute(p, f, env_force=env)
        pd.compute(p, f, velocity=v, env_force=env)
        handle_to_twist(p, tw)

    cycle()
    assert_no_allocation(cycle)


def assert_no_allocation(fn, calls: int = 1000, peak_limit: int = 2048) -> None:
    """No growth over ``calls`` calls, and no temporary the size of a per-beam float array.

    A few hundred bytes of growth are the measuring loop itself (its frame, the last loop
    counter); a leak of even one byte per call would exceed the limit over 1000 calls. Numpy
    reductions allocate about 1 kB of iterator state, so the peak limit sits between that and
    the smallest float array over a scan (3.2 kB for 809 float32 beams).
    """
    grown, peak = allocation_stats(fn, calls)
    assert grown < 512, f"grew by {grown} bytes over {calls} calls"
    assert peak < peak_limit, f"a call allocated {peak} bytes at peak"


def test_pd_in_scalar_maths_is_the_saturated_sum_on_random_inputs():
    """The PD's scalar path against a direct numpy evaluation of eq. 5.1/5.2 (seeded)."""
    rng = np.random.default_rng(5)
    params = CentringParams(kp_n_per_m=55.0, kd_ns_per_m=0.2, force_limit_n=4.0)
    origin = np.array([0.001, -0.002, 0.003])
    pd, out = CentringPD(params, origin), np.zeros(3)
    for _ in range(500):
        p, v, env = rng.normal(0, 0.05, 3), rng.normal(0, 0.5, 3), rng.normal(0, 3.0, 3)
        expected = np.clip((origin - p) * params.kp_n_per_m - v * params.kd_ns_per_m + env, -4.0, 4.0)
        np.testing.assert_array_equal(pd.compute(p, out, v, env), expected)
    previous = np.zeros(3)
    pd.reset()
    for i in range(100):  # no velocity given: the backward difference of positions
        p = rng.normal(0, 0.01, 3)
        v = (p - previous) / params.period_s if i else np.zeros(3)
        expected = np.clip((origin - p) * params.kp_n_per_m - v * params.kd_ns_per_m, -4.0, 4.0)
        np.testing.assert_allclose(pd.compute(p, out), expected, rtol=1e-12, atol=1e-12)
        previous = p
