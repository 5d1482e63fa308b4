"""Golden-file corpus for `hapticop validate`: one tiny composition per rule.

Each file in corpus/invalid breaks exactly one rule and is pinned here to the one error
it must produce: its rule id, the line it points at, a piece of its message and, for
'did you mean' cases, a piece of its hint. Every file in corpus/valid must produce no
diagnostics at all, warnings included.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from hapticop.validation import validate_path

CORPUS = Path(__file__).parent / "corpus"
INVALID = CORPUS / "invalid"
VALID = CORPUS / "valid"

# (file, rule, line, substring of the message, substring of the hint or None)
CASES = [
    ("invalid-ros2-own-process.yaml", "own-process", 8, "must run alone in a process of its own", "deploy: process"),
    ("invalid-ros2-shape.yaml", "bad-value", 14, "shape [4] does not fit geometry_msgs/msg/Twist", None),
    ("invalid-ros2-unit.yaml", "stream-unit", 21, "'ros2.scan' writes float32[181] [m]", None),
    ("invalid-nested-param-key.yaml", "unknown-key", 18, "unknown key 'fz_maxx'", "did you mean 'fz_max_n'?"),
    ("invalid-nested-param-value.yaml", "bad-value", 18, "'silent_ratio' must be less than 1.0 (got 1.5)", None),
    ("invalid-param-nan.yaml", "bad-value", 18, "Input should be a finite number (got nan)", None),
    ("invalid-force-model-kind.yaml", "bad-value", 18, "unknown kind 'braking'", None),
    # found while writing the corpus: each once gave a crash, a second error or a wrong line
    ("invalid-arc-undeclared-place.yaml", "unknown-place", 21, "arc to undeclared place 'EXTRA' of net 'boot'", None),
    ("invalid-mediator-off-main.yaml", "mediator", 12, "scheduled on thread 'sensors'", None),
    ("invalid-net-unbounded.yaml", "net-unbounded", 18, "place 'COUNT' is unbounded", None),
    ("invalid-period-param-mismatch.yaml", "period-mismatch", 15, "'centring.period_s' is 0.002 s", None),
    ("invalid-mode-not-live.yaml", "mode-not-live", 42, "changes 'scan_points' of 'haptic'", "retunes live: blind"),
    ("invalid-period-no-unit.yaml", "bad-duration", 10, "a duration needs a unit", None),
    ("invalid-sink-owner-writes.yaml", "flag-two-writers", 30, "is written by activity 'mediator'", None),
    ("invalid-stream-reader-twice.yaml", "stream-reader-twice", 18, "'haptic.handle_velocity' is listed twice", None),
    ("invalid-version.yaml", "bad-version", 2, "composition version 2 is not supported", None),
    ("invalid-flag-map-unknown-net-follow-on.yaml", "unknown-net", 25, "unknown net 'exti'", "did you mean 'exit'?"),
    ("invalid-priority-99-only-thread.yaml", "priority-range", 6, "priority 99 is outside 1 to 98", None),
    ("invalid-latency-unreachable.yaml", "latency-unreachable", 16, "no stream path carries data", None),
    ("invalid-latency-unknown-port.yaml", "unknown-port", 17, "has no output port 'cont'", "did you mean 'count'?"),
    ("invalid-record-unknown-stream.yaml", "unknown-stream", 16, "names stream 'cont'", "did you mean 'count'?"),
    ("invalid-phase-too-long.yaml", "bad-value", 6, "phase must be shorter than the period", None),
    # the hosts' link (docs/security.md); expired, foreign and readable keys: tests/test_link_keys.py
    ("invalid-security-no-keys.yaml", "security-keys", 3, "the hosts' link names no keys", "hapticop hosts keys"),
    ("invalid-security-endpoint.yaml", "security-endpoint", 6, "which carries no TLS", "'tls/127.0.0.1:7462'"),
    # YAML level
    ("invalid-yaml-syntax.yaml", "yaml-syntax", 7, "malformed YAML", None),
    ("invalid-duplicate-key.yaml", "duplicate-key", 7, 'duplicate key "period"', None),
    ("invalid-empty-file.yaml", "empty-file", 1, "the file is empty", None),
    ("invalid-top-level-list.yaml", "top-level-type", 1, "the document is a list, not a mapping", None),
    # schema: top level
    ("invalid-top-level-key-typo.yaml", "unknown-key", 3, "unknown key 'nmae'", "did you mean 'name'?"),
    ("invalid-missing-version.yaml", "missing-key", 1, "missing required key 'version'", None),
    # schema: threads (on a second thread; see the report about single-thread files)
    ("invalid-thread-unknown-key.yaml", "unknown-key", 11, "unknown key 'priorty'", "did you mean 'priority'?"),
    ("invalid-missing-period.yaml", "missing-key", 9, "missing required key 'period'", None),
    ("invalid-period-bad-unit.yaml", "bad-duration", 10, "'parsec' is not a unit of time or rate", None),
    ("invalid-period-zero-rate.yaml", "bad-duration", 10, "'0Hz' is a rate of zero", None),
    ("invalid-priority-99.yaml", "priority-range", 11, "priority 99 is outside 1 to 98", None),
    ("invalid-priority-0.yaml", "priority-range", 11, "priority 0 is outside 1 to 98", None),
    ("invalid-cpus-repeated.yaml", "bad-value", 11, "a CPU is listed twice in [0, 0]", None),
    ("invalid-cpus-empty.yaml", "bad-value", 11, "an empty CPU set", None),
    ("invalid-deploy-value.yaml", "bad-value", 11, "'fork' is not allowed", None),
    # schema: activities and blocks
    ("invalid-block-type.yaml", "unknown-block", 17, "unknown block type 'lidarr'", "did you mean 'lidar'?"),
    ("invalid-block-import.yaml", "unknown-block", 17, "cannot import module 'my_robot.sensors'", None),
    ("invalid-block-param-value.yaml", "bad-value", 15, "'serial' is not allowed", None),
    ("invalid-falcon-usb-no-firmware.yaml", "bad-value", 14, "driver 'usb' needs 'firmware'", None),
    ("invalid-block-param-key.yaml", "unknown-key", 19, "unknown key 'pionts'", "did you mean 'points'?"),
    # needs: a simulated device and its simulator
    ("invalid-falcon-sim-no-simulator.yaml", "bad-value", 13,
     "driver 'sim' needs 'simulator': the activity that simulates the device (a falcon_simulator)", None),
    ("invalid-lidar-simulator-real-driver.yaml", "bad-value", 14,
     "'simulator' goes with driver 'sim' only (the driver is 'tcp')", None),
    ("invalid-falcon-sim-unscheduled.yaml", "missing-need", 13,
     "'falcon' needs 'falcon_sim' (with driver 'sim': the activity that simulates the device), which is in no "
     "thread's schedule", "schedule 'falcon_sim' on a thread"),
    ("invalid-falcon-sim-misspelt.yaml", "missing-need", 13,
     "'falcon' needs an activity 'falcon_sm' that provides 'falcon_device'", "did you mean 'falcon_sim'?"),
    ("invalid-falcon-sim-not-a-falcon.yaml", "missing-need", 13,
     "'falcon' needs 'lidar' to provide 'falcon_device'", None),
    ("invalid-lidar-sim-no-simulator.yaml", "missing-need", 16,
     "'lidar' needs an activity 'lidar_sim' that provides 'tim561'", "built-in: tim561_simulator"),
    ("invalid-tim561-no-world.yaml", "missing-need", 17,
     "'lidar_sim' needs an activity 'hallway' that provides 'hallway'", "built-in: scene_world"),
    ("invalid-ethercat-sim-no-plant.yaml", "missing-need", 19,
     "'ethercat' needs an activity 'ropod_plnt' that provides 'ropod_wheels'", "did you mean 'ropod_plant'?"),
    # schema: streams
    ("invalid-bad-name.yaml", "bad-name", 17, "'Pos' is not a valid name", None),
    ("invalid-stream-from-list.yaml", "stream-writers", 17, "exactly one writer port, got 2", None),
    ("invalid-policy-kind.yaml", "bad-value", 20, "unknown kind 'ring'", None),
    ("invalid-queue-capacity.yaml", "bad-value", 20, "'capacity' must be at least 1 (got 0)", None),
    # threads, schedules, mediator, rates
    ("invalid-no-schedule-0.yaml", "schedule-0", 7, "thread 'main' has no schedule 0", None),
    ("invalid-schedule-repeat.yaml", "schedule-repeat", 8, "activity 'mediator' appears twice in schedule 0", None),
    ("invalid-activity-two-threads.yaml", "activity-two-threads", 12,
     "activity 'lidar' is scheduled on threads 'main' and 'sensors'", None),
    ("invalid-unknown-activity.yaml", "unknown-activity", 13, "unknown activity 'lidr'", "did you mean 'lidar'?"),
    ("invalid-reserved-name.yaml", "reserved-name", 10, "'system' cannot name an activity", None),
    ("invalid-no-main-thread.yaml", "main-thread", 3, "no thread has 'deploy: main'", None),
    ("invalid-two-main-threads.yaml", "main-thread", 11, "threads 'main' and 'other' both have 'deploy: main'", None),
    ("invalid-no-mediator.yaml", "mediator", 9, "no activity uses block 'mediator'", None),
    ("invalid-two-mediators.yaml", "mediator", 13, "'mediator' and 'mediator_2' are both mediators", None),
    ("invalid-mediator-not-in-schedule.yaml", "mediator", 9,
     "schedule 1 of main thread 'main' lacks the mediator", None),
    ("invalid-rate-mismatch.yaml", "rate", 10, "activity 'falcon' (falcon) cannot run at 15 Hz", None),
    ("invalid-start-never-requested.yaml", "start-never-requested", 11,
     "'threads.sensors' starts on request, but no flag map writes", None),
    # streams and ports
    ("invalid-stream-unknown-port.yaml", "unknown-port", 17, "has no output port 'positon'",
     "did you mean 'position'?"),
    ("invalid-stream-unknown-activity.yaml", "unknown-activity", 17, "unknown activity 'falcn' in port reference",
     "did you mean 'falcon'?"),
    ("invalid-stream-direction.yaml", "port-direction", 21, "'lidar.angles' is an output port", None),
    ("invalid-stream-dtype.yaml", "stream-dtype", 18, "dtype mismatch: 'falcon.buttons' writes uint8[]", None),
    ("invalid-stream-shape.yaml", "stream-shape", 21,
     "shape mismatch: 'lidar_400.ranges' writes float32[400] [m], 'haptic.ranges' reads float32[811]", None),
    ("invalid-stream-unit.yaml", "stream-unit", 19, "unit mismatch: 'haptic.velocity_setpoint'", None),
    ("invalid-port-two-writers.yaml", "port-writers", 19,
     "'haptic.handle_position' is written by 2 streams (pos, pos_2)", None),
    ("invalid-input-unconnected.yaml", "input-unconnected", 15, "required input 'haptic.handle_velocity'", None),
    ("invalid-stream-sync-none.yaml", "stream-thread-safety", 20, "with 'sync: none'", None),
    ("invalid-block-flag-never-written.yaml", "flag-no-writer", 15,
     "activity 'haptic' waits for flag 'haptic.resources_ready' but no flag map writes it", None),
    # coordination: nets
    ("invalid-marking-undeclared-place.yaml", "unknown-place", 18, "initial marking of undeclared place 'BEGIN'", None),
    ("invalid-terminal-undeclared-place.yaml", "unknown-place", 19, "terminal undeclared place 'END'", None),
    ("invalid-transition-no-input.yaml", "transition-no-input", 21, "transition 'finish' has no input place", None),
    ("invalid-net-dead-marking.yaml", "net-dead-marking", 14, "dead marking {MIDDLE: 1} after [begin]", None),
    ("invalid-net-terminal-unreachable.yaml", "net-terminal-unreachable", 14,
     "can never reach a terminal place (EXIT)", None),
    ("invalid-net-livelock.yaml", "net-livelock", 14, "transitions [ping, pong] can fire in a cycle", None),
    # coordination: flag maps and flags
    ("invalid-flag-map-unknown-net.yaml", "unknown-net", 24, "unknown net 'bot'", "did you mean 'boot'?"),
    ("invalid-flag-map-undeclared-place.yaml", "unknown-place", 29,
     "flag map binding to undeclared place 'EXITED'", "did you mean 'EXIT'?"),
    ("invalid-unknown-flag.yaml", "unknown-flag", 27, "unknown flag 'system.shutdown_request'",
     "did you mean 'system.shutdown_requested'?"),
    ("invalid-source-never-written.yaml", "flag-no-writer", 27,
     "flag 'mediator.lcsm.request_running' is read by activity 'mediator': no one writes it", None),
    ("invalid-sink-two-writers.yaml", "flag-two-writers", 33, "already written by flag map 'exit'", None),
    ("invalid-coupling-flag-unread.yaml", "flag-no-reader", 32, "flag 'flags.stopped' is read by no one", None),
    ("invalid-flag-consumed-twice.yaml", "flag-consumed-twice", 34,
     "'system.shutdown_requested' is consumed by two converting sources", None),
    ("invalid-thread-never-cleaned.yaml", "thread-never-cleaned", 28,
     "the nets start thread 'sensors' but never clean it", None),
    # coordination.standard: findings in what it writes point at the part that asked for it
    ("invalid-standard-unknown-activity.yaml", "unknown-flag", 17, "unknown flag 'lidr.lcsm.running'",
     "written out from coordination.standard.wait_for.0"),
    ("invalid-standard-clash.yaml", "standard-clash", 15, "'mediator' is written by hand and by coordination.standard",
     None),
    ("invalid-standard-place-twice.yaml", "standard-clash", 18,
     "place 'STOPPING_THREADS' of net 'mediator' would be written twice", None),
    # hosts: placement, each network stream's QoS, loops through the network (docs/teleop.md)
    ("invalid-host-unknown.yaml", "host-unknown", 16, "placed on host 'robto'", "hosts: desk, robot"),
    ("invalid-host-missing.yaml", "host-missing", 13, "thread 'robot_main' names no host", None),
    ("invalid-host-unknown-place.yaml", "host-unknown-place", 4, "would hold place 'WHEEL_FAULT' while the link",
     "name a place of coordination.standard.sources"),
    ("invalid-host-split-activity.yaml", "host-split-activity", 11, "'counter' is scheduled on hosts desk, robot",
     None),
    ("invalid-host-transport.yaml", "host-transport", 6, "host 'desk' asks for the low-latency transport but host "
     "'robot' does not", "the same 'transport:' on every host"),
    ("invalid-host-reserved-name.yaml", "host-reserved-name", 14, "stream 'bridge_rtt' has the name the host split "
     "gives each host's network bridge", "rename it"),
    ("invalid-network-no-qos.yaml", "network-qos", 24, "crosses from host 'desk' to 'robot' and states no", None),
    ("invalid-network-no-deadline.yaml", "network-deadline", 27, "without a 'deadline'", None),
    ("invalid-network-unbounded.yaml", "network-unbounded", 27, "as a queue without 'depth'", None),
    ("invalid-network-blocking.yaml", "network-blocking", 28, "samples of real-time thread 'main'", None),
    ("invalid-host-part-unknown-port.yaml", "unknown-port", 25, "has no output port 'cont'", "did you mean 'count'?"),
    ("invalid-network-loop.yaml", "network-loop", 22,
     "the loop here -> there -> here closes through the network within one period", "keep the loop's"),
]

# Files that are sound but for one likely mistake: (file, rule, line, substring of the message)
WARNING_CASES = [
    ("invalid-security-insecure.yaml", "security-insecure", 3, "the hosts' link is insecure"),
    ("invalid-schedule-never-selected.yaml", "schedule-never-selected", 12,
     "schedule 1 of thread 'sensors' is never selected"),
]


@pytest.mark.parametrize(("name", "rule", "line", "message", "hint"), CASES, ids=[c[0] for c in CASES])
def test_invalid_file_gives_its_one_error(name, rule, line, message, hint):
    path = INVALID / name
    report = validate_path(path).report
    assert len(report.errors) == 1, "\n".join(d.to_text() for d in report.sorted())
    error = report.errors[0]
    assert error.rule == rule
    assert error.line == line, error.to_text()
    assert message in error.message
    if hint is not None:
        assert hint in error.hint
    assert error.file == str(path)


@pytest.mark.parametrize(("name", "rule", "line", "message"), WARNING_CASES, ids=[c[0] for c in WARNING_CASES])
def test_warning_file_gives_its_one_warning(name, rule, line, message):
    report = validate_path(INVALID / name).report
    assert report.ok and len(report.warnings) == 1, "\n".join(d.to_text() for d in report.sorted())
    warning = report.warnings[0]
    assert (warning.rule, warning.line) == (rule, line), warning.to_text()
    assert message in warning.message


def test_a_parameter_set_chosen_by_its_kind_is_no_key_of_the_path():
    """pydantic locates an error inside a discriminated union under the member's tag; the YAML has no such key."""
    error = validate_path(INVALID / "invalid-nested-param-value.yaml").report.errors[0]
    assert error.path == ("activities", "haptic", "params", "force_model", "silent_ratio")
    assert (error.line, error.column) == (18, 56)


