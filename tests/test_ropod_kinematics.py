"""Smart-wheel kinematics, statics and torque distribution against reference.json (§4, §5)."""

from __future__ import annotations

import numpy as np
import pytest

from hapticop.devices.ropod.geometry import Geometry
from hapticop.devices.ropod.kinematics import SmartWheelKinematics, distribute_qp, jacobian

from .test_ropod_data import load

REF = load("reference")
TOL = REF["_about"]["tolerances_suggested"]
ABS_K, ABS_D, ABS_QP = TOL["kinematics_abs"], TOL["distribution_abs"], TOL["qp_abs"]


def _kin(delta, enable=None) -> SmartWheelKinematics:
    kin = SmartWheelKinematics()
    kin.update(np.asarray(delta, float), None if enable is None else np.asarray(enable, float))
    return kin


def test_geometry_is_the_references():
    geo, ref = Geometry(), REF["_about"]["geometry"]
    assert (geo.wheel_radius_m, geo.caster_offset_m, geo.wheel_distance_m) == (
        ref["r_w_m"], ref["s_w_m"], ref["d_w_m"])
    assert [list(p) for p in geo.pivots_m] == [ref["pivots_xy_m"][f"SW{i}"] for i in range(1, 5)]
    assert geo.k == pytest.approx(4.0)


@pytest.mark.parametrize("case", REF["inverse_kinematics"], ids=lambda c: c["note"])
def test_inverse_kinematics(case):
    kin, v = _kin(case["delta"]), np.array(case["v"])
    np.testing.assert_allclose(kin.G, case["G_wheels_8x3"], rtol=0, atol=ABS_K)
    np.testing.assert_allclose(kin.wheel_speeds(v, np.zeros(8)), case["wheel_speeds_rad_s"], rtol=0, atol=ABS_K)
    np.testing.assert_allclose(kin.pivot_rates(v, np.zeros(4)), case["pivot_rates_rad_s"], rtol=0, atol=ABS_K)


@pytest.mark.parametrize("case", REF["forward_kinematics"], ids=lambda c: str(c["enable"]))
def test_forward_kinematics_is_the_masked_least_squares_twist(case):
    kin = _kin(case["delta"], case["enable"])
    np.testing.assert_allclose(kin.twist(np.array(case["phidot_meas"]), np.zeros(3)), case["v_est"],
                               rtol=0, atol=ABS_K)
    mask = np.repeat(case["enable"], 2).astype(bool)
    lstsq = np.linalg.lstsq(kin.G[mask], np.array(case["phidot_meas"])[mask], rcond=None)[0]
    np.testing.assert_allclose(kin.twist(np.array(case["phidot_meas"]), np.zeros(3)), lstsq, atol=1e-12)


def test_forward_inverts_inverse_and_matches_the_feel_numbers():
    rng = np.random.default_rng(3)
    for _ in range(20):
        kin = _kin(rng.uniform(-np.pi, np.pi, 4))
        v = rng.normal(size=3)
        np.testing.assert_allclose(kin.twist(kin.wheel_speeds(v, np.zeros(8)), np.zeros(3)), v, atol=1e-12)
    kin = _kin(np.zeros(4))
    np.testing.assert_allclose(kin.wheel_speeds(np.array([1.0, 0, 0]), np.zeros(8)), 19.047619047619, atol=1e-9)
    np.testing.assert_allclose(kin.wheel_speeds(np.array([0, 1.0, 0]), np.zeros(8)),
                               [-76.190476190476, 76.190476190476] * 4, atol=1e-9)
    np.testing.assert_allclose(kin.pivot_rates(np.array([0, 1.0, 0]), np.zeros(4)), 100.0)


def test_statics_is_the_transpose_by_virtual_work():
    """Power in = power out: tau . phidot == wrench . twist for any pivot angles."""
    rng = np.random.default_rng(4)
    for _ in range(20):
        kin = _kin(rng.uniform(-np.pi, np.pi, 4))
        tau, v = rng.normal(size=8), rng.normal(size=3)
        assert tau @ kin.wheel_speeds(v, np.zeros(8)) == pytest.approx(kin.wrench(tau, np.zeros(3)) @ v, rel=1e-12)
    # At delta = 0 the largest forward force is 8 tau_max / r = 426.7 N.
    assert _kin(np.zeros(4)).wrench(np.full(8, 2.8), np.zeros(3))[0] == pytest.approx(426.6667, abs=1e-4)


@pytest.mark.parametrize("case", REF["torque_distribution"], ids=lambda c: f"{c['wrench_N_N_Nm']}-{c['enable']}")
def test_pseudo_inverse_distribution(case):
    kin, tau = _kin(case["delta"], case["enable"]), np.zeros(8)
    scale = kin.distribute(np.array(case["wrench_N_N_Nm"]), case["tau_max_Nm"], tau)
    ref = case["pinv"]
    np.testing.assert_allclose(tau, ref["tau_Nm"], rtol=0, atol=ABS_D)
    assert scale == pytest.approx(ref["scale"], abs=ABS_D)
    np.testing.assert_allclose(kin.wrench(tau, np.zeros(3)), ref["achieved_wrench"], rtol=0, atol=ABS_D * 1000)
    assert np.abs(tau).max() <= case["tau_max_Nm"] + 1e-12
    assert not tau[np.repeat(case["enable"], 2) == 0].any()  # a disabled unit gets no torque


