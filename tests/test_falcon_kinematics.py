"""Falcon kinematics against libnifalcon's numbers, and the errors of libnifalcon we do not copy."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from hapticop.devices.falcon.kinematics import FalconKinematics
from hapticop.devices.falcon.mechanism import WORKSPACE_BOX_M, Drive, Geometry
from hapticop.testing import grown_bytes

from .conftest import FIXTURES, SHARED_TESTDATA

# The full reference data when ../shared is present, else the small copies the project ships.
DATA = SHARED_TESTDATA / "falcon" if (SHARED_TESTDATA / "falcon").is_dir() else FIXTURES / "falcon"
REF = json.loads((DATA / "kinematics_reference.json").read_text()) if DATA.is_dir() else {
    "inverse_kinematics_and_jacobian": [], "forward_kinematics": [], "encoder_to_angle": []}
IK_CASES = REF["inverse_kinematics_and_jacobian"]
FK_CASES = [c for c in REF["forward_kinematics"] if c.get("independent_fk_m") is not None]
FK_UNREACHABLE = [c for c in REF["forward_kinematics"] if c.get("independent_fk_m") is None]


def _libnifalcon_S(J: np.ndarray) -> np.ndarray:
    """What libnifalcon's getForces multiplies F by: J's lower triangle mirrored (§8)."""
    i, j = np.indices((3, 3))
    return J[np.maximum(i, j), np.minimum(i, j)]


@pytest.fixture
def kin() -> FalconKinematics:
    return FalconKinematics()


# ---------------------------------------------------------------- constants and encoders
def test_defaults_are_libnifalcons_constants():
    c, g, dr = REF["constants"], Geometry(), Drive()
    assert [getattr(g, k) for k in "abcdefrs"] == [c[k] for k in "abcdefrs"]
    assert np.allclose(np.radians(g.leg_angles_deg), c["phi_rad"], atol=1e-8)  # libnifalcon's pi = 3.14159265
    assert math.degrees(dr.rad_per_count) == pytest.approx(c["encoder"]["deg_per_tick"], rel=1e-15)
    assert dr.zero_count_deg == c["encoder"]["THETA_OFFSET_ANGLE_deg"]
    assert dr.motor_per_nm == c["getForces"]["sign"] * c["getForces"]["torque_to_motor_scale"]


@pytest.mark.parametrize("case", REF["encoder_to_angle"], ids=lambda c: str(c["encoder"]))
def test_counts_to_thigh_angle(kin, case):
    theta = kin.angles_from_counts(np.full(3, case["encoder"]), np.zeros(3))
    assert np.degrees(theta) == pytest.approx(case["theta_deg"], rel=1e-13, abs=1e-12)
    # libnifalcon converts with 0.0174532925: relative 1e-9 from exact radians
    assert theta == pytest.approx(case["theta_rad_libnifalcon"], rel=2e-9)
    counts = kin.counts_from_angles(theta, np.zeros(3, dtype=np.int64))
    assert counts.tolist() == [case["encoder"]] * 3


# ---------------------------------------------------------------- inverse kinematics, Jacobian
@pytest.mark.parametrize("case", IK_CASES, ids=lambda c: str(c["position_m"]))
def test_inverse_kinematics(kin, case):
    t1, t2, t3 = np.zeros(3), np.zeros(3), np.zeros(3)
    assert kin.inverse(case["position_m"], t1, t2, t3)
    for got, leg in ((t1, "theta1"), (t2, "theta2"), (t3, "theta3")):
        assert got == pytest.approx(case[f"libnifalcon_{leg}_rad"], abs=5e-7)  # float32 in libnifalcon
        assert got == pytest.approx(case[f"independent_{leg}_rad"], abs=1e-12)


@pytest.mark.parametrize("case", IK_CASES, ids=lambda c: str(c["position_m"]))
def test_jacobian(kin, case):
    J, M = np.zeros((3, 3)), np.zeros((3, 3))
    assert kin.jacobian(case["position_m"], J, M)
    assert np.allclose(J, case["independent_jacobian"], rtol=1e-9, atol=1e-14)
    assert np.allclose(M, case["independent_dtheta1_dp"], rtol=1e-9, atol=1e-12)
    assert np.allclose(J @ M, np.eye(3), atol=1e-12)
    # M against central differences of our own IK
    p, h, tp, tm = np.array(case["position_m"], float), 1e-7, np.zeros(3), np.zeros(3)
    for k in range(3):
        dp = np.zeros(3)
        dp[k] = h
        assert kin.inverse(p + dp, tp) and kin.inverse(p - dp, tm)
        assert (tp - tm) / (2 * h) == pytest.approx(M[:, k], rel=1e-6, abs=1e-6)
    # libnifalcon's J: x and y columns of its inverse are right, the z column is not (issue #66)
    M_lib = np.linalg.inv(np.array(case["libnifalcon_jacobian"]))
    assert np.allclose(M_lib[:, :2], M[:, :2], rtol=1e-5, atol=1e-5)


def test_libnifalcon_z_column_error_is_real_and_large():
    worst = max(np.abs(np.array(c["libnifalcon_jacobian"]) - c["independent_jacobian"]).max()
                / np.abs(c["independent_jacobian"]).max() for c in IK_CASES)
    assert worst > 0.15  # docs/devices/falcon-kinematics.md: up to 18 %


# ---------------------------------------------------------------- forces
@pytest.mark.parametrize("case", IK_CASES, ids=lambda c: str(c["position_m"]))
def test_forces_use_the_true_jacobian_transpose(kin, case):
    J_lib = np.array(case["libnifalcon_jacobian"])
    tau, motor = np.zeros(3), np.zeros(3, dtype=np.int64)
    for f in case["getForces"]:
        assert kin.forces_to_torques(case["position_m"], f["force_N"], tau)
        assert tau == pytest.approx(f["independent_torque_Nm_JT_F_correct_jacobian"], abs=1e-12)
        # the reference's libnifalcon motor values are trunc(-10000 S F) with the symmetrised S
        tau_lib = _libnifalcon_S(J_lib) @ f["force_N"]
        assert tau_lib == pytest.approx(f["libnifalcon_effective_torque_Nm"], abs=1e-12)
        assert np.trunc(-10000 * tau_lib).astype(int).tolist() == f["libnifalcon_getForces_motor_values"]
        # ours: the same scale and rounding on the true torque, saturated to +-4095 together
        assert kin.forces_to_motor(case["position_m"], f["force_N"], motor)
        want = -10000 * tau
        peak = np.abs(want).max()
        if peak > 4095:
            want *= 4095 / peak
        assert motor.tolist() == np.trunc(want).astype(int).tolist()


def test_documented_example_at_125mm(kin):
    """docs/devices/falcon-kinematics.md §8: F = (1, 0, 0) N at (0, 0, 0.125) m gives (-178, 605, -427)."""
    motor = np.zeros(3, dtype=np.int64)
    assert kin.forces_to_motor([0.0, 0.0, 0.125], [1.0, 0.0, 0.0], motor)
    assert motor.tolist() == [-178, 605, -427]  # libnifalcon sends (-178, 596, -324)


@pytest.mark.parametrize("case", IK_CASES[::3], ids=lambda c: str(c["position_m"]))
def test_virtual_work_holds_for_ours_and_fails_for_libnifalcons(kin, case):
    """tau . dtheta == F . dx for a small real motion (FK of perturbed angles, not J)."""
    p0 = np.array(case["position_m"], float)
    theta0, p1, p0m, tau = np.zeros(3), np.zeros(3), np.zeros(3), np.zeros(3)
    assert kin.inverse(p0, theta0)
    rng = np.random.default_rng(7)
    lib_errors = []
    for _ in range(5):
        dtheta = rng.normal(size=3) * 1e-5
        force = rng.normal(size=3) * 5.0
        assert kin.forward_angles(theta0 + dtheta, p1) and kin.forward_angles(theta0 - dtheta, p0m)
        dx = (p1 - p0m) / 2  # central: second-order terms cancel
        assert kin.forces_to_torques(p0, force, tau)
        work = force @ dx
        assert tau @ dtheta == pytest.approx(work, rel=1e-6)
        tau_lib = _libnifalcon_S(np.array(case["libnifalcon_jacobian"])) @ force
        lib_errors.append(abs(tau_lib @ dtheta - work) / abs(work))
    assert max(lib_errors) > 0.01  # libnifalcon's torques do not do the work the force does


def test_saturation_keeps_the_force_direction(kin):
    motor, tau = np.zeros(3, dtype=np.int64), np.zeros(3)
    force = np.array([40.0, -25.0, 60.0])
    assert kin.forces_to_torques([0.01, 0.0, 0.13], force, tau)
    assert kin.forces_to_motor([0.01, 0.0, 0.13], force, motor)
    assert np.abs(motor).max() == 4095
    assert motor / np.linalg.norm(motor) == pytest.approx(-tau / np.linalg.norm(tau), abs=1e-3)


def test_bad_inputs_give_false_and_zero_commands(kin):
    motor = np.array([5, 5, 5], dtype=np.int64)
    assert not kin.forces_to_motor([0.0, 0.0, 0.125], [np.nan, 0.0, 0.0], motor)
    assert motor.tolist() == [0, 0, 0]
    motor[:] = 5
    assert not kin.forces_to_motor([0.0, 0.0, 0.5], [1.0, 0.0, 0.0], motor)  # unreachable
    assert motor.tolist() == [0, 0, 0]
    theta = np.full(3, 9.0)
    assert not kin.inverse([0.0, 0.0, 0.03], theta) and theta.tolist() == [9.0] * 3
    assert not kin.inverse([np.nan, 0.0, 0.1], theta)


def test_force_at_last_forward_pose_equals_force_at_that_position(kin):
    p, a, b = np.zeros(3), np.zeros(3, dtype=np.int64), np.zeros(3, dtype=np.int64)
    assert kin.forward([300, -200, 100], p)
    assert kin.forces_to_motor(None, [2.0, -1.0, 3.0], a)
    assert kin.forces_to_motor(p, [2.0, -1.0, 3.0], b)
    assert a.tolist() == b.tolist()
    F = np.zeros(3)
    tau = np.zeros(3)
    assert kin.forces_to_torques(None, [2.0, -1.0, 3.0], tau)
    assert kin.torques_to_force(p, tau, F) and F == pytest.approx([2.0, -1.0, 3.0], abs=1e-12)


# ---------------------------------------------------------------- forward kinematics
@pytest.mark.parametrize("case", FK_CASES, ids=lambda c: str(c["encoders"]))
def test_forward_kinematics_cold(kin, case):
    p = np.zeros(3)
    assert kin.forward(case["encoders"], p)
    assert kin.iterations <= 8
    assert p == pytest.approx(case["independent_fk_m"], abs=1e-9)
    assert p == pytest.approx(case["libnifalcon_getPosition_after_300_calls_m"], abs=1e-7)
    # libnifalcon's single call is off by up to 0.36 mm; ours is not
    theta, back = kin.angles_from_counts(case["encoders"], np.zeros(3)), np.zeros(3)
    assert kin.inverse(p, back) and back == pytest.approx(theta, abs=1e-12)


@pytest.mark.parametrize("case", FK_UNREACHABLE, ids=lambda c: str(c["encoders"]))
def test_forward_kinematics_unreachable_says_so(kin, case):
    p = np.array([1.0, 2.0, 3.0])
    assert kin.forward([0, 0, 0], np.zeros(3))
    assert not kin.forward(case["encoders"], p)
    assert p.tolist() == [1.0, 2.0, 3.0]  # untouched
    assert kin.forward([10, 10, 10], p) and kin.iterations <= 4  # warm start survived


def test_warm_started_sequence_does_not_lag(kin):
    """libnifalcon's one half-step per cycle lags the encoders; ours is exact every cycle."""
    p, cold = np.zeros(3), np.zeros(3)
    lib_err = []
    for step in REF["fk_stateful_sequence"]:
        assert kin.forward(step["encoders"], p)
        assert kin.iterations <= 3
        other = FalconKinematics()
        assert other.forward(step["encoders"], cold)
        assert p == pytest.approx(cold, abs=1e-12)
        lib_err.append(np.abs(np.array(step["libnifalcon_position_m"]) - p).max())
    assert max(lib_err[:21]) > 1e-4  # libnifalcon trails by > 0.1 mm while the ramp runs
    assert all(b < a for a, b in zip(lib_err[20:], lib_err[21:]))  # then creeps in, halving
    assert lib_err[-1] < 1e-6


