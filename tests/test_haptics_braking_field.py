"""M1 (docs/hallway-experiment.md §9.1): footprint clearance, braking-ratio risk, predictive lateral clearance."""

import math

import numpy as np
import pytest

from hapticop.haptics.force_models import BrakingField, BrakingFieldParams, CorrectedThesisForce

from .scans import hallway, robot_scan, tim561_angles
from .test_haptics_handle import assert_no_allocation

ANGLES = tim561_angles(809)
STATIC = BrakingFieldParams(risk_rate_per_s=math.inf)  # no rate limit: the risk jumps to its target
PUSH = np.array([0.0, 0.0, -0.03])  # forward, past the 2 cm ramp
CENTRED = np.zeros(3)


def model(params=STATIC):
    m = BrakingField(params)
    m.configure(ANGLES)
    return m


def end_wall(front_clearance, half_width=5.0):
    """A wall across the path, ``front_clearance`` ahead of the footprint's front (0.35 m ahead of centre)."""
    x = 0.35 + front_clearance
    return [((x, -half_width), (x, half_width))]


def side_wall(y, start=-10.0, end=20.0):
    return [((start, y), (end, y))]


def fz(m, segments, v, pose=(0.0, 0.0, 0.0), handle=PUSH, age=0.0):
    return m.compute(handle, robot_scan(ANGLES, segments, pose), np.array([v, 0.0, 0.0]), np.zeros(3), age)[2]


def test_zero_in_free_space():
    m = model()
    out = np.full(3, np.nan)
    for handle in (PUSH, np.array([0.03, 0.0, -0.03]), np.array([-0.02, 0.0, 0.02])):
        m.compute(handle, np.full(809, np.nan), np.array([1.0, 0.0, 0.3]), out)
        np.testing.assert_array_equal(out, 0.0)
    # Walls far to the sides, end wall out of range: nothing is in the field while cruising.
    scan = robot_scan(ANGLES, hallway(4.0, 30.0))
    m.compute(PUSH, scan, np.array([0.56, 0.0, 0.0]), out)
    np.testing.assert_array_equal(out, 0.0)


def test_longitudinal_force_matches_the_braking_ratio_equations():
    m = model()
    # Front clearance 1.5 m: g = 1.0 m, v_allow = √(2·0.5·1.0) = 1 m/s, ratio 0.5 → ρ = (0.5 − 0.4)/0.6.
    f = m.compute(np.array([0.0, 0.0, -0.01]), robot_scan(ANGLES, end_wall(1.5)), np.array([0.5, 0, 0]), np.zeros(3))
    assert m.gap_m == pytest.approx(1.0, abs=1e-9)
    assert m.rho_brake == pytest.approx(1 / 6) and m.rho_prox == 0.0
    assert f[2] == pytest.approx(6.0 * (1 / 6) * 0.5)  # F_z,max·ρ·sat(−z/z_g), z = −1 cm
    assert f[2] > 0  # pushes the hand back: resists driving forward


def test_force_grows_as_time_to_collision_shrinks():
    for risk in ("braking", "ttc"):
        m = model(BrakingFieldParams(risk_rate_per_s=math.inf, longitudinal_risk=risk))
        clearances = [4.0, 3.0, 2.0, 1.5, 1.2, 1.0, 0.8, 0.6, 0.5]
        forces = [fz(m, end_wall(c), 0.5) for c in clearances]
        assert forces[0] == 0.0
        assert all(b >= a for a, b in zip(forces, forces[1:])), (risk, forces)
        assert forces[-1] == pytest.approx(6.0)
        # Same distance, faster: less time to collision, more force.
        speeds = [fz(m, end_wall(1.5), v) for v in (0.2, 0.4, 0.6, 0.8, 1.0)]
        assert all(b > a for a, b in zip(speeds[1:], speeds[2:])), (risk, speeds)


def test_slow_approach_is_silent_until_the_proximity_zone():
    m = model()
    assert fz(m, end_wall(1.0), 0.15) == 0.0  # 0.15 m/s against v_allow 0.71 m/s: below r0
    near = fz(m, end_wall(0.7), 0.0)  # standstill, 0.2 m before the 0.3 m proximity zone ends
    assert near == pytest.approx(6.0 * (1 - 0.2 / 0.3))


def test_a_persistent_stop_cue_at_the_stop_line_resists_only_forward_pushes():
    m = model()
    wall = end_wall(0.5)  # at dist2: g = 0
    assert fz(m, wall, 0.0) == pytest.approx(6.0)
    assert fz(m, wall, 0.0, handle=np.array([0.0, 0.0, -0.01])) == pytest.approx(3.0)
    assert fz(m, wall, 0.0, handle=np.array([0.0, 0.0, 0.02])) == 0.0  # backing off is free


