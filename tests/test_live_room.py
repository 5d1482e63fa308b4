"""Live additions past the region's spare room are refused whole, before anything changes: by
`validate` for a file's scripted patches, and by the running system for what validation cannot
know (patches asked over the socket, several prepared together)."""

from __future__ import annotations

from hapticop.composition.description import SPARE_ACTIVITIES
from hapticop.runtime.system import ExitStatus
from hapticop.validation import validate_text

from .runtime_helpers import compose

BASE = """
version: 1
name: room
threads:
  main: {period: 1ms, deploy: main, schedules: {0: [mediator, source]}}
activities:
  mediator: {block: mediator}
  source: {block: counter}
"""


def _adding(name: str, at: str, count: int, first: int = 0) -> str:
    probes = ", ".join(f"p{i}: {{block: counter}}" for i in range(first, first + count))
    return f"""  {name}:
    at: {at}
    patch:
      activities: {{{probes}}}
"""


def test_validate_refuses_scripted_additions_past_the_room():
    text = BASE + "patches:\n" + _adding("many", "100ms", SPARE_ACTIVITIES + 1)
    report = validate_text(text, "room.yaml").report
    (error,) = report.errors
    assert error.rule == "scripted-patch" and "room for 16 added activities" in error.message
    assert error.path[:2] == ("patches", "many")
    fits = validate_text(BASE + "patches:\n" + _adding("some", "100ms", SPARE_ACTIVITIES), "room.yaml").report
    assert fits.ok, fits.diagnostics


def test_validate_counts_the_additions_of_all_scripted_patches():
    text = BASE + "patches:\n" + _adding("first", "100ms", 10) + _adding("second", "200ms", 10, first=10)
    (error,) = validate_text(text, "room.yaml").report.errors
    assert error.path[:2] == ("patches", "second") and "add 20 activities by then" in error.message


def test_a_patch_that_no_longer_fits_when_due_is_refused_whole_and_the_run_goes_on(tmp_path, monkeypatch):
    """The room checked again when the patch is applied: a run whose spare room is smaller than
    validation assumed (here, as after additions validation could not see) refuses the patch
    before any of it is applied, reports why, and runs to its end."""
    import hapticop.runtime.region as region

    text = BASE + "patches:\n" + _adding("first", "100ms", 3) + _adding("second", "200ms", 3, first=3)
    assert validate_text(text, "room.yaml").report.ok
    monkeypatch.setattr(region, "SPARE_ACTIVITIES", 4)  # the running system keeps room for 4
    result = compose(tmp_path, text, duration="400ms", name="room")
    assert result.outcome.status is not ExitStatus.SUCCESS  # a refused scripted patch is a failed run
    assert any("scripted patch 'second' refused: no room for 3 more activities: 1 of the 4" in reason
               for reason in result.outcome.reasons), result.outcome.reasons
    log = (tmp_path / "run-room" / "system.log").read_text()
    assert "scripted patch 'first' applied" in log and "internal error" not in log
    states = result.states
    assert {"p0", "p1", "p2"} <= set(states) and not {"p3", "p4", "p5"} & set(states)  # nothing of 'second'
