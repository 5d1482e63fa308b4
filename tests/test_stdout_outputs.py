"""`-o -` writes to standard output, as Unix tools read a lone dash, in every command that takes
-o/--output (or --csv): never a file named `-`, and the 'wrote' line kept off the data."""

from __future__ import annotations

import os

import pytest
from typer.testing import CliRunner

from hapticop.cli.main import app

from .conftest import SYSTEMS
from .runtime_helpers import compose
from .test_recording import counters

PNG = b"\x89PNG\r\n\x1a\n"
MCAP = b"\x89MCAP0\r\n"


@pytest.fixture
def here(tmp_path, monkeypatch):
    """Run in an empty directory, so a file named '-' would be seen."""
    monkeypatch.chdir(tmp_path)
    return tmp_path


@pytest.fixture(scope="module")
def recording(tmp_path_factory):
    directory = tmp_path_factory.mktemp("recorded")
    compose(directory, counters(), duration="300ms")
    return directory / "run-c" / "c.mcap"


def _no_dash_file(directory):
    assert not (directory / "-").exists() and sorted(os.listdir(directory)) == []


@pytest.mark.parametrize("form", ["svg", "dot"])
def test_graph_to_standard_output(here, form):
    result = CliRunner().invoke(app, ["graph", str(SYSTEMS / "hallway.yaml"), "--format", form, "-o", "-"])
    assert result.exit_code == 0, result.output
    assert result.stdout.lstrip().startswith("<?xml" if form == "svg" else "digraph")
    assert "wrote" not in result.stdout
    _no_dash_file(here)


def test_plot_and_csv_to_standard_output(here, recording):
    runner = CliRunner()
    table = runner.invoke(app, ["plot", str(recording), "count", "--csv", "-"])
    assert table.exit_code == 0, table.output
    assert table.stdout.splitlines()[0] == "stream,sequence,publish_time_s,log_time_s,value[0]"
    assert "wrote standard output" in table.stderr
    picture = runner.invoke(app, ["plot", str(recording), "count", "-o", "-"])
    assert picture.exit_code == 0, picture.output
    assert picture.stdout_bytes.startswith(PNG)
    both = runner.invoke(app, ["plot", str(recording), "count", "--csv", "-", "-o", "-"])
    assert both.exit_code == 2 and "cannot both be standard output" in both.stderr
    _no_dash_file(here)


def test_recover_to_standard_output_and_report_refuses_it(here, recording):
    runner = CliRunner()
    copy = runner.invoke(app, ["recover", str(recording), "-o", "-"])
    assert copy.exit_code == 0, copy.stderr
    assert copy.stdout_bytes.startswith(MCAP) and copy.stdout_bytes.endswith(MCAP)
    assert "recovered" in copy.stderr
    refused = runner.invoke(app, ["report", str(recording), "-o", "-"])
    assert refused.exit_code == 2 and "a report is a directory" in refused.stderr
    _no_dash_file(here)
