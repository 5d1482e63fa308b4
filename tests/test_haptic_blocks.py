"""The haptic building blocks alone, each in a BlockHarness: ports, parameters and their equations."""

import numpy as np
import pydantic
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from hapticop.haptics.effects import WallParams, render_wall
from hapticop.testing import BlockHarness

force = st.tuples(*[st.floats(-50.0, 50.0)] * 3)


def test_every_haptic_block_is_built_in_with_si_ports_at_the_falcons_rate():
    for name in ("virtual_wall", "spring_damper", "viscous_field", "workspace_limit", "force_sum", "force_limit"):
        harness = BlockHarness(name)
        assert harness.interface.outputs["force"].unit == "N" and harness.interface.outputs["force"].shape == (3,)
        assert harness.interface.rate.admits(1_000_000)
    assert BlockHarness("button").interface.flags_written.keys() == {"pressed"}


def test_the_wall_block_renders_its_equation_and_nothing_without_a_handle():
    params = {"wall": {"point_m": [0.0, -0.01, 0.0], "normal": [0.0, 1.0, 0.0], "kp_n_per_m": 800.0}}
    harness = BlockHarness("virtual_wall", params)
    harness.configure()
    harness.step()
    np.testing.assert_array_equal(harness.outputs.force.value, 0.0)  # no position yet: nothing to render against
    harness.feed("position", [0.01, -0.015, 0.02])
    harness.step()  # velocity never fed: the handle counts as at rest
    np.testing.assert_allclose(harness.outputs.force.value, [0.0, 4.0, 0.0])
    harness.feed("velocity", [0.0, -1.0, 0.0])
    harness.step()
    expected = render_wall(WallParams(**params["wall"]), np.array([0.01, -0.015, 0.02]), np.array([0.0, -1.0, 0.0]),
                           np.zeros(3))
    np.testing.assert_allclose(harness.outputs.force.value, expected)
    assert harness.outputs.force.published == 3


@pytest.mark.parametrize(("block", "params", "expected"), [
    ("spring_damper", {"spring": {"anchor_m": [0.0, 0.0, 0.01], "kp_n_per_m": 100.0, "kd_ns_per_m": 1.0}},
     [-1.0 - 0.1, 2.0, 1.0]),
    ("viscous_field", {"viscosity": {"b_ns_per_m": 4.0}}, [-0.4, 0.0, 0.0]),
    ("workspace_limit", {"limit": {"kind": "box", "half_size_m": [0.005, 0.05, 0.05], "kp_n_per_m": 500.0,
                                   "kd_ns_per_m": 0.0}}, [-2.5, 0.0, 0.0]),
    ("workspace_limit", {"limit": {"kind": "sphere", "radius_m": 0.01, "kp_n_per_m": 500.0, "kd_ns_per_m": 0.0}},
     [-0.2 * 500 * (np.sqrt(0.0005) - 0.01) / np.sqrt(0.0005) * 0.05, 0.4 * 500 * (np.sqrt(0.0005) - 0.01)
      / np.sqrt(0.0005) * 0.05, 0.0]),
])
def test_the_field_blocks_render_their_equations(block, params, expected):
    harness = BlockHarness(block, params)
    harness.configure()
    harness.feed("position", [0.01, -0.02, 0.0])
    harness.feed("velocity", [0.1, 0.0, 0.0])
    harness.step()
    np.testing.assert_allclose(harness.outputs.force.value, expected, atol=1e-12)


@settings(max_examples=50, deadline=None)
@given(inputs=st.lists(force, min_size=2, max_size=8))
def test_the_sum_is_the_sum(inputs):
    harness = BlockHarness("force_sum", {"inputs": len(inputs)})
    assert set(harness.interface.inputs) == {f"force_{i}" for i in range(1, len(inputs) + 1)}
    harness.configure()
    for i, value in enumerate(inputs, start=1):
        harness.feed(f"force_{i}", value)
    harness.step()
    np.testing.assert_allclose(harness.outputs.force.value, np.sum(inputs, axis=0), atol=1e-9)


def test_a_sum_counts_a_force_it_never_got_as_zero_and_takes_two_to_eight():
    harness = BlockHarness("force_sum", {"inputs": 3})
    harness.configure()
    harness.feed("force_1", [1.0, 2.0, 3.0])
    harness.feed("force_3", [0.5, 0.0, -1.0])
    harness.step()
    np.testing.assert_allclose(harness.outputs.force.value, [1.5, 2.0, 2.0])
    for bad in (1, 9):
        with pytest.raises(pydantic.ValidationError):
            BlockHarness("force_sum", {"inputs": bad})


