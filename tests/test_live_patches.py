"""Live reconfiguration: scripted patches under the virtual clock, socket patches on a live system."""

import threading
import time

import pytest

from hapticop.composition.lcsm import State
from hapticop.runtime.control import request
from hapticop.runtime.system import ExitStatus
from hapticop.validation import validate_text

from .runtime_helpers import compose

BASE = """
version: 1
name: live
threads:
  main: {period: 1ms, deploy: main, schedules: {0: [mediator, source], 1: [mediator]}}
  worker: {period: 2ms, DEPLOY schedules: {0: [relay]}}
activities:
  mediator: {block: mediator}
  source: {block: counter}
  relay: {block: echo}
streams:
  count: {from: source.count, to: relay.input}
"""


def base(deploy="thread"):
    return BASE.replace("DEPLOY", f"deploy: {deploy},")


SCRIPTED = base() + """
patches:
  faster:
    at: 100ms
    patch: [{op: add, path: /activities/source/params, value: {step: 5}}]
  probe:
    at: 200ms
    patch:
      activities: {probe: {block: echo}}
      streams: {tap: {from: relay.output, to: probe.input}}
      threads: {main: {schedules: {0: [mediator, source, probe]}}}
  quiet:
    at: 300ms
    patch: {threads: {worker: {schedules: {0: []}}}}
"""


def test_scripted_patches_apply_at_their_time(tmp_path):
    result = compose(tmp_path, SCRIPTED, duration="400ms")
    assert result.outcome.status is ExitStatus.SUCCESS, result.outcome.reasons
    run = tmp_path / "run-c"
    system_log = (run / "system.log").read_text()
    for name, at in (("faster", "100ms"), ("probe", "200ms"), ("quiet", "300ms")):
        assert f"scripted patch '{name}' applied at {at}" in system_log
    # 'step' is a capability parameter: the counter went through capability configuration only
    source_log = (run / "source.log").read_text()
    assert "running -> capability_configuration" in source_log and "-> resource_configuration" not in source_log[100:]
    # the probe was created live and received relayed samples until the relay was disabled
    assert "creation -> resource_configuration" in (run / "probe.log").read_text()
    steps = result.timing["activities"]
    assert 40 <= steps["relay"]["steps"] <= 160  # only until 300 ms
    assert result.states["probe"] is State.DONE


def test_a_scripted_patch_that_would_be_refused_is_a_validation_error():
    text = base() + """
patches:
  slower:
    at: 1s
    patch: [{op: replace, path: /threads/main/period, value: 2ms}]
"""
    report = validate_text(text, "scripted.yaml").report
    (error,) = report.errors
    assert error.rule == "scripted-patch" and "patch 'slower' would be refused" in error.message
    assert "period" in error.message and error.line > 0


def test_scripted_runs_are_deterministic(tmp_path):
    a = compose(tmp_path, SCRIPTED, duration="400ms", name="a")
    b = compose(tmp_path, SCRIPTED, duration="400ms", name="b")
    assert a.timing["activities"]["relay"]["steps"] == b.timing["activities"]["relay"]["steps"]
    assert (tmp_path / "run-a" / "probe.log").read_text() == (tmp_path / "run-b" / "probe.log").read_text()


@pytest.mark.parametrize("deploy", ["thread", "process"])
def test_patches_on_a_live_realtime_system(tmp_path, deploy):
    socket = tmp_path / "live.sock"
    replies = {}

    def operator(system):
        def talk():
            deadline = time.monotonic() + 20
            while time.monotonic() < deadline and not (socket.exists() and system.state("relay") is State.RUNNING):
                time.sleep(0.02)
            replies["dry"] = request(socket, {
                "op": "patch", "dry_run": True,
                "text": "- {op: add, path: /activities/relay/params, value: {unit: '1'}}"})
            replies["refused"] = request(socket, {"op": "patch", "text": "threads: {worker: {period: 3ms}}"})
            replies["invalid"] = request(socket, {
                "op": "patch", "text": "threads: {main: {schedules: {0: [mediator, source, ghost]}}}"})
            replies["disable"] = request(socket, {"op": "patch", "text": "threads: {worker: {schedules: {0: []}}}"})
            replies["status"] = request(socket, {"op": "status"})
        threading.Thread(target=talk, daemon=True).start()

    result = compose(tmp_path, base(deploy), clock="realtime", duration="3s", on_start=operator, control=str(socket))
    assert result.outcome.status is ExitStatus.SUCCESS, result.outcome.reasons
    assert replies["dry"]["ok"] and replies["dry"]["applied"] is False and "+" in replies["dry"]["diff"]
    assert not replies["refused"]["ok"]
    assert replies["refused"]["diagnostics"][0]["rule"] == "patch-unsupported"
    assert not replies["invalid"]["ok"] and replies["invalid"]["diagnostics"][0]["rule"] == "unknown-activity"
    assert replies["disable"]["ok"] and replies["disable"]["applied"] is True
    status = replies["status"]["status"]
    assert status["threads"]["worker"]["schedule"] == 0 and status["activities"]["relay"]["state"] == "running"
    # the relay stopped being stepped once disabled: far fewer steps than the 1500 cycles of 3 s
    assert result.timing["activities"]["relay"]["steps"] < 1400


NOT_FINITE = [
    "- {op: add, path: /activities/noise/params, value: {sigma: .nan}}",
    "activities: {noise: {params: {sigma: .inf}}}",
    '[{"op": "add", "path": "/activities/noise/params", "value": {"sigma": NaN}}]',
    '[{"op": "add", "path": "/activities/noise/params", "value": {"sigma": -Infinity}}]',
]


def test_a_live_patch_with_a_value_that_is_not_finite_is_refused_and_changes_nothing(tmp_path):
    from .control_helpers import while_running

    def work(path, system):
        before = system.composition.model_dump()
        finite = request(path, {"op": "patch", "dry_run": True,
                                "text": "- {op: add, path: /activities/noise/params, value: {sigma: 2.0}}"})
        assert finite["ok"] is True, finite  # the same change with a number is one a running system takes
        for text in NOT_FINITE:
            reply = request(path, {"op": "patch", "text": text})
            assert reply["ok"] is False, (text, reply)
            found = reply["diagnostics"][0]
            assert found["rule"] == "bad-value" and "finite number" in found["message"], (text, found)
            assert found["line"] >= 1
        assert request(path, {"op": "status"})["ok"] is True
        assert system.composition.model_dump() == before

    while_running(tmp_path, work)


def test_a_patch_whose_aliases_would_expand_without_bound_is_refused_at_once(tmp_path):
    from hapticop.validation.patches import PatchError, load_patch

    levels = "".join(f"    l{i}: &l{i} [" + ", ".join([f"*l{i - 1}"] * 10) + "]\n" for i in range(1, 9))
    text = "- op: test\n  path: /name\n  value:\n    l0: &l0 [x, x, x, x, x, x, x, x, x, x]\n" + levels
    with pytest.raises(PatchError) as caught:
        load_patch(text, "laughs.yaml")
    found = caught.value.diagnostics[0]
    assert found.rule == "yaml-too-large" and found.file == "laughs.yaml" and "YAML aliases expand" in found.message
    assert load_patch(text[: text.index("    l2:")], "few.yaml")  # a few aliases are fine
