"""Live reconfiguration: scripted patches under the virtual clock, socket patches on a live system."""

import subprocess
import sys
import time

import numpy as np
import pytest
from mcap.reader import make_reader

from hapticop.composition.lcsm import State
from hapticop.control.client import request
from hapticop.runtime.system import ExitStatus
from hapticop.validation import validate_text

from .conftest import ROOT
from .control_helpers import PATIENCE_S, while_running
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


TAP = """
      activities: {%(reader)s: {block: echo}}
      streams: {tap: {from: relay.output, to: %(reader)s.input}}
      threads: {main: {schedules: {0: [mediator, source, %(reader)s]}}}
"""


def recorded_times_ms(recording, topic: str) -> np.ndarray:
    with recording.open("rb") as stream:
        return np.array([m.publish_time for _, _, m in make_reader(stream).iter_messages(topics=[topic])]) / 1e6


def test_a_stream_added_live_is_recorded_from_then_until_it_is_removed(tmp_path):
    """A recorded run records the streams a patch adds, on a channel of their own from the moment they
    exist; a stream removed stops being recorded, and one added again under its name goes on in its channel."""
    text = base() + "record: {}\npatches:\n  plug:\n    at: 200ms\n    patch:" + TAP % {"reader": "probe"} + """
  unplug:
    at: 300ms
    patch:
      - {op: remove, path: /streams/tap}
      - {op: remove, path: /activities/probe}
      - {op: replace, path: /threads/main/schedules/0, value: [mediator, source]}
  replug:
    at: 350ms
    patch:""" + TAP % {"reader": "again"}
    result = compose(tmp_path, text, duration="500ms")
    assert result.outcome.status is ExitStatus.SUCCESS, result.outcome.reasons
    tap = recorded_times_ms(tmp_path / "run-c" / "live.mcap", "/streams/tap")
    # the relay writes every 2 ms: 50 samples while first plugged, 75 from its return to the end
    assert len(tap) == 125 and tap.min() >= 200 and not np.any((tap > 300) & (tap < 350))
    assert result.recording["streams"]["tap"] == {"written": 125, "recorded": 125, "dropped": 0}
    with (tmp_path / "run-c" / "live.mcap").open("rb") as stream:
        channels = make_reader(stream).get_summary().channels.values()
    assert [c.topic for c in channels].count("/streams/tap") == 1


def test_a_stream_nobody_reads_may_be_added_live_and_is_recorded(tmp_path):
    """A figure worth watching is given a stream without readers while the system runs."""
    text = base() + """record: {}
patches:
  watch:
    at: 200ms
    patch: {streams: {watched: {from: relay.output}}}
"""
    result = compose(tmp_path, text, duration="500ms")
    assert result.outcome.status is ExitStatus.SUCCESS, result.outcome.reasons
    watched = recorded_times_ms(tmp_path / "run-c" / "live.mcap", "/streams/watched")
    assert len(watched) == 150 and watched.min() >= 200  # the relay writes every 2 ms from then on
    assert result.recording["streams"]["watched"] == {"written": 150, "recorded": 150, "dropped": 0}


def test_a_stream_added_by_a_live_patch_reaches_the_recorders_process(tmp_path):
    """On the wall clock the recorder is a process of its own: it hears of the added stream's ring
    over its pipe and records it until the run ends."""

    def work(path, system):
        reply = request(path, {"op": "patch", "text": TAP % {"reader": "probe"}}, timeout=PATIENCE_S)
        assert reply["ok"] and reply["applied"], reply
        probe = system.runners["probe"].block
        wait_for(lambda: probe.received >= 100, "the added stream carries samples")

    while_running(tmp_path, work, text=base() + "record: {}\n", ready="relay")
    tap = recorded_times_ms(tmp_path / "run-c" / "live.mcap", "/streams/tap")
    assert len(tap) >= 100


def test_an_added_stream_whose_recorder_ring_would_not_fit_is_refused_whole(tmp_path):
    """Its ring holds 'record.depth' of its samples in the room kept for live additions: a minute of
    a 500 Hz stream does not fit, so the patch is refused before any of it applies, and says why."""
    text = base() + "record: {depth: 60s}\npatches:\n  plug:\n    at: 200ms\n    patch:" + TAP % {"reader": "probe"}
    result = compose(tmp_path, text, duration="300ms")
    assert result.outcome.status is not ExitStatus.SUCCESS
    [reason] = result.outcome.reasons
    assert "scripted patch 'plug' refused" in reason and "the recorder's rings of the new streams" in reason, reason
    assert "probe" not in result.states
    assert "tap" not in result.recording["streams"]


def hapticop_patch(path, patch: str, tmp_path, *extra: str) -> subprocess.CompletedProcess:
    """`hapticop patch SOCKET FILE` as a user types it, in its own process."""
    file = tmp_path / f"patch-{abs(hash(patch))}.yaml"
    file.write_text(patch)
    return subprocess.run([sys.executable, "-m", "hapticop.cli", "patch", str(path), str(file), *extra],
                          cwd=ROOT, capture_output=True, text=True, timeout=PATIENCE_S * 6)


def wait_for(condition, what: str) -> None:
    """Until `condition()` holds; fails (instead of hanging) when it never does."""
    deadline = time.monotonic() + PATIENCE_S
    while not condition():
        assert time.monotonic() < deadline, f"never happened: {what}"
        time.sleep(0.005)