def test_scan_age_is_predicted_away():
    m = model()
    fresh = fz(m, end_wall(1.5), 0.5, age=0.0)
    old = fz(m, end_wall(1.5), 0.5, age=0.4)  # the robot has moved 0.2 m since
    assert m.gap_m == pytest.approx(0.8, abs=1e-9)
    assert old > fresh


def test_footprint_matters_a_wall_0_3_m_beside_the_scanner_touches_a_0_6_m_wide_robot():
    m = model()
    out = np.zeros(3)
    m.compute(CENTRED, robot_scan(ANGLES, side_wall(0.3)), np.array([0.5, 0, 0]), out)
    assert m.c_left_m == pytest.approx(0.0, abs=1e-9)
    assert out[0] == pytest.approx(5.0)  # full lateral push to the right, handle centred
    m.compute(CENTRED, robot_scan(ANGLES, side_wall(0.6)), np.array([0.5, 0, 0]), out)
    assert m.c_left_m == pytest.approx(0.3, abs=1e-9)
    assert out[0] == pytest.approx(5.0 * (0.65 - 0.3) / 0.55)
    # The source field, a point robot at the scanner, gives nothing with a centred handle.
    f1 = CorrectedThesisForce()
    f1.configure(ANGLES)
    np.testing.assert_array_equal(f1.compute(CENTRED, robot_scan(ANGLES, side_wall(0.3)), np.zeros(3), out), 0.0)


def test_lateral_term_responds_to_how_fast_the_side_gap_closes():
    m = model()
    twist = np.array([0.5, 0.0, 0.0])

    def fx(heading_deg, wall_y=0.9):
        scan = robot_scan(ANGLES, side_wall(wall_y), (0.0, 0.0, math.radians(heading_deg)))
        return m.compute(CENTRED, scan, twist, np.zeros(3))[0]

    towards, parallel, away = fx(10.0), fx(0.0), fx(-10.0)
    assert towards > parallel > away >= 0.0  # push right, harder the faster the gap closes
    assert parallel == pytest.approx(5.0 * (0.65 - 0.6) / 0.55)  # parallel: predicted = current clearance
    # A right wall mirrors it.
    assert fx(-10.0, wall_y=-0.9) == pytest.approx(-towards)
    # Sideways drift (the ropod is holonomic) towards the wall also counts.
    scan = robot_scan(ANGLES, side_wall(0.9))
    drift = m.compute(CENTRED, scan, np.array([0.5, 0.1, 0.0]), np.zeros(3))[0]
    assert drift > parallel


def test_no_lateral_cue_at_standstill_and_opposite_walls_cancel():
    m = model()
    out = np.zeros(3)
    m.compute(CENTRED, robot_scan(ANGLES, side_wall(0.6)), np.zeros(3), out)
    assert out[0] == 0.0
    m.compute(CENTRED, robot_scan(ANGLES, hallway(1.5, 30.0)), np.array([0.5, 0, 0]), out)
    assert m.c_left_m == pytest.approx(m.c_right_m, abs=0.01)
    assert abs(out[0]) < 0.05


def test_forces_stay_within_the_falcon_budget():
    m = model()
    rng = np.random.default_rng(6)
    out = np.zeros(3)
    for _ in range(50):
        ranges = rng.uniform(0.05, 3.0, 809)
        handle = rng.uniform(-0.05, 0.05, 3)
        twist = np.array([rng.uniform(-0.5, 1.0), rng.uniform(-0.2, 0.2), rng.uniform(-1, 1)])
        m.compute(handle, ranges, twist, out)
        assert 0.0 <= out[2] <= 6.0 and abs(out[0]) <= 5.0 and out[1] == 0.0


def test_the_risk_state_is_rate_limited():
    m = model(BrakingFieldParams())  # 3 /s at 1 kHz: 0.003 per call
    scan, twist, out = robot_scan(ANGLES, end_wall(0.5)), np.zeros(3), np.zeros(3)
    m.compute(PUSH, scan, twist, out)
    assert m.risk[0] == pytest.approx(0.003)
    for _ in range(99):
        m.render(PUSH, twist, out)
    assert m.risk[0] == pytest.approx(0.3) and out[2] == pytest.approx(6.0 * 0.3)
    for _ in range(300):
        m.render(PUSH, twist, out)
    assert m.risk[0] == pytest.approx(1.0, abs=1e-9)  # the wall 1e-12 m beyond dist2 (tests/scans.py)
    m.compute(PUSH, np.full(809, np.nan), twist, out)  # obstacle gone: ramps down, no step
    assert m.risk[0] == pytest.approx(0.997)
    m.reset()
    assert m.risk[0] == 0.0