@pytest.mark.parametrize("case", IK_CASES, ids=lambda c: str(c["position_m"]))
def test_round_trip_ik_fk(kin, case):
    theta, p = np.zeros(3), np.zeros(3)
    assert kin.inverse(case["position_m"], theta)
    assert kin.forward_angles(theta, p)
    assert p == pytest.approx(case["position_m"], abs=1e-10)


coord = st.floats(0.0, 1.0, allow_nan=False)


@settings(max_examples=300, deadline=None)
@given(coord, coord, coord, coord, coord, coord)
def test_fk_inverts_ik_in_the_workspace(a, b, c, d, e, f):
    lo, hi = np.array(WORKSPACE_BOX_M)
    target = lo + (hi - lo) * np.array([a, b, c])
    previous = lo + (hi - lo) * np.array([d, e, f])
    kin, theta, p = FalconKinematics(), np.zeros(3), np.zeros(3)
    assume(kin.inverse(target, theta) and kin.inverse(previous, p))
    assert kin.forward_angles(theta, p)  # cold
    assert np.abs(p - target).max() < 1e-9
    assert kin.inverse(previous, theta) and kin.forward_angles(theta, p)  # warm, from elsewhere
    assert kin.inverse(target, theta) and kin.forward_angles(theta, p)
    assert np.abs(p - target).max() < 1e-9


