"""The haptic effects and the force limit against their equations (docs/haptic-blocks.md), for arbitrary inputs."""

import math

import numpy as np
import pydantic
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from hapticop.blocks.effects import VirtualWallParams, WorkspaceLimitBlockParams
from hapticop.haptics.effects import (
    BoxLimitParams,
    SphereLimitParams,
    SpringParams,
    ViscousParams,
    WallParams,
    render_spring,
    render_viscous,
    render_wall,
    render_workspace_limit,
)
from hapticop.haptics.force_limit import ForceLimit, ForceLimitParams
from hapticop.testing import allocation_stats

coordinate = st.floats(-0.1, 0.1, allow_nan=False)
speed = st.floats(-2.0, 2.0, allow_nan=False)
vectors = st.tuples(coordinate, coordinate, coordinate)
velocities = st.tuples(speed, speed, speed)
direction = st.tuples(st.floats(-1, 1), st.floats(-1, 1), st.floats(-1, 1)).filter(lambda v: math.hypot(*v) > 0.1)
gain = st.floats(0.0, 5000.0)
damping = st.floats(0.0, 50.0)


def _render(render, params, position, velocity):
    out = np.full(3, np.nan)
    render(params, np.array(position), np.array(velocity), out)
    return out


@settings(max_examples=300, deadline=None)
@given(point=vectors, normal=direction, k=gain, b=damping, q=vectors, v=velocities)
def test_the_wall_pushes_out_along_its_normal_only_while_penetrated(point, normal, k, b, q, v):
    wall = WallParams(point_m=point, normal=normal, kp_n_per_m=k, kd_ns_per_m=b)
    force = _render(render_wall, wall, q, v)
    n = np.array(normal) / np.linalg.norm(normal)
    depth = float(np.dot(np.array(point) - np.array(q), n))
    if depth <= 0.0:
        np.testing.assert_array_equal(force, 0.0)  # in front of the wall: nothing, damping neither
        return
    expected = max(k * depth - b * float(np.dot(v, n)), 0.0)
    np.testing.assert_allclose(force, expected * n, atol=1e-9)
    assert float(np.dot(force, n)) >= 0.0  # never pulls the handle into the wall
    np.testing.assert_allclose(np.cross(force, n), 0.0, atol=1e-9)  # along the normal only


def test_the_wall_at_rest_is_a_spring_of_its_stiffness():
    wall = WallParams(point_m=(0.0, -0.01, 0.0), normal=(0.0, 2.0, 0.0), kp_n_per_m=1000.0, kd_ns_per_m=2.0)
    np.testing.assert_allclose(_render(render_wall, wall, (0.03, -0.014, 0.02), (0, 0, 0)), [0.0, 4.0, 0.0])
    np.testing.assert_allclose(_render(render_wall, wall, (0.0, -0.014, 0.0), (0.0, -0.5, 0.0)), [0.0, 5.0, 0.0])
    np.testing.assert_allclose(_render(render_wall, wall, (0.0, -0.014, 0.0), (0.0, 3.0, 0.0)), 0.0)  # leaving fast


def test_a_wall_needs_a_direction_and_finite_gains():
    with pytest.raises(pydantic.ValidationError, match="normal must not be the zero vector"):
        VirtualWallParams.model_validate({"wall": {"normal": [0, 0, 0]}})
    for bad in ({"kp_n_per_m": -1.0}, {"kd_ns_per_m": float("nan")}, {"kp_n_per_m": float("inf")}, {"stiffness": 1}):
        with pytest.raises(pydantic.ValidationError):
            VirtualWallParams.model_validate({"wall": bad})


@settings(max_examples=200, deadline=None)
@given(anchor=vectors, k=gain, b=damping, q=vectors, v=velocities)
def test_the_spring_pulls_to_its_anchor_and_damps(anchor, k, b, q, v):
    force = _render(render_spring, SpringParams(anchor_m=anchor, kp_n_per_m=k, kd_ns_per_m=b), q, v)
    np.testing.assert_allclose(force, k * (np.array(anchor) - q) - b * np.array(v), atol=1e-9)


@settings(max_examples=200, deadline=None)
@given(b=damping, q=vectors, v=velocities)
def test_the_viscous_field_opposes_the_velocity_everywhere(b, q, v):
    force = _render(render_viscous, ViscousParams(b_ns_per_m=b), q, v)
    np.testing.assert_allclose(force, -b * np.array(v), atol=1e-12)
    assert float(np.dot(force, v)) <= 0.0  # it only takes energy out


half_sizes = st.tuples(st.floats(0.005, 0.05), st.floats(0.005, 0.05), st.floats(0.005, 0.05))