def test_every_invalid_file_is_pinned():
    on_disk = {p.name for p in INVALID.iterdir()}
    pinned = [c[0] for c in CASES + WARNING_CASES]
    assert len(pinned) == len(set(pinned)), "a file is pinned twice"
    assert on_disk == set(pinned), {"not pinned": sorted(on_disk - set(pinned)),
                                    "missing": sorted(set(pinned) - on_disk)}


VALID_FILES = sorted(VALID.glob("*.yaml"))


@pytest.mark.parametrize("path", VALID_FILES, ids=[p.name for p in VALID_FILES])
def test_valid_file_has_no_diagnostics(path):
    report = validate_path(path).report
    assert report.diagnostics == [], "\n".join(d.to_text() for d in report.sorted())


def test_corpus_is_not_empty():
    assert len(CASES) >= 36 and len(VALID_FILES) >= 3


def test_busy_wait_beside_other_threads_is_a_warning():
    text = """
version: 1
threads:
  main: {period: 1ms, deploy: main, busy_wait: 50us, schedules: {0: [mediator]}}
  other: {period: 1ms, schedules: {0: []}}
  alone: {period: 1ms, deploy: process, busy_wait: 50us, schedules: {0: []}}
activities:
  mediator: {block: mediator}
"""
    from hapticop.validation import validate_text

    report = validate_text(text, "b.yaml").report
    assert report.ok
    [warning] = report.warnings
    assert (warning.rule, warning.path, warning.line) == ("busy-wait-shared", ("threads", "main", "busy_wait"), 4)
