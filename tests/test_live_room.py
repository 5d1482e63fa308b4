"""Live additions past the region's spare room are refused whole, before anything changes: by
`validate` for a file's scripted patches, and by the running system for what validation cannot
know (patches asked over the socket, several prepared together)."""

from __future__ import annotations

import json

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


def test_a_live_addition_past_the_room_is_refused_whole_and_the_system_runs_on(tmp_path):
    """Over the socket: a patch adding more activities than the region has room for is refused
    before anything changes (the description stays as it was, no activity is added); one that
    fits is applied; then the room left is what counts."""
    from hapticop.composition.lcsm import State
    from hapticop.control.client import request

    from .control_helpers import PATIENCE_S, while_running

    def adding(count: int, first: int = 0) -> str:
        return "activities: {" + ", ".join(f"p{i}: {{block: counter}}" for i in range(first, first + count)) + "}"

    def work(path, system):
        before = system.composition.model_dump()
        too_many = request(path, {"op": "patch", "text": adding(SPARE_ACTIVITIES + 1)}, timeout=PATIENCE_S)
        assert too_many["ok"] is False and "room" in json.dumps(too_many), too_many
        assert system.composition.model_dump() == before
        assert not {f"p{i}" for i in range(SPARE_ACTIVITIES + 1)} & set(system.runners)
        assert request(path, {"op": "status"}, timeout=PATIENCE_S)["ok"] is True

        some = request(path, {"op": "patch", "text": adding(SPARE_ACTIVITIES - 2)}, timeout=PATIENCE_S)
        assert some["ok"] is True and some["applied"] is True, some
        after = system.composition.model_dump()
        assert set(after["activities"]) - set(before["activities"]) == {f"p{i}" for i in range(SPARE_ACTIVITIES - 2)}
        past = request(path, {"op": "patch", "text": adding(3, first=SPARE_ACTIVITIES)}, timeout=PATIENCE_S)
        assert past["ok"] is False and "room" in json.dumps(past), past
        assert system.composition.model_dump() == after
        status = request(path, {"op": "status"}, timeout=PATIENCE_S)["status"]
        assert not {f"p{i}" for i in range(SPARE_ACTIVITIES, SPARE_ACTIVITIES + 3)} & set(status["activities"])
        assert system.state("source") is State.RUNNING

    while_running(tmp_path, work, text=BASE, ready="source")


def test_racing_additions_that_fit_alone_but_not_together_have_one_winner(tmp_path):
    import threading

    from hapticop.control.client import request

    from .control_helpers import PATIENCE_S, while_running

    half = SPARE_ACTIVITIES // 2 + 1  # each fits the room alone, the two together do not
    texts = ["activities: {" + ", ".join(f"{who}{i}: {{block: counter}}" for i in range(half)) + "}" for who in "ab"]

    def work(path, system):
        before = set(system.composition.activities)
        replies: list[dict] = []
        racers = [threading.Thread(target=lambda t=t: replies.append(request(path, {"op": "patch", "text": t},
                                                                              timeout=PATIENCE_S)))
                  for t in texts]
        for racer in racers:
            racer.start()
        for racer in racers:
            racer.join(PATIENCE_S * 2)
        assert sorted(r["ok"] for r in replies) == [False, True], replies
        added = set(system.composition.activities) - before
        assert added in ({f"a{i}" for i in range(half)}, {f"b{i}" for i in range(half)}), added
        assert added <= set(system.runners)

    while_running(tmp_path, work, text=BASE, ready="source")