def test_geometry_is_a_parameter():
    """The thesis's r = 36.6 mm moves the counts-0 point by 2.4 mm in z (docs/devices/falcon-kinematics.md §1)."""
    p, q = np.zeros(3), np.zeros(3)
    assert FalconKinematics().forward([0, 0, 0], p)
    assert FalconKinematics(Geometry(r=0.0366)).forward([0, 0, 0], q)
    assert p[2] == pytest.approx(0.134602, abs=1e-6)
    assert abs(p[2] - q[2]) == pytest.approx(0.0024, abs=1e-4)


def test_cycle_path_allocates_nothing_that_stays(kin):
    p, motor = np.zeros(3), np.zeros(3, dtype=np.int64)
    enc = np.zeros(3, dtype=np.int64)
    force = np.array([1.0, -2.0, 0.5])

    def cycles(n):
        for i in range(n):
            enc[0], enc[1], enc[2] = i % 200, -(i % 150), (i % 90) - 40
            kin.forward(enc, p)
            kin.forces_to_motor(None, force, motor)

    cycles(300)
    grown = grown_bytes(lambda: cycles(3000))
    assert grown < 2048


# ---------------------------------------------------------------- the float-level API, against the equations
def _direct_theta1_and_M(p: np.ndarray, g: Geometry = Geometry()) -> tuple[np.ndarray, np.ndarray]:
    """theta1 of §4 for all legs at once in numpy, and M = d theta1 / d p by central differences."""
    def theta1(q: np.ndarray) -> np.ndarray:
        phi = np.radians(g.leg_angles_deg)
        u = np.cos(phi) * q[0] + np.sin(phi) * q[1] - g.r
        v = -np.sin(phi) * q[0] + np.cos(phi) * q[1]
        X, w = u + g.c, q[2]
        K = g.d + g.e + g.b * np.sin(np.arccos((v + g.f - g.s) / g.b))
        rho = np.hypot(X, w)
        return np.arctan2(w, X) - np.arccos((g.a ** 2 + rho ** 2 - K ** 2) / (2 * g.a * rho))

    h = 1e-7
    M = np.stack([(theta1(p + h * e) - theta1(p - h * e)) / (2 * h) for e in np.eye(3)], axis=1)
    return theta1(p), M