@settings(max_examples=50, deadline=None)
@given(max_norm=st.floats(0.5, 20.0), max_rate=st.floats(100.0, 5000.0), targets=st.lists(force, min_size=1,
                                                                                          max_size=30))
def test_the_limit_block_keeps_the_norm_and_the_rate_of_change(max_norm, max_rate, targets):
    harness = BlockHarness("force_limit", {"limit": {"max_norm_n": max_norm, "max_rate_n_per_s": max_rate}})
    harness.configure()
    last = np.zeros(3)
    for target in targets:
        harness.feed("demand", target)
        harness.step()
        out = harness.outputs.force.value
        assert np.linalg.norm(out) <= max_norm * (1 + 1e-12)
        assert np.linalg.norm(out - last) <= max_rate * 1e-3 * (1 + 1e-9)
        last = out.copy()


def test_the_dead_man_limit_lets_the_force_through_only_while_enabled():
    assert "enable" not in BlockHarness("force_limit").interface.inputs
    harness = BlockHarness("force_limit", {"limit": {"max_norm_n": 8.0, "max_rate_n_per_s": 2000.0},
                                           "dead_man": True})
    assert harness.interface.inputs["enable"].dtype == "uint8"
    harness.configure()
    harness.feed("demand", [0.0, 5.0, 0.0])
    harness.step(5)
    np.testing.assert_array_equal(harness.outputs.force.value, 0.0)  # never enabled
    harness.feed("enable", np.uint8(1))
    harness.step(5)
    np.testing.assert_allclose(harness.outputs.force.value, [0.0, 5.0, 0.0])
    harness.feed("enable", np.uint8(0))
    harness.step()
    np.testing.assert_allclose(harness.outputs.force.value, [0.0, 3.0, 0.0])  # let go: down at the rate
    harness.step(3)
    np.testing.assert_array_equal(harness.outputs.force.value, 0.0)


def test_a_paused_limit_starts_again_from_zero():
    harness = BlockHarness("force_limit")
    harness.configure()
    harness.feed("demand", [4.0, 0.0, 0.0])
    harness.step(3)
    np.testing.assert_allclose(harness.outputs.force.value, [4.0, 0.0, 0.0])
    harness.block.pausing()
    np.testing.assert_array_equal(harness.outputs.force.value, 0.0)
    harness.step(2)  # the first cycle after the pause only takes the time
    np.testing.assert_allclose(harness.outputs.force.value, [2.0, 0.0, 0.0])


@settings(max_examples=100, deadline=None)
@given(masks=st.lists(st.integers(0, 15), min_size=1, max_size=60), debounce_ms=st.integers(0, 6),
       mask=st.integers(1, 15), require=st.sampled_from(["any", "all"]))
def test_the_button_flag_follows_the_buttons_once_a_change_has_lasted_the_debounce(masks, debounce_ms, mask,
                                                                                    require):
    harness = BlockHarness("button", {"mask": mask, "require": require, "debounce_s": debounce_ms / 1000})
    harness.configure()
    raw = [(m & mask == mask) if require == "all" else (m & mask != 0) for m in masks]
    flags = []
    for m in masks:
        harness.feed("buttons", np.uint8(m))
        harness.step()
        flags.append(harness.flags["pressed"])
        assert int(harness.outputs.pressed.value) == flags[-1]
    for j in range(len(masks)):
        steady = j >= debounce_ms and len(set(raw[j - debounce_ms:j + 1])) == 1
        if steady:
            assert flags[j] == raw[j]  # held long enough: the flag says so
        before = flags[j - 1] if j else False
        if flags[j] != before:
            assert steady and flags[j] == raw[j]  # it changes only for a change that lasted


def test_a_button_reads_released_at_once_when_its_mask_goes_stale():
    harness = BlockHarness("button", {"debounce_s": 0.01})
    harness.configure()
    harness.feed("buttons", np.uint8(1))
    harness.step(11)
    assert harness.flags["pressed"]
    harness.block.inputs.buttons.max_age_ns = 5_000_000  # as a stream's max_age would make it
    harness.step(6)
    assert not harness.flags["pressed"] and int(harness.outputs.pressed.value) == 0
