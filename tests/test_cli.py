"""The command line as a user meets it: exit codes, text and JSON reports, graphs."""

import json
import subprocess
import sys

from typer.testing import CliRunner

from hapticop.cli import app

from .conftest import CORPUS, ROOT, SYSTEMS

runner = CliRunner()
BAD = CORPUS / "invalid" / "invalid-rate-mismatch.yaml"


def test_validate_without_arguments_checks_systems(monkeypatch):
    monkeypatch.chdir(ROOT)
    result = runner.invoke(app, ["validate"])
    assert result.exit_code == 0, result.output
    assert "systems/hallway.yaml: ok (0 errors, 0 warnings)" in result.output


def test_validate_reports_every_file_and_fails_on_errors():
    result = runner.invoke(app, ["validate", str(SYSTEMS / "hallway.yaml"), str(BAD)])
    assert result.exit_code == 1
    assert f"{BAD}:" in result.output and "error: threads." in result.output and "[rate]" in result.output
    assert "hallway.yaml: ok" in result.output


def test_validate_json_for_editors():
    result = runner.invoke(app, ["validate", "--format", "json", str(BAD)])
    assert result.exit_code == 1
    report = json.loads(result.output)["files"][0]
    (diagnostic,) = report["diagnostics"]
    assert report["ok"] is False and diagnostic["rule"] == "rate"
    assert diagnostic["line"] > 0 and diagnostic["column"] > 0 and diagnostic["path"][0] == "threads"


def test_strict_turns_warnings_into_failures(tmp_path):
    # An unscheduled activity is a warning: add one to a valid file.
    composition = tmp_path / "unscheduled.yaml"
    composition.write_text(
        "version: 1\nthreads:\n  main:\n    period: 1ms\n    deploy: main\n    schedules: {0: [mediator]}\n"
        "activities:\n  mediator: {block: mediator}\n  spare: {block: lidar}\n"
        "streams: {}\n"
    )
    lenient = runner.invoke(app, ["validate", str(composition)])
    strict = runner.invoke(app, ["validate", "--strict", str(composition)])
    assert lenient.exit_code == 0 and "never runs" in lenient.output
    assert strict.exit_code == 1


def test_graph_dot_and_png(tmp_path):
    result = runner.invoke(app, ["graph", str(SYSTEMS / "hallway.yaml"), "--format", "dot"])
    assert result.exit_code == 0
    dot = result.output
    for fragment in ('subgraph "cluster_thread_fieldbus"', '"activity:ropod"', 'cluster_net_thread_scheduler',
                     '"flag:system.exit"', 'velocity_setpoint: velocity_setpoint->velocity_setpoint'):
        assert fragment in dot
    png = tmp_path / "hallway.png"
    result = runner.invoke(app, ["graph", str(SYSTEMS / "hallway.yaml"), "--format", "png", "-o", str(png)])
    assert result.exit_code == 0, result.output
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and png.stat().st_size > 10_000
    svg = tmp_path / "hallway.svg"
    assert runner.invoke(app, ["graph", str(SYSTEMS / "hallway.yaml"), "-o", str(svg)]).exit_code == 0
    assert "<svg" in svg.read_text()


def test_graph_draws_the_simulators_and_what_they_stand_behind():
    """Every simulated device is an activity of its own in the picture, joined to the device block
    it serves and to the world it lives in; the hardware file has none."""
    hallway = runner.invoke(app, ["graph", str(SYSTEMS / "hallway.yaml"), "--format", "dot"]).output
    for device, simulator, kind in (("falcon", "falcon_sim", "falcon_device"), ("lidar", "lidar_sim", "tim561"),
                                    ("ethercat", "ropod_plant", "ropod_wheels"), ("lidar_sim", "world", "hallway")):
        assert f'"activity:{device}" -> "activity:{simulator}" [style=dashed, color=darkorange, ' \
               f'label="needs {kind}"]' in hallway
    assert '"activity:lidar_sim" [shape=box' in hallway  # drawn in its thread's box
    hardware = runner.invoke(app, ["graph", str(SYSTEMS / "hardware.yaml"), "--format", "dot"]).output
    assert "needs " not in hardware and "_sim" not in hardware


def test_graph_of_unloadable_file_fails_cleanly():
    result = runner.invoke(app, ["graph", str(CORPUS / "invalid" / "invalid-empty-file.yaml")])
    assert result.exit_code == 1 and "cannot draw a file that does not load" in result.output


def test_schema_check():
    assert runner.invoke(app, ["schema", "--check"]).exit_code == 0


def test_console_script_never_shows_a_traceback(tmp_path):
    """Through the real entry point, as a user runs it."""
    missing = tmp_path / "missing.yaml"
    result = subprocess.run([sys.executable, "-m", "hapticop.cli", "validate", str(missing)],
                            capture_output=True, text=True, cwd=ROOT)
    assert result.returncode == 1
    assert "Traceback" not in result.stdout + result.stderr
    assert "cannot read the file" in result.stdout


def test_version_and_counted_nouns():
    from hapticop import __version__

    result = runner.invoke(app, ["--version"])
    assert result.exit_code == 0 and result.output.strip() == f"hapticop {__version__}"
    result = runner.invoke(app, ["validate", str(BAD)])
    assert result.exit_code == 1 and result.output.rstrip().endswith("FAILED (1 error, 0 warnings)")
