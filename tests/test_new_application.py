"""`hapticop new`: what it writes validates and runs, with a built-in spring or the author's own block."""

import sys

import pytest
from typer.testing import CliRunner

from hapticop.blocks.registry import blocks_not_imported
from hapticop.cli import app
from hapticop.runtime.system import ExitStatus
from hapticop.validation import validate_path

from .runtime_helpers import compose

runner = CliRunner()


@pytest.mark.parametrize("own_block", [False, True])
def test_a_new_application_validates_and_runs(tmp_path, own_block):
    args = ["new", "desk_spring", "--dir", str(tmp_path)] + (["--block"] if own_block else [])
    result = runner.invoke(app, args)
    assert result.exit_code == 0, result.output
    yaml_file = tmp_path / "desk_spring.yaml"
    assert ("desk_spring_blocks:Spring" in yaml_file.read_text()) == own_block
    try:
        report = validate_path(yaml_file).report  # its own module is found beside it
        assert report.ok and not report.warnings, [d.to_text() for d in report.diagnostics]
        run = compose(tmp_path, yaml_file.read_text(), duration=None, name="desk_spring")
        assert run.outcome.status is ExitStatus.SUCCESS, run.outcome.reasons  # the hand's script ends the run
        assert run.timing["activities"]["spring"]["steps"] > 1000
    finally:
        sys.modules.pop("desk_spring_blocks", None)


def test_validate_finds_an_authors_module_beside_the_file_without_running_it(tmp_path):
    runner.invoke(app, ["new", "mine", "--dir", str(tmp_path), "--block"])
    (tmp_path / "mine_blocks.py").write_text((tmp_path / "mine_blocks.py").read_text() + "\nraise SystemExit(3)\n")
    with blocks_not_imported():
        report = validate_path(tmp_path / "mine.yaml").report
    assert report.ok and [w.rule for w in report.warnings] == ["block-not-imported"]
    assert "mine_blocks" not in sys.modules


def test_new_refuses_a_bad_name_and_an_existing_file(tmp_path):
    result = runner.invoke(app, ["new", "My-App", "--dir", str(tmp_path)])
    assert result.exit_code == 2 and "not a lower_snake_case name" in result.output
    assert runner.invoke(app, ["new", "app", "--dir", str(tmp_path)]).exit_code == 0
    before = (tmp_path / "app.yaml").read_text()
    result = runner.invoke(app, ["new", "app", "--dir", str(tmp_path)])
    assert result.exit_code == 2 and "exists; --force overwrites" in result.output
    assert (tmp_path / "app.yaml").read_text() == before


@pytest.mark.parametrize("block, message", [
    ("tests.blocks:SameName", "declares 'force' as both an input and an output port"),
    ("tests.blocks:BadDeclaration", "could not declare its ports for these parameters: ZeroDivisionError"),
])
def test_an_authors_block_that_cannot_declare_its_ports_is_a_located_finding(block, message):
    from hapticop.validation import validate_text

    text = f"""
version: 1
threads:
  main: {{period: 1ms, deploy: main, schedules: {{0: [mediator, mine]}}}}
activities:
  mediator: {{block: mediator}}
  mine: {{block: "{block}"}}
"""
    errors = validate_text(text, "mine.yaml").report.errors
    assert [(e.rule, e.line) for e in errors] == [("block-declaration", 7)], [e.to_text() for e in errors]
    assert message in errors[0].message