def test_float_level_pose_and_force_agree_with_the_equations_and_the_array_api(kin):
    rng = np.random.default_rng(11)
    lo, hi = np.array(WORKSPACE_BOX_M)
    checked = 0
    for _ in range(200):
        p = lo + (hi - lo) * rng.random(3)
        pose = kin.pose(*p.tolist())
        if pose is None:
            assert not kin.inverse(p, np.zeros(3))
            continue
        checked += 1
        theta1, M = _direct_theta1_and_M(p)
        assert [leg[0] for leg in pose] == pytest.approx(theta1.tolist(), abs=1e-13)
        tau = rng.normal(size=3)
        force, F = kin.pose_force(pose, *tau.tolist()), np.zeros(3)
        assert force == pytest.approx((M.T @ tau).tolist(), rel=1e-6)  # F = M^T tau
        assert kin.torques_to_force(p, tau, F) and F.tolist() == list(force)
        t, back = np.zeros(3), np.zeros(3)
        assert kin.forces_to_torques(p, F, t) and t == pytest.approx(tau, rel=1e-12, abs=1e-12)  # J^T M^T = 1
        counts = kin.counts_from_angles(theta1, np.zeros(3, dtype=np.int64))
        assert counts.tolist() == [kin.count(a) for a in theta1.tolist()]
        assert counts.tolist() == np.rint((theta1 - kin.drive.zero_count_rad) / kin.drive.rad_per_count).tolist()
        assert kin.forward(counts, back) and kin.inverse(back, t)
        assert t == pytest.approx(kin.angles_from_counts(counts, np.zeros(3)), abs=1e-12)
    assert checked > 100


@pytest.mark.parametrize("axis", [0, 1, 2])
def test_non_finite_torque_on_any_axis_gives_zero_commands(kin, axis):
    tau, motor = np.array([0.1, -0.2, 0.3]), np.full(3, 7, dtype=np.int64)
    tau[axis] = np.nan
    assert not kin.torques_to_motor(tau, motor) and motor.tolist() == [0, 0, 0]
    tau[axis] = np.inf
    motor[:] = 7
    assert not kin.torques_to_motor(tau, motor) and motor.tolist() == [0, 0, 0]
