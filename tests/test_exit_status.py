"""The exit status of a run says when it is incomplete: an activity that started but never ran,
or results an activity promised and did not leave, fail the run with one line each."""

from __future__ import annotations

import json

import pytest
from typer.testing import CliRunner

from hapticop.blocks.base import Block
from hapticop.blocks.interface import Params
from hapticop.cli.main import app
from hapticop.runtime.system import ExitStatus

from .conftest import SYSTEMS
from .runtime_helpers import compose


class ReportParams(Params):
    write: bool = True


class Report(Block):
    """Promises report.txt, and writes it when it cleans unless told not to."""

    Params = ReportParams

    @classmethod
    def promises(cls, params: ReportParams) -> tuple[str, ...]:
        return ("report.txt",)

    def clean(self):
        if self.params.write:
            (self.run_dir / "report.txt").write_text("done")


def _report(write: bool) -> str:
    return f"""
    version: 1
    threads:
      main: {{period: 1ms, deploy: main, schedules: {{0: [mediator, report]}}}}
    activities:
      mediator: {{block: mediator}}
      report: {{block: "tests.test_exit_status:Report", params: {{write: {str(write).lower()}}}}}
    """


def test_promised_results_left_make_a_successful_run(tmp_path):
    result = compose(tmp_path, _report(write=True), duration="50ms")
    assert result.outcome.status is ExitStatus.SUCCESS, result.outcome.reasons
    assert (tmp_path / "run-c" / "report.txt").read_text() == "done"


def test_promised_results_lost_fail_the_run_with_one_line(tmp_path):
    result = compose(tmp_path, _report(write=False), duration="50ms")
    assert result.outcome.status is ExitStatus.FAILURE
    assert result.outcome.reasons == [f"'report' ran but left no report.txt in {tmp_path / 'run-c'}: results lost"]


def test_an_activity_that_never_ran_keeps_its_promise_out_of_it(tmp_path):
    """Started, never running: said once, as never running (its results were never due)."""
    text = _report(write=False).replace("[mediator, report]", "[mediator, report, stuck]") + """
      stuck: {block: "tests.blocks:Stuck", params: {stuck_in: capability_configuration}}
    """
    result = compose(tmp_path, text, duration="50ms")
    assert result.outcome.status is ExitStatus.FAILURE
    assert "'stuck' never reached running (it got as far as capability configuration)" in result.outcome.reasons
    assert not [r for r in result.outcome.reasons if r.startswith("'stuck'") and "results" in r]


def test_a_hallway_run_too_short_to_operate_says_what_never_ran(tmp_path):
    """One simulated second: the handle is not homed yet, so the haptic loop never runs and the
    world records nothing. It used to exit 0."""
    result = compose(tmp_path, (SYSTEMS / "hallway.yaml").read_text(), duration="1s", name="hallway")
    assert result.outcome.status is ExitStatus.FAILURE
    reasons = result.outcome.reasons
    assert "'haptic' never reached running (it got as far as resource configuration)" in reasons, reasons
    assert any(r.startswith("'world' ran but left no trajectory.npz, metrics.json, results.json")
               and r.endswith("results lost") for r in reasons), reasons


class VerdictParams(Params):
    met: bool = False


class Verdict(Block):
    """Leaves a results.json with one target, met or missed, as the hallway's world does."""

    Params = VerdictParams

    def clean(self):
        row = {"metric": "distance to the goal", "value": 2.5, "unit": "m", "target": "< 0.1", "ok": self.params.met}
        (self.run_dir / "results.json").write_text(json.dumps({"title": "goal", "rows": [row]}))


@pytest.mark.parametrize(("met", "check", "status", "last"), [
    (True, False, 0, "exit: success (0)"),
    (True, True, 0, "exit: success (0)"),
    (False, False, 0, "exit: success (0), but 1 target missed (goal: distance to the goal); --check makes that exit 1"),
    (False, True, 1, "exit: failure (1): 1 target missed (goal: distance to the goal)"),
])
def test_the_last_line_says_a_missed_target(tmp_path, met, check, status, last):
    """A run that misses its own targets does not end saying a plain success; --check makes it exit 1."""
    path = tmp_path / "verdict.yaml"
    path.write_text(f"""
    version: 1
    threads:
      main: {{period: 1ms, deploy: main, schedules: {{0: [mediator, verdict]}}}}
    activities:
      mediator: {{block: mediator}}
      verdict: {{block: "tests.test_exit_status:Verdict", params: {{met: {str(met).lower()}}}}}
    """)
    result = CliRunner().invoke(app, ["compose", str(path), "--clock", "virtual", "--duration", "20ms",
                                      "--run-dir", str(tmp_path / "run"), "--control", str(tmp_path / "ctl")]
                                + (["--check"] if check else []))
    assert result.exit_code == status, result.output
    assert result.output.rstrip().splitlines()[-1] == last
    assert ("target missed: goal: distance to the goal" in result.output) is not met