@settings(max_examples=300, deadline=None)
@given(centre=vectors, half=half_sizes, k=gain, b=damping, q=vectors, v=velocities)
def test_the_box_pushes_back_each_axis_beyond_its_face(centre, half, k, b, q, v):
    box = BoxLimitParams(centre_m=centre, half_size_m=half, kp_n_per_m=k, kd_ns_per_m=b)
    force = _render(render_workspace_limit, box, q, v)
    for axis in range(3):
        e = q[axis] - centre[axis]
        beyond = abs(e) - half[axis]
        if beyond <= 0.0:
            assert force[axis] == 0.0
            continue
        outwards = math.copysign(1.0, e)
        expected = max(k * beyond + b * v[axis] * outwards, 0.0)
        assert force[axis] == pytest.approx(-outwards * expected, abs=1e-9)
        assert force[axis] * outwards <= 0.0  # never pushes the handle further out


@settings(max_examples=300, deadline=None)
@given(centre=vectors, radius=st.floats(0.005, 0.08), k=gain, b=damping, q=vectors, v=velocities)
def test_the_sphere_pushes_back_towards_its_centre_beyond_its_radius(centre, radius, k, b, q, v):
    sphere = SphereLimitParams(centre_m=centre, radius_m=radius, kp_n_per_m=k, kd_ns_per_m=b)
    force = _render(render_workspace_limit, sphere, q, v)
    e = np.array(q) - centre
    r = float(np.linalg.norm(e))
    if r <= radius:
        np.testing.assert_array_equal(force, 0.0)
        return
    u = e / r
    expected = max(k * (r - radius) + b * float(np.dot(v, u)), 0.0)
    np.testing.assert_allclose(force, -expected * u, atol=1e-9)


def test_a_workspace_limit_is_a_box_or_a_sphere_by_its_kind():
    box = WorkspaceLimitBlockParams.model_validate({"limit": {"kind": "box", "half_size_m": [0.03, 0.02, 0.04]}})
    assert isinstance(box.limit, BoxLimitParams)
    assert isinstance(WorkspaceLimitBlockParams().limit, SphereLimitParams)
    for bad in ({"kind": "cube"}, {"kind": "box", "half_size_m": [0.03, 0.0, 0.04]}, {"kind": "sphere", "radius_m": 0}):
        with pytest.raises(pydantic.ValidationError):
            WorkspaceLimitBlockParams.model_validate({"limit": bad})


forces = st.tuples(*[st.floats(-100.0, 100.0)] * 3)


@settings(max_examples=200, deadline=None)
@given(max_norm=st.floats(0.1, 20.0), max_rate=st.floats(1.0, 10_000.0),
       targets=st.lists(st.tuples(forces, st.floats(0.0, 0.01)), min_size=1, max_size=40))
def test_the_limited_force_keeps_both_bounds_for_any_targets(max_norm, max_rate, targets):
    params = ForceLimitParams(max_norm_n=max_norm, max_rate_n_per_s=max_rate)
    limit, out = ForceLimit(), np.zeros(3)
    last = np.zeros(3)
    for target, dt in targets:
        limit.step(params, np.array(target), dt, out)
        assert np.linalg.norm(out) <= max_norm * (1 + 1e-12)
        assert np.linalg.norm(out - last) <= max_rate * dt * (1 + 1e-9) + 1e-12
        last = out.copy()


def test_the_limited_force_reaches_a_reachable_target_and_drops_nan():
    params = ForceLimitParams(max_norm_n=8.0, max_rate_n_per_s=2000.0)
    limit, out = ForceLimit(), np.zeros(3)
    for _ in range(3):
        limit.step(params, np.array([0.0, 5.0, 0.0]), 0.001, out)
    np.testing.assert_allclose(out, [0.0, 5.0, 0.0])  # 2 N per millisecond: there after three
    limit.step(params, np.array([0.0, 30.0, 0.0]), 1.0, out)
    np.testing.assert_allclose(out, [0.0, 8.0, 0.0])  # the norm bound
    limit.step(params, np.array([np.nan, 1.0, 0.0]), 0.001, out)
    np.testing.assert_allclose(out, [0.0, 6.0, 0.0])  # nothing known: heading for zero, at the rate
    limit.reset()
    limit.step(params, np.array([0.0, 5.0, 0.0]), 0.001, out)
    np.testing.assert_allclose(out, [0.0, 2.0, 0.0])


def test_the_effects_and_the_limit_allocate_nothing_that_stays():
    position, velocity, out = np.array([0.01, -0.02, 0.005]), np.array([0.1, -0.2, 0.0]), np.zeros(3)
    cases = [(render_wall, WallParams()), (render_spring, SpringParams()), (render_viscous, ViscousParams()),
             (render_workspace_limit, BoxLimitParams(half_size_m=(0.005, 0.005, 0.005))),
             (render_workspace_limit, SphereLimitParams(radius_m=0.01))]
    for render, params in cases:
        kept, _ = allocation_stats(lambda render=render, params=params: render(params, position, velocity, out))
        assert kept < 512, render.__name__  # over 1000 calls: nothing per call
    limit, limit_params = ForceLimit(), ForceLimitParams()
    kept, _ = allocation_stats(lambda: limit.step(limit_params, position, 0.001, out))
    assert kept < 512
