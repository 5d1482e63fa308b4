"""The desk scene's scripted hand: homing when asked, then its script, interpolated, and the end of it."""

import numpy as np
import pydantic
import pytest

from hapticop.devices.falcon import Flag
from hapticop.testing import BlockHarness

SCRIPT = [{"t_s": 0.0, "force_n": [0.0, 0.0, 0.0], "buttons": 1},
          {"t_s": 0.1, "force_n": [0.0, -2.0, 1.0], "buttons": 3},
          {"t_s": 0.2, "force_n": [0.0, 0.0, 0.0]}]


def test_the_hand_homes_while_the_led_is_red_then_places_the_grip_then_plays_its_script():
    harness = BlockHarness("scripted_hand", {"script": SCRIPT, "settle_s": 0.05, "start_m": [0.0, 0.01, 0.0]})
    harness.configure()
    harness.feed("leds", np.uint8(Flag.LED_RED))
    harness.step(10)
    assert np.abs(harness.outputs.hand_force.value).max() > 1.0  # pulling the grip out to home it
    harness.feed("leds", np.uint8(Flag.LED_GREEN))
    harness.feed("handle_position", [0.0, 0.0, 0.0])
    harness.step()
    np.testing.assert_allclose(harness.outputs.hand_force.value, [0.0, 3.0, 0.0])  # towards start_m, 300 N/m
    assert int(harness.outputs.buttons.value) == 0
    harness.step(49)  # 50 ms: the script's t = 0
    harness.step(51)  # t = 0.05 s, halfway to the second keyframe
    np.testing.assert_allclose(harness.outputs.hand_force.value, [0.0, -1.0, 0.5], atol=1e-9)
    assert int(harness.outputs.buttons.value) == 1 and not harness.flags["finished"]
    harness.step(55)  # t = 0.105 s, just past the second keyframe
    np.testing.assert_allclose(harness.outputs.hand_force.value, [0.0, -1.9, 0.95], atol=1e-9)
    assert int(harness.outputs.buttons.value) == 3
    harness.step(100)
    np.testing.assert_array_equal(harness.outputs.hand_force.value, 0.0)
    assert int(harness.outputs.buttons.value) == 0 and harness.flags["finished"]


def test_a_script_goes_forward_in_time_with_finite_forces():
    for bad in ([], [{"t_s": 0.5}, {"t_s": 0.5}], [{"t_s": 1.0}, {"t_s": 0.5}], [{"t_s": 0.0, "force_n": [0, 0, 1e3]}],
                [{"t_s": 0.0, "force_n": [0, float("nan"), 0]}], [{"t_s": -1.0}], [{"t_s": 0.0, "buttons": 16}]):
        with pytest.raises(pydantic.ValidationError):
            BlockHarness("scripted_hand", {"script": bad})
