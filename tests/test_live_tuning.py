"""Live tuning keeps running: a gain patched into a driving hallway takes effect between two cycles.

The README's example (`k1` 28 -> 30) once sent the haptic controller back to capability
configuration, where it waited for a re-centred handle the operator was holding off centre: the
robot stopped mid-hallway for good. Gains, limits and force models now retune in place.
"""

import threading

import numpy as np
import pytest

from hapticop.blocks.haptic import HapticController
from hapticop.devices.ropod.controller_params import LinearControllerParams
from hapticop.devices.ropod.linear_bank import ControllerBank
from hapticop.runtime.system import ExitStatus
from hapticop.testing import BlockHarness

from .conftest import SYSTEMS
from .runtime_helpers import compose

TUNE_AT_S = 5.0
TUNED = f"""
patches:
  stiffer_driving:
    at: {TUNE_AT_S:g}s
    patch:
      activities:
        haptic: {{params: {{driving: {{k1_per_s: 30.0}}, centring: {{kp_n_per_m: 60.0}},
                            force_model: {{kind: braking_field, silent_ratio: 0.8}}}}}}
        ropod: {{params: {{wheel: {{p_gain: 0.06}}}}}}
"""


def _short_hallway(limit_s: float) -> str:
    return (SYSTEMS / "hallway.yaml").read_text().replace("time_limit_s: 90.0", f"time_limit_s: {limit_s:g}")


def test_a_gain_patched_while_driving_keeps_the_robot_driving(tmp_path):
    result = compose(tmp_path, _short_hallway(9.0) + TUNED, duration=None, name="tuned")
    assert result.outcome.status is ExitStatus.SUCCESS, result.outcome.reasons
    run = tmp_path / "run-tuned"
    assert "scripted patch 'stiffer_driving' applied at 5s" in (run / "system.log").read_text()
    for activity in ("haptic", "ropod"):  # neither left running: no re-centring, no controller reset
        log = (run / f"{activity}.log").read_text()
        assert log.count("-> running") == 1, log
        assert "running -> capability_configuration" not in log and "running -> resource_configuration" not in log
    trajectory = np.load(run / "trajectory.npz")
    t, x = trajectory["t"], trajectory["pose"][:, 0]
    before = x[np.searchsorted(t, TUNE_AT_S)]
    assert before > 0.5, "the robot was driving when the gain changed"
    assert x[-1] > before + 0.5, "and kept driving afterwards"


def test_a_retuned_controller_bank_keeps_its_states():
    slow = LinearControllerParams(p_gain=1.0, i_fhz=1.0, ll_zero_fhz=5.0, ll_pole_fhz=5.0, lpf_fhz=50.0,
                                  i_saturation=100.0)
    bank = ControllerBank(slow, ts=1e-3, n=2)
    out = np.zeros(2)
    for _ in range(200):
        bank.step([0.5, -0.2], out)
    states = bank.xi.copy(), bank.xd.copy(), bank.xl.copy()
    bank.retune(LinearControllerParams(p_gain=2.0, i_fhz=1.0, ll_zero_fhz=5.0, ll_pole_fhz=5.0, lpf_fhz=50.0,
                                       i_saturation=100.0))
    for kept, now in zip(states, (bank.xi, bank.xd, bank.xl)):
        np.testing.assert_array_equal(kept, now)
    fresh = ControllerBank(slow, ts=1e-3, n=2)
    fresh.retune(slow)
    np.testing.assert_array_equal(fresh.xi, np.zeros(2))


def test_the_haptic_controller_says_what_its_start_waits_for():
    harness = BlockHarness(HapticController, name="haptic")
    harness.block.create()
    assert harness.block.configure_capabilities() is False
    assert "handle's position" in harness.context.waiting
    harness.feed("handle_position", [0.02, 0.0, 0.0])
    harness.inputs.handle_position.refresh()
    assert harness.block.configure_capabilities() is False
    assert "within 5 mm" in harness.context.waiting and "20 mm off" in harness.context.waiting
    assert any("waiting for the handle within 5 mm" in line for line in harness.log_lines())


def test_a_retuned_haptic_controller_renders_with_the_new_gain_at_once():
    harness = BlockHarness(HapticController, name="haptic")
    harness.flags["resources_ready"] = True
    harness.feed("handle_position", [0.0, 0.0, 0.0])
    harness.configure(max_cycles=10)
    harness.feed("ranges", np.full(811, 10.0, np.float32))  # open space: no obstacle force, not blind
    harness.feed("angles", np.linspace(-0.75 * np.pi, 0.75 * np.pi, 811, dtype=np.float32))
    harness.feed("handle_position", [0.01, 0.0, 0.0])
    harness.feed("handle_velocity", [0.0, 0.0, 0.0])
    harness.step()
    assert harness.outputs.force.value[0] == -0.55  # kp 55 N/m at 10 mm
    speed = np.linalg.norm(harness.outputs.velocity_setpoint.value)
    assert speed > 0
    changed = harness.retune({"centring": {"kp_n_per_m": 80.0}, "driving": {"k2_rad_per_s_m": 20.0}})
    assert changed == {"centring", "driving"}
    harness.step()
    assert harness.outputs.force.value[0] == -0.8
    assert np.linalg.norm(harness.outputs.velocity_setpoint.value) == pytest.approx(2 * speed)  # k2 doubled


def test_status_says_what_a_configuring_activity_waits_for(tmp_path):
    from hapticop.control.client import request

    from .runtime_helpers import counting

    socket = tmp_path / "stuck.sock"
    text = (counting().replace("schedules: {0: [mediator, noise]}", "schedules: {0: [mediator, noise, stuck]}")
            .replace("  recorder: {block: echo}\n", "  recorder: {block: echo}\n  stuck: {block: 'tests.blocks:Stuck', "
                     "params: {stuck_in: capability_configuration}}\n"))
    replies = {}

    def operator(system):
        def talk():
            try:
                for _ in range(200):  # until the stuck activity has said so (bounded: 10 s)
                    reply = replies["status"] = request(socket, {"op": "status"}) if socket.exists() else {}
                    if reply.get("ok") and reply["status"]["activities"]["stuck"]["waiting_for"]:
                        break
                    threading.Event().wait(0.05)
            finally:
                system.request_shutdown()
        threading.Thread(target=talk, daemon=True).start()

    compose(tmp_path, text, clock="realtime", duration="30s", on_start=operator, control=str(socket))
    stuck = replies["status"]["status"]["activities"]["stuck"]
    assert stuck["state"] == "capability_configuration"
    assert stuck["waiting_for"] == "a 'capability_configuration' that never completes (a test)"
    assert replies["status"]["status"]["activities"]["mediator"]["waiting_for"] is None


def test_a_re_configuration_after_the_start_does_not_wait_for_a_re_centred_handle():
    harness = BlockHarness(HapticController, name="haptic")
    harness.flags["resources_ready"] = True
    harness.feed("handle_position", [0.0, 0.0, 0.0])
    harness.configure(max_cycles=10)
    harness.feed("handle_position", [0.03, 0.0, 0.0])  # the operator holds it 30 mm off centre
    harness.inputs.handle_position.refresh()
    assert harness.block.configure_capabilities() is True
    assert harness.context.waiting is None