@pytest.mark.parametrize("case", REF["torque_distribution"], ids=lambda c: f"{c['wrench_N_N_Nm']}-{c['enable']}")
def test_qp_distribution(case):
    tau, scale = distribute_qp(jacobian(case["delta"]), case["wrench_N_N_Nm"], case["enable"], case["tau_max_Nm"])
    ref = case["qp"]
    np.testing.assert_allclose(tau, ref["tau_Nm"], rtol=0, atol=ABS_QP)
    assert scale == pytest.approx(ref["scale"], abs=ABS_QP)
    np.testing.assert_allclose(jacobian(case["delta"]).T @ tau, ref["achieved_wrench"], rtol=0, atol=ABS_QP * 100)


def test_qp_reaches_a_wrench_the_pseudo_inverse_must_scale():
    """§5.3: at delta = 0, w = [300, 200, 60] pinv scales to 0.983; the QP redistributes and gets it all."""
    w = np.array([300.0, 200.0, 60.0])
    kin, tau = _kin(np.zeros(4)), np.zeros(8)
    assert kin.distribute(w, 2.8, tau) == pytest.approx(0.983026782833, abs=1e-9)
    tau_qp, scale = distribute_qp(kin.G, w, [1, 1, 1, 1], 2.8)
    assert scale == pytest.approx(1.0, abs=1e-9)
    np.testing.assert_allclose(kin.G.T @ tau_qp, w, atol=1e-6)


def test_flip_compensation_is_the_identity_in_normal_mode_and_amplifies_differential_torque():
    kin = _kin(np.zeros(4))
    tau = np.array([0.1, 0.5, 0.3, 0.3, -0.2, 0.2, 0.0, 0.01])
    same = tau.copy()
    kin.flip_compensate(same, kmax=1.0)
    np.testing.assert_array_equal(same, tau)
    flipped = tau.copy()
    kin.flip_compensate(flipped, kmax=4.0, force_threshold=10.0)
    t2, f2 = tau.reshape(4, 2), flipped.reshape(4, 2)
    np.testing.assert_allclose(f2.sum(axis=1), t2.sum(axis=1))  # the common torque is kept
    # Unit 1: lateral force 4 * 0.4 / r = 30.5 N > 10 N, so its difference grows by 1 + 3 |sin|.
    lam, lon = 4 * 0.4 / 0.0525, 0.6 / 0.0525
    gain = 1 + 3 * abs(lam) / np.hypot(lam, lon)
    assert f2[0, 1] - f2[0, 0] == pytest.approx(gain * 0.4)
    assert f2[1].tolist() == t2[1].tolist()  # no lateral force
    assert f2[3].tolist() == t2[3].tolist()  # 0.76 N lateral: below the threshold
    assert f2[2, 1] - f2[2, 0] == pytest.approx(4.0 * 0.4)  # pure lateral force: |sin| = 1


def test_per_unit_clip_scales_each_pair_alone():
    kin = _kin(np.zeros(4))
    tau = np.array([4.0, 2.0, 1.0, -1.0, -5.6, 1.4, 2.8, -2.8])
    kin.clip_per_unit(tau, 2.8)
    np.testing.assert_allclose(tau, [2.8, 1.4, 1.0, -1.0, -2.8, 0.7, 2.8, -2.8])


def test_one_unit_cannot_steer_the_platform():
    with pytest.raises(np.linalg.LinAlgError):
        _kin(np.zeros(4), [1, 0, 0, 0])
    _kin(np.zeros(4), [0, 1, 0, 1])  # two are enough


def test_the_unit_by_unit_evaluation_is_the_stacked_jacobian_and_its_normal_equations():
    """G from its definition, then N, its inverse, the twist, the wheel speeds, the statics and the
    distribution straight from numpy's linear algebra, on random seeded angles and enables."""
    rng = np.random.default_rng(21)
    geo = Geometry()
    px, py = np.array(geo.pivots_m).T
    for trial in range(50):
        delta = rng.uniform(-7.0, 7.0, 4)
        enable = np.ones(4) if trial % 2 else rng.permutation([1.0, 1.0, 0.0, float(trial % 3 == 0)])
        c, s = np.cos(delta), np.sin(delta)
        u = np.stack([c, s, px * s - py * c], axis=1)
        q = np.stack([-s, c, px * c + py * s], axis=1)
        g = np.stack([u - geo.k * q, u + geo.k * q], axis=1).reshape(8, 3) / geo.wheel_radius_m
        m = np.repeat(enable, 2)
        n = g.T @ (m[:, None] * g)
        kin = _kin(delta, enable)
        np.testing.assert_allclose(kin.G, g, rtol=1e-13, atol=1e-12)
        np.testing.assert_allclose(kin.N, n, rtol=1e-12, atol=1e-12 * np.abs(n).max())
        np.testing.assert_allclose(kin.N_inv @ n, np.eye(3), atol=1e-10)
        v, phidot, tau = rng.normal(size=3), rng.normal(0, 10, 8), rng.normal(size=8)
        np.testing.assert_allclose(kin.wheel_speeds(v, np.zeros(8)), g @ v, rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(kin.twist(phidot, np.zeros(3)), np.linalg.solve(n, g.T @ (m * phidot)),
                                   rtol=1e-10, atol=1e-12)
        np.testing.assert_allclose(kin.wrench(tau, np.zeros(3)), g.T @ tau, rtol=1e-12, atol=1e-12)
        w, out = rng.normal(0, 50, 3), np.zeros(8)
        scale = kin.distribute(w, 2.8, out)
        unscaled = np.linalg.pinv(g.T * m) @ w
        assert scale == pytest.approx(min(1.0, 2.8 / np.abs(unscaled).max()), rel=1e-10)
        np.testing.assert_allclose(out, unscaled * scale, rtol=1e-9, atol=1e-12)