@pytest.mark.parametrize("deploy", ["thread", "process"])
def test_patches_on_a_live_realtime_system(tmp_path, deploy):
    """A parameter change sent with `hapticop patch` reaches the running block; a refused patch,
    even one that also carries a valid change, leaves the description and the block as they were."""

    def work(path, system):
        source = system.runners["source"].block
        assert source.params.step == 1

        dry = request(path, {"op": "patch", "dry_run": True,
                             "text": "- {op: add, path: /activities/relay/params, value: {unit: '1'}}"})
        assert dry["ok"] and dry["applied"] is False and "+" in dry["diff"]
        assert system.composition.activities["relay"].params == {}

        applied = hapticop_patch(path, "activities: {source: {params: {step: 5}}}", tmp_path)
        assert applied.returncode == 0 and applied.stdout.strip().endswith("applied"), applied.stderr
        assert system.composition.activities["source"].params == {"step": 5}
        # the running block takes the new value before its next step...
        wait_for(lambda: source.params.step == 5, "the running block takes the new value")
        wait_for(lambda: system.state("source") is State.RUNNING, "the counter runs again after reconfiguring")
        counted = source.count
        wait_for(lambda: source.count >= counted + 50, "the counter counts on")
        assert (source.count - counted) % 5 == 0  # ...and counts with it

        before = system.composition.model_dump()
        for refused, rule in [
            ("threads: {worker: {period: 3ms}}", "patch-unsupported"),
            ("activities: {source: {params: {step: 7}}}\nthreads: {worker: {period: 3ms}}", "patch-unsupported"),
            ("threads: {main: {schedules: {0: [mediator, source, ghost]}}}", "unknown-activity"),
            ("activities: {source: {params: {step: seven}}}", None),
        ]:
            reply = hapticop_patch(path, refused, tmp_path)
            assert reply.returncode == 1 and "the system runs on unchanged" in reply.stderr, (refused, reply.stderr)
            assert rule is None or rule in reply.stderr, (refused, reply.stderr)
            assert system.composition.model_dump() == before, refused
            assert source.params.step == 5, refused
        counted = source.count
        wait_for(lambda: source.count >= counted + 50, "the counter counts on")
        assert (source.count - counted) % 5 == 0

        disabled = request(path, {"op": "patch", "text": "threads: {worker: {schedules: {0: []}}}"})
        assert disabled["ok"] and disabled["applied"] is True
        status = request(path, {"op": "status"})["status"]
        assert status["threads"]["worker"]["schedule"] == 0 and status["activities"]["relay"]["state"] == "running"
        # the relay is no longer stepped, though its thread goes on cycling
        steps = status["timing"]["activities"]["relay"]["steps"]
        cycles = status["timing"]["threads"]["worker"]["cycles"]
        wait_for(lambda: request(path, {"op": "status"})["status"]["timing"]["threads"]["worker"]["cycles"]
                 > cycles + 20, "the worker thread cycles on")
        assert request(path, {"op": "status"})["status"]["timing"]["activities"]["relay"]["steps"] == steps

    while_running(tmp_path, work, text=base(deploy), ready="relay")


def test_the_haptic_controllers_gain_patched_live_reaches_the_running_controller(tmp_path):
    """The hallway on the wall clock: `hapticop patch` changes the centring spring of the running haptic
    controller, whose PD is rebuilt with it; gains it must refuse (NaN, negative, or beside a change it
    cannot make live) leave the description, the block's parameters and its PD as they were."""
    from .conftest import SYSTEMS

    def work(path, system):
        haptic = system.runners["haptic"].block
        assert haptic.pd.params.kp_n_per_m == 55.0

        applied = hapticop_patch(path, "activities: {haptic: {params: {centring: {kp_n_per_m: 30.0}}}}", tmp_path)
        assert applied.returncode == 0 and applied.stdout.strip().endswith("applied"), applied.stderr
        centring = system.composition.activities["haptic"].params["centring"]
        assert centring == {"kp_n_per_m": 30.0, "kd_ns_per_m": 0.2, "force_limit_n": 10.0}  # merged, not replaced
        wait_for(lambda: haptic.params.centring.kp_n_per_m == 30.0, "the controller takes the new gain")
        wait_for(lambda: haptic.built_for is haptic.params, "the controller rebuilt its laws with the new gain")
        assert haptic.pd.params.kp_n_per_m == 30.0 and haptic.pd.params.kd_ns_per_m == 0.2

        before, params, pd = system.composition.model_dump(), haptic.params, haptic.pd
        for refused in [
            "activities: {haptic: {params: {centring: {kp_n_per_m: .nan}}}}",
            "- {op: replace, path: /activities/haptic/params/centring/kp_n_per_m, value: -5.0}",
            "activities: {haptic: {params: {centring: {kp_n_per_m: 40.0}}}}\nthreads: {main: {period: 2ms}}",
        ]:
            reply = request(path, {"op": "patch", "text": refused}, timeout=PATIENCE_S)
            assert reply["ok"] is False and reply["diagnostics"], (refused, reply)
            assert system.composition.model_dump() == before, refused
            assert haptic.params is params and haptic.pd is pd and pd.params.kp_n_per_m == 30.0, refused

    while_running(tmp_path, work, text=(SYSTEMS / "hallway.yaml").read_text(), ready="haptic")


NOT_FINITE = [
    "- {op: add, path: /activities/noise/params, value: {sigma: .nan}}",
    "activities: {noise: {params: {sigma: .inf}}}",
    '[{"op": "add", "path": "/activities/noise/params", "value": {"sigma": NaN}}]',
    '[{"op": "add", "path": "/activities/noise/params", "value": {"sigma": -Infinity}}]',
]


def test_a_live_patch_with_a_value_that_is_not_finite_is_refused_and_changes_nothing(tmp_path):
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