def test_the_lateral_risk_may_keep_its_own_faster_rate():
    """side_risk_rate_per_s: the lateral cue rises at its own limit while the stop cue keeps the common one."""
    wall_and_end = side_wall(0.45) + end_wall(0.05, half_width=0.25)  # a wall 0.15 m to the left, the stop line passed
    scan, twist, out = robot_scan(ANGLES, wall_and_end), np.array([0.5, 0.0, 0.0]), np.zeros(3)
    common, own = model(BrakingFieldParams()), model(BrakingFieldParams(side_risk_rate_per_s=6.0))
    for m in (common, own):
        m.compute(PUSH, scan, twist, out)
        for _ in range(99):
            m.render(PUSH, twist, out)
    assert common.risk[0] == pytest.approx(0.3) and common.risk[1] == pytest.approx(0.3)
    assert own.risk[0] == pytest.approx(0.3) and own.risk[1] == pytest.approx(0.6)  # 6 /s for 100 ms
    assert out[0] == pytest.approx(5.0 * 0.6)  # full speed: F_x = F_x,max·e_L


def test_the_lateral_cue_fades_out_before_the_handle_reaches_the_workspace_edge():
    """A soft hand pushed by the cue must not be driven to the Falcon's 5 cm edge (a divergence, §5)."""
    m = model()
    scan, twist, out = robot_scan(ANGLES, side_wall(0.45)), np.array([0.5, 0.0, 0.0]), np.zeros(3)
    full = m.compute(np.zeros(3), scan, twist, out)[0]
    assert full > 1.0  # the wall 0.15 m to the left pushes the hand to the right (+x)
    for x, share in ((0.03, 1.0), (0.04, 1 / 3), (0.045, 0.0), (0.05, 0.0), (-0.05, 1.0)):  # -x: against the cue
        assert m.compute(np.array([x, 0.0, 0.0]), scan, twist, out)[0] == pytest.approx(full * share), x

def test_compute_and_render_allocate_nothing():
    m = model(BrakingFieldParams())
    ranges = robot_scan(ANGLES, hallway(2.0, 6.0), (0.5, 0.3, math.radians(8))).astype(np.float32)
    handle, twist, out = np.array([0.01, 0.0, -0.02]), np.array([0.5, 0.0, 0.1]), np.zeros(3)
    assert_no_allocation(lambda: m.compute(handle, ranges, twist, out, 0.05))
    assert_no_allocation(lambda: m.render(handle, twist, out, 0.05))


def test_side_clearances_are_the_kth_smallest_clearance_by_direct_evaluation():
    """BeamGeometry's per-cycle side clearances against the equation evaluated beam by beam (seeded),
    for sorted and shuffled beams and a scanner on and off the body's centre line."""
    from hapticop.devices.ropod.body import Body, SensorMount
    from hapticop.haptics.geometry import BeamGeometry

    rng = np.random.default_rng(4)
    sorted_angles = np.sort(rng.uniform(-2.4, 2.4, 400))
    for angles in (sorted_angles, rng.permutation(sorted_angles)):
        for body in (Body(), Body(lidar=SensorMount(0.1, 0.2)), Body(lidar=SensorMount(0.25, 0.5))):
            fp, lidar = body.footprint, body.lidar
            beams, hl, hw = BeamGeometry(angles, body), fp.length_m / 2, fp.width_m / 2
            for _ in range(20):
                ranges = rng.uniform(0.05, 3.0, angles.size)
                ranges[rng.random(angles.size) < 0.1] = np.nan
                beams.load(ranges)
                beams.select_sides(0.5, 1.5)
                sx, sy = rng.uniform(-0.5, 1.5), rng.choice([0.0, rng.uniform(-0.2, 0.2)])
                got = beams.side_clearances(sx, sy, 3)
                px, py = ranges * np.cos(angles) + lidar.x_m, ranges * np.sin(angles) + lidar.y_m
                window = ~np.isnan(ranges) & (px >= -hl - 0.5) & (px <= hl + 1.5)
                clearance = np.hypot(np.maximum(np.abs(px - sx) - hl, 0), np.maximum(np.abs(py - sy) - hw, 0))
                for side, mask in enumerate((window & (py > hw), window & (py < -hw))):
                    values = np.sort(clearance[mask])
                    expected = values[2] if values.size >= 3 else math.inf
                    assert got[side] == pytest.approx(expected, rel=1e-12, abs=1e-12)
