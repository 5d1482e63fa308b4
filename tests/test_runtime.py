"""The runtime under the virtual clock: life cycles, coordination, schedules, determinism."""

import numpy as np
import pytest

from hapticop.composition.lcsm import State
from hapticop.runtime.system import ExitStatus

from .runtime_helpers import COUNTER, IGNORES_SHUTDOWN, compose, pipeline


def test_a_run_walks_everything_to_done(tmp_path):
    result = compose(tmp_path, pipeline(), duration="500ms")
    assert result.outcome.status is ExitStatus.SUCCESS, result.outcome.reasons
    assert all(state is State.DONE for state in result.states.values())
    threads = result.timing["threads"]
    assert threads["main"]["cycles"] >= 500 and threads["slow"]["cycles"] >= 50
    assert threads["main"]["missed_deadlines"] == 0
    assert result.timing["activities"]["recorder"]["steps"] >= 48


def test_same_seed_same_run_bit_for_bit(tmp_path):
    def samples(seed, name):
        compose(tmp_path, pipeline(), duration="300ms", seed=seed, name=name)
        data = np.load(tmp_path / f"run-{name}" / "recorder.npz")
        return data["samples"], data["stamps"]

    a, stamps_a = samples(7, "a")
    b, stamps_b = samples(7, "b")
    c, _ = samples(8, "c")
    assert len(a) > 20
    assert a.tobytes() == b.tobytes() and np.array_equal(stamps_a, stamps_b)
    assert not np.array_equal(a, c)
    # the recorder on the 10 ms thread sees the newest 1 ms sample: stamps advance by 10 ms
    assert set(np.diff(stamps_a)) == {10_000_000}


def test_process_deployment_is_ignored_by_the_virtual_clock(tmp_path):
    compose(tmp_path, pipeline("process"), duration="200ms", seed=3, name="p")
    compose(tmp_path, pipeline("thread"), duration="200ms", seed=3, name="t")
    p = np.load(tmp_path / "run-p" / "recorder.npz")["samples"]
    t = np.load(tmp_path / "run-t" / "recorder.npz")["samples"]
    assert p.tobytes() == t.tobytes()


SWITCH = """
version: 1
threads:
  main:
    period: 1ms
    deploy: main
    schedules: {0: [mediator], 1: [mediator, counter]}
activities:
  mediator: {block: mediator}
  counter: {block: counter, params: {stop_after: 100}}
coordination:
  nets:
    switch:
      places: {START: , WAITING: , SELECT: , DONE: , STOP: , REACHED: }
      transitions:
        select: {in: [START], out: [WAITING, SELECT]}
        stop: {in: [WAITING, REACHED], out: [DONE, STOP]}
      marking: {START: 1}
      terminal: [DONE]
  flag_maps:
    switch:
      net: switch
      converting_sinks: {threads.main.select_schedule.1: SELECT, system.exit: STOP}
      converting_sources: {counter.reached: REACHED}
"""


def test_schedule_switch_and_a_net_that_ends_the_run(tmp_path):
    result = compose(tmp_path, SWITCH, duration=None)
    assert result.outcome.status is ExitStatus.SUCCESS, result.outcome.reasons
    assert result.timing["activities"]["counter"]["steps"] >= 100
    log = (tmp_path / "run-c" / "thread-main.log").read_text()
    assert "schedule 0 -> 1" in log
    assert result.markings["switch"]["DONE"] == 1


FAILING = COUNTER.replace("counter: {block: counter}", "counter: {block: counter, params: {fail_at: 50}}")


def test_a_failing_activity_is_reported_and_fails_the_run(tmp_path):
    result = compose(tmp_path, FAILING, duration="200ms")
    assert result.outcome.status is ExitStatus.FAILURE
    assert any("'counter' failed (running failed)" in r for r in result.outcome.reasons)
    assert "counter reached fail_at=50" in (tmp_path / "run-c" / "counter.log").read_text()
    assert result.states["counter"] is State.DONE


@pytest.mark.parametrize("stuck_in", ["creation", "resource_configuration", "capability_configuration", "running"])
def test_shutdown_from_each_state(tmp_path, stuck_in):
    text = f"""
    version: 1
    threads:
      main: {{period: 1ms, deploy: main, schedules: {{0: [mediator]}}}}
      worker: {{period: 5ms, schedules: {{0: [stuck]}}}}
    activities:
      mediator: {{block: mediator}}
      stuck: {{block: "tests.blocks:Stuck", params: {{stuck_in: {stuck_in}}}}}
    """
    result = compose(tmp_path, text, duration="100ms")
    # The shutdown is clean from every state; a run whose activity never ran is still a failed run.
    if stuck_in == "running":
        assert result.outcome.status is ExitStatus.SUCCESS, result.outcome.reasons
    else:
        assert result.outcome.status is ExitStatus.FAILURE
        assert result.outcome.reasons == [
            f"'stuck' never reached running (it got as far as {stuck_in.replace('_', ' ')})"]
    assert all(state is State.DONE for state in result.states.values())
    assert (tmp_path / "run-c" / "stuck.cleaned").exists() == (stuck_in != "creation")


