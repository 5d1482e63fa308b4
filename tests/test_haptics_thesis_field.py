"""The thesis environmental force (eq. 5.5, 5.6) on hand-made scans, its corrected F1 variant, and F0."""

import math

import numpy as np
import pytest

from hapticop.haptics.force_models import (
    FORCE_MODELS,
    CorrectedThesisForce,
    NoForce,
    ThesisForce,
    ThesisParams,
    make_force_model,
)

from .scans import tim561_angles
from .test_haptics_handle import assert_no_allocation

K3 = K4 = 100.0
D_MAX = 2.0
STILL = np.zeros(3)


def force(model_cls, angles_deg, ranges, x=0.0, z=0.0):
    model = model_cls(ThesisParams(K3, K4, D_MAX))
    model.configure(np.radians(angles_deg))
    return model.compute(np.array([x, 0.0, z]), np.asarray(ranges, dtype=float), STILL, np.full(3, np.nan))


def literal(angles, ranges, x, z, k3=K3, k4=K4, d_max=D_MAX):
    """Eq. 5.5/5.6 transcribed beam by beam; θ_d = φ + 90° (ahead at sin θ_d > 0, right at cos θ_d > 0)."""
    def maxabs(h, trig):
        best = 0.0
        for d, th in zip(ranges, angles):
            t = th + math.pi / 2
            value = (1.0 if h(d, t) else 0.0) * (d - d_max) / d_max * trig(t)
            if not math.isnan(value) and abs(value) > abs(best):
                best = value
        return best

    def h1(d, t): return d < d_max and math.sin(t) < 0
    def h2(d, t): return d < d_max and math.sin(t) > 0
    def h3(d, t): return d < d_max and math.cos(t) > 0
    def h4(d, t): return d < d_max and math.cos(t) < 0

    fz = k3 * z * maxabs(h1, math.sin) if z >= 0 else -k3 * z * maxabs(h2, math.sin)
    fx = k4 * x * maxabs(h3, math.cos) if x >= 0 else -k4 * x * maxabs(h4, math.cos)
    return fx, fz


def test_obstacle_straight_ahead_while_pushing_forward_gives_eq_5_5():
    f = force(ThesisForce, [0.0], [1.0], z=-0.02)
    expected = -K3 * -0.02 * ((1.0 - D_MAX) / D_MAX * 1.0)  # z < 0 branch, sin θ_d = 1
    assert f[2] == pytest.approx(expected) == pytest.approx(-1.0)
    # The quirk: the literal z force points along the push (forward, −z): it lowers the stiffness.
    assert np.sign(f[2]) == np.sign(-0.02)
    assert f[0] == 0.0 and f[1] == 0.0


def test_the_corrected_variant_resists_the_push_with_the_same_magnitude():
    f = force(CorrectedThesisForce, [0.0], [1.0], z=-0.02)
    assert f[2] == pytest.approx(+1.0)


def test_obstacles_behind_are_ignored_while_driving_forward_and_felt_while_reversing():
    behind = [120.0, -130.0]  # sin θ_d = cos φ < 0
    assert force(ThesisForce, behind, [0.5, 0.8], z=-0.02)[2] == 0.0
    back = force(ThesisForce, behind, [0.5, 0.8], z=+0.02)[2]
    # Largest magnitude of (d − d_max)/d_max·cos φ: 0.5 m at 120° → 0.75·0.5 = 0.375 vs 0.6·0.643.
    term = max((1 - 0.5 / 2) * abs(math.cos(math.radians(120))), (1 - 0.8 / 2) * abs(math.cos(math.radians(130))))
    assert back == pytest.approx(K3 * 0.02 * term)  # z ≥ 0 branch: +k3·z·(positive term)
    assert force(CorrectedThesisForce, behind, [0.5, 0.8], z=+0.02)[2] == pytest.approx(-back)


def test_max_returns_the_largest_magnitude_so_the_nearest_obstacle_wins():
    # Both terms are negative; a numeric max would pick the farther obstacle (-0.25).
    angles, ranges = [0.0, 10.0], [1.5, 0.8]
    near = (0.8 - D_MAX) / D_MAX * math.cos(math.radians(10.0))
    f = force(ThesisForce, angles, ranges, z=-0.01)
    assert f[2] == pytest.approx(-K3 * -0.01 * near)
    assert abs(f[2]) > abs(K3 * 0.01 * (1.5 - D_MAX) / D_MAX)
    # ...and the max is over the products: an oblique near obstacle loses to a straight-on one.
    f = force(ThesisForce, [0.0, 80.0], [1.0, 0.5], z=-0.01)
    assert f[2] == pytest.approx(K3 * -0.01 * 0.5)  # 0.5 ahead beats 0.75·cos 80° = 0.13


def test_turning_right_feels_obstacles_on_the_right_only_and_is_restoring():
    right, left = -90.0, 90.0
    f = force(ThesisForce, [right], [1.0], x=+0.02)
    assert f[0] == pytest.approx(-K4 * 0.02 * 0.5)  # pushes back to the left: centring
    assert force(ThesisForce, [left], [1.0], x=+0.02)[0] == 0.0
    f = force(ThesisForce, [left], [1.0], x=-0.02)
    assert f[0] == pytest.approx(+K4 * 0.02 * 0.5)
    np.testing.assert_allclose(force(CorrectedThesisForce, [left, right], [1.0, 0.4], x=-0.02), f)


