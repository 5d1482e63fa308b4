"""Modes: parameter values that hold while a flag is true, validated and applied between two cycles."""

import itertools

import pytest

from hapticop.runtime.system import ExitStatus
from hapticop.validation import validate_text

from .runtime_helpers import compose

MODES = """
version: 1
name: modes
threads:
  main: {period: 1ms, deploy: main, schedules: {0: [mediator, grip, gain]}}
activities:
  mediator: {block: mediator}
  grip: {block: "tests.blocks:Switch", params: {on_at: 100, off_at: 200}}
  gain: {block: "tests.blocks:Gain", params: {gain: 1.0}}
modes:
  held:
    doc: the grip is held
    when: grip.on
    params:
      gain: {gain: 5.0}
"""


def test_a_mode_holds_its_values_while_its_flag_is_true(tmp_path):
    result = compose(tmp_path, MODES, duration="300ms", name="m")
    assert result.outcome.status is ExitStatus.SUCCESS, result.outcome.reasons
    run = tmp_path / "run-m"
    gains = [float(g) for g in (run / "gain.gains").read_text().split()]
    runs = [(value, len(list(group))) for value, group in itertools.groupby(gains)]
    assert [value for value, _ in runs] == [1.0, 5.0, 1.0]  # entered once, left once
    assert 95 <= runs[1][1] <= 105  # held about as long as the flag (a cycle of delay each way)
    assert (run / "gain.retuned").read_text() == "[['gain'], ['gain']]"
    system_log = (run / "system.log").read_text()
    assert "modes: entered held" in system_log and "modes: left held" in system_log
    assert "-> capability_configuration" not in (run / "gain.log").read_text().split("-> running", 1)[1]


def test_modes_reach_an_activity_in_its_own_process(tmp_path):
    # the grip counts its cycles in the worker too, so the mode holds once the worker runs
    text = MODES.replace("schedules: {0: [mediator, grip, gain]}}",
                         "schedules: {0: [mediator]}}\n  worker: {period: 1ms, deploy: process, "
                         "schedules: {0: [grip, gain]}}")
    result = compose(tmp_path, text, clock="realtime", duration="4s", name="p")
    assert result.outcome.status is ExitStatus.SUCCESS, result.outcome.reasons
    gains = [float(g) for g in (tmp_path / "run-p" / "gain.gains").read_text().split()]
    assert [value for value, _ in itertools.groupby(gains)] == [1.0, 5.0, 1.0]


def _errors(text: str):
    return validate_text(text, "modes.yaml").report.errors


@pytest.mark.parametrize("change, rule, message", [
    ("gain: {label: parked}", "mode-not-live", "mode 'held' changes 'label' of 'gain', which block"),
    ("gain: {gain: .nan}", "bad-value", "finite number"),
    ("gian: {gain: 2.0}", "unknown-activity", "unknown activity 'gian'"),
    ("gain: {gain: fast}", "bad-value", "'gain' takes a number (got 'fast')"),
])
def test_a_mode_that_cannot_hold_live_is_refused_where_it_is_written(change, rule, message):
    (error,) = _errors(MODES.replace("gain: {gain: 5.0}", change))
    assert error.rule == rule and message in error.message, error.to_text()
    assert error.line == 15


def test_a_mode_on_an_unknown_flag_or_one_no_one_writes():
    (error,) = _errors(MODES.replace("when: grip.on", "when: grip.of"))
    assert error.rule == "unknown-flag" and "did you mean 'grip.on'" in error.to_text() and error.line == 13
    text = MODES.replace("when: grip.on", "when: flags.parked").replace("modes:\n", "coordination:\n  flags:\n"
                                                                         "    parked: the operator let go\nmodes:\n")
    (error,) = _errors(text)
    assert error.rule == "flag-no-writer" and "the mode never holds" in error.message


def test_modes_that_clash_only_together_are_found():
    text = """
version: 1
threads:
  main: {period: 1ms, deploy: main, schedules: {0: [mediator, grip, haptic_stub]}}
activities:
  mediator: {block: mediator}
  grip: {block: "tests.blocks:Switch"}
  haptic_stub: {block: haptic_controller}
modes:
  soft: {when: grip.on, params: {haptic_stub: {centring: {force_limit_n: 30.0}}}}
"""
    errors = _errors(text)
    assert any(e.rule == "bad-value" and "force_limit_n" in e.to_text() for e in errors), [e.to_text() for e in errors]


def test_the_desk_parks_when_the_grip_is_let_go_and_drives_while_it_is_held(tmp_path):
    from .conftest import SYSTEMS

    result = compose(tmp_path, (SYSTEMS / "desk_modes.yaml").read_text(), duration=None, name="desk_modes")
    assert result.outcome.status is ExitStatus.SUCCESS, result.outcome.reasons
    run = tmp_path / "run-desk_modes"
    changes = [line.split("modes: ", 1)[1] for line in (run / "system.log").read_text().splitlines()
               if "modes: " in line]
    assert changes == ["entered parked", "left parked", "entered parked"]  # homing, gripped, let go
    centre = (run / "centre.log").read_text()
    assert centre.count("-> running") == 1 and "running -> capability_configuration" not in centre