def test_shutdown_from_pausing(tmp_path):
    text = COUNTER + """
coordination:
  nets:
    pause:
      places: {A: , P: , PAUSED: }
      transitions: {t: {in: [A], out: [P, PAUSED]}}
      marking: {A: 1}
      terminal: [PAUSED]
  flag_maps:
    pause: {net: pause, converting_sinks: {counter.lcsm.request_pausing: P}}
"""
    result = compose(tmp_path, text, duration="100ms")
    assert result.outcome.status is ExitStatus.SUCCESS
    log = (tmp_path / "run-c" / "counter.log").read_text()
    assert "running -> pausing" in log and "pausing -> cleaning" in log


def test_coordination_that_never_finishes_is_forced(tmp_path):
    text = COUNTER + IGNORES_SHUTDOWN
    result = compose(tmp_path, text, duration="100ms", shutdown_timeout="50ms")
    assert result.outcome.status is ExitStatus.FAILURE
    assert any("did not finish the shutdown" in r for r in result.outcome.reasons)
    assert all(state is State.DONE for state in result.states.values())


def test_hallway_coordination_runs_its_course(tmp_path):
    from .conftest import SYSTEMS

    # 3 s: long enough for the handle to be homed and the operator to drive (every activity runs,
    # the world leaves its results); a shorter run is incomplete and fails (test_exit_status.py).
    result = compose(tmp_path, (SYSTEMS / "hallway.yaml").read_text(), duration="3s", name="hallway")
    assert result.outcome.status is ExitStatus.SUCCESS, result.outcome.reasons
    assert result.markings["mediator"]["EXIT"] == 1 and result.markings["thread_lcsm"]["DONE"] == 1
    assert result.markings["thread_scheduler"] == {"SELECTED": 1}
    assert all(state is State.DONE for state in result.states.values())
    lidar_thread = (tmp_path / "run-hallway" / "thread-lidar.log").read_text()
    assert "schedule 0 -> 1" in lidar_thread


def test_a_virtual_run_without_duration_lasts_as_long_as_the_composition_wants(tmp_path):
    """No time limit of its own: this one ends after 100 simulated seconds, by its net."""
    result = compose(tmp_path, SWITCH.replace("stop_after: 100", "stop_after: 100000"), duration=None)
    assert result.outcome.status is ExitStatus.SUCCESS, result.outcome.reasons
    assert result.timing["activities"]["counter"]["steps"] >= 100_000


LOOPBACK = """
version: 1
name: loopback
threads:
  main:
    period: 1ms
    deploy: main
    schedules: {0: [mediator, device, controller]}
activities:
  mediator: {block: mediator}
  device: {block: "tests.blocks:Loopback", params: {fail_after: FAIL}}
  controller: {block: echo, params: {dtype: float64}}
streams:
  reading: {from: device.reading, to: controller.input}
  command: {from: controller.output, to: device.command}
latencies:
  reading_to_write: {from: device.reading, to: device.command}
"""


def test_a_device_writes_what_the_cycle_computed_from_its_reading_in_the_same_cycle(tmp_path):
    result = compose(tmp_path, LOOPBACK.replace("FAIL", "0"), duration="300ms")
    assert result.outcome.status is ExitStatus.SUCCESS, result.outcome.reasons
    written = np.load(tmp_path / "run-c" / "device.npy")
    assert len(written) > 250
    # The controller ran after the device's compute and before its flush: each cycle writes its own count.
    assert np.array_equal(written, np.arange(1, len(written) + 1))
    path = result.timing["latencies"]["reading_to_write"]
    assert path["samples"] == len(written) and path["latency_us"]["max"] == 0


def test_a_failing_flush_fails_the_activity_like_a_failing_compute(tmp_path):
    result = compose(tmp_path, LOOPBACK.replace("FAIL", "50"), duration="300ms")
    assert result.outcome.status is not ExitStatus.SUCCESS
    assert any("device" in reason and "running failed" in reason for reason in result.outcome.reasons), \
        result.outcome.reasons