def test_the_magnitude_never_exceeds_k3_z_and_reaches_it_at_contact():
    f = force(ThesisForce, [0.0, 90.0], [1e-9, 1e-9], x=-0.03, z=-0.04)
    assert abs(f[2]) == pytest.approx(K3 * 0.04)
    assert abs(f[0]) == pytest.approx(K4 * 0.03)
    rng = np.random.default_rng(3)
    angles = tim561_angles(809)
    model = ThesisForce(ThesisParams(K3, K4, D_MAX))
    model.configure(angles)
    out = np.zeros(3)
    for _ in range(50):
        ranges = rng.uniform(0.05, 4.0, 809)
        x, z = rng.uniform(-0.05, 0.05, 2)
        model.compute(np.array([x, 0.0, z]), ranges, STILL, out)
        assert abs(out[2]) <= K3 * abs(z) + 1e-12 and abs(out[0]) <= K4 * abs(x) + 1e-12


def test_matches_a_beam_by_beam_transcription_on_random_scans_with_invalid_beams():
    rng = np.random.default_rng(4)
    angles = tim561_angles(809)
    out = np.zeros(3)
    for cls, sign in ((ThesisForce, 1.0), (CorrectedThesisForce, -1.0)):
        model = cls(ThesisParams(80.0, 120.0, 2.5))
        model.configure(angles)
        for _ in range(20):
            ranges = rng.uniform(0.05, 6.0, 809)
            ranges[rng.random(809) < 0.1] = np.nan
            x, z = rng.uniform(-0.05, 0.05, 2)
            model.compute(np.array([x, 0.0, z]), ranges.astype(np.float32), STILL, out)
            fx, fz = literal(angles, ranges.astype(np.float32).astype(float), x, z, 80.0, 120.0, 2.5)
            assert out[0] == pytest.approx(fx, abs=1e-12)
            assert out[2] == pytest.approx(fz if sign > 0 else -abs(fz) * np.sign(z), abs=1e-12)


def test_no_force_with_a_centred_handle_or_nothing_within_d_max():
    assert np.all(force(ThesisForce, [0.0, 90.0, -90.0], [0.3, 0.3, 0.3]) == 0.0)
    assert np.all(force(ThesisForce, [0.0, 90.0], [2.0, 9.0], x=0.02, z=-0.02) == 0.0)
    assert np.all(force(ThesisForce, [0.0, 90.0], [np.nan, np.nan], x=0.02, z=-0.02) == 0.0)


def test_literal_z_field_makes_the_handle_unstable_near_a_wall_when_k3_exceeds_kp():
    # Net z stiffness Kp − k3·ρ: with k3 = 100 and a wall at 0.4 m (ρ = 0.8) it is negative.
    kp = 55.0
    z = -0.01
    f_env = force(ThesisForce, [0.0], [0.4], z=z)[2]
    assert -kp * z + f_env < 0  # the total force pushes the handle further forward
    f_env = force(CorrectedThesisForce, [0.0], [0.4], z=z)[2]
    assert -kp * z + f_env > 0


def test_the_none_model_is_zero_and_the_registry_knows_all_models():
    model = make_force_model("none", tim561_angles(809))
    assert isinstance(model, NoForce)
    out = np.full(3, np.nan)
    model.compute(np.array([0.03, 0, -0.03]), np.full(809, 0.3), np.array([1.0, 0, 0]), out)
    np.testing.assert_array_equal(out, 0.0)
    assert set(FORCE_MODELS) == {"none", "thesis", "thesis_corrected", "braking_field"}
    with pytest.raises(ValueError, match="unknown force model"):
        make_force_model("potential")


@pytest.mark.parametrize("name", ["none", "thesis", "thesis_corrected"])
def test_compute_allocates_nothing(name):
    angles = tim561_angles(809)
    model = make_force_model(name, angles)
    ranges = np.random.default_rng(5).uniform(0.05, 4.0, 809).astype(np.float32)
    ranges[::9] = np.nan
    handle, twist, out = np.array([0.01, 0.0, -0.02]), np.array([0.5, 0.0, 0.0]), np.zeros(3)
    assert_no_allocation(lambda: model.compute(handle, ranges, twist, out))
    assert_no_allocation(lambda: model.render(handle, twist, out))


def test_a_parameter_set_builds_the_model_its_kind_names():
    from hapticop.haptics.force_models import BrakingField, BrakingFieldParams, NoForceParams

    params = ThesisParams(80.0, 120.0, 2.5, kind="thesis_corrected")
    model = make_force_model(params, tim561_angles(809))
    assert type(model) is CorrectedThesisForce and model.params is params
    assert type(make_force_model(ThesisParams())) is ThesisForce
    assert type(make_force_model(NoForceParams())) is NoForce
    assert type(make_force_model(BrakingFieldParams(silent_ratio=0.9))) is BrakingField
    assert make_force_model("thesis_corrected").params.kind == "thesis_corrected"
