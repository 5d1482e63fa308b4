"""The messages a new user meets first, each as it reads: what was expected, in which unit, and a hint."""

import click
import pytest
import typer
from typer.testing import CliRunner

from hapticop.cli import app
from hapticop.validation import validate_text

from .conftest import CORPUS, SYSTEMS

runner = CliRunner()
WALL = (SYSTEMS / "wall.yaml").read_text()


def _only_error(text: str):
    report = validate_text(text, "wall.yaml").report
    assert len(report.errors) == 1, [d.to_text() for d in report.sorted()]
    return report.errors[0]


def test_a_wrong_type_says_what_the_field_takes_and_its_unit():
    error = _only_error(WALL.replace("kp_n_per_m: 1000.0", "kp_n_per_m: stiff"))
    assert error.message == "'kp_n_per_m' takes a number in N/m (got 'stiff')"
    assert error.hint == "write the number alone, such as 1.5: the unit (N/m) is in the key's name"
    assert "Input should be" not in error.to_text()
    error = _only_error(WALL.replace("priority: 38", "priority: high"))
    assert error.message == "'priority' takes a whole number (got 'high')" and error.line == 15


def test_a_negative_period_is_called_negative():
    error = _only_error(WALL.replace("period: 1ms", "period: -1ms"))
    assert error.message == "'-1ms' is negative: a period or rate must be positive"
    assert (error.rule, error.line) == ("bad-duration", 14)


@pytest.mark.parametrize("priority", [0, 99, 120])
def test_every_priority_outside_the_range_gets_the_same_range(priority):
    error = _only_error(WALL.replace("priority: 38", f"priority: {priority}"))
    assert error.rule == "priority-range"
    assert error.message.startswith(f"priority {priority} is outside 1 to 98: ")


def test_an_indentation_error_points_at_the_columns_to_compare():
    error = _only_error(WALL.replace("\n    deploy: main", "\n   deploy: main"))
    assert (error.rule, error.line) == ("yaml-syntax", 16)
    assert error.hint.startswith("check the indentation: line 16 starts at column 4, the line above at column 5")
    tab = _only_error("version: 1\nthreads:\n\tmain: {}\n")
    assert tab.hint == "line 3 is indented with a tab: YAML indents with spaces only"


def test_a_run_duration_offers_only_time_units():
    result = runner.invoke(app, ["compose", str(SYSTEMS / "wall.yaml"), "--duration", "5"])
    assert result.exit_code == 2
    assert "'5' has no unit: write it with one of ns, us, ms or s, such as '5s'" in " ".join(
        result.output.replace("│", " ").split())
    assert "Hz" not in result.output


def test_validate_with_nothing_to_check_is_an_error(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    result = runner.invoke(app, ["validate"])
    assert result.exit_code == 2 and "no composition files given and none in systems/" in result.output


def test_devices_with_nothing_to_look_for_says_so():
    result = runner.invoke(app, ["devices", "--no-usb"])
    assert result.exit_code == 2
    assert "nothing to look for" in result.output and "--lidar HOST[:PORT]" in result.output


def test_falcon_ik_outside_the_workspace_says_where_it_is():
    result = runner.invoke(app, ["falcon", "ik", "0.3", "0", "0.125"])
    assert result.exit_code == 1
    assert ("reaches about x -0.045 to +0.045, y -0.045 to +0.045, z 0.080 to 0.170 m"
            in " ".join(result.output.split()))


def test_lidar_decode_names_the_sensors_units():
    capture = CORPUS.parent / "fixtures" / "sick" / "cola_a" / "tim561_sRA_LMDscandata_dist_rssi16.bin"
    result = runner.invoke(app, ["lidar", "decode", str(capture)])
    assert result.exit_code == 0, result.output
    assert "scan_frequency           1500 (1/100 Hz: 15 Hz)" in result.output
    assert "measurement_frequency    162 (100 Hz: 16.2 kHz between neighbouring points)" in result.output
    assert "DIST1: 811 values from -450000 (1/10000 deg: -45 deg) in steps of 3333 (1/10000 deg: 0.3333 deg)" \
        in result.output


def _commands(command: click.Command, path: tuple[str, ...] = ()):
    yield path
    for name, sub in getattr(command, "commands", {}).items():
        yield from _commands(sub, (*path, name))


def test_help_shows_no_python_types():
    """`--strict`, not `--strict <bool>`; `--seed SEED`, not `--seed <int>`; choices as `text|json`."""
    paths = list(_commands(typer.main.get_command(app)))
    assert len(paths) > 15
    for path in paths:
        result = runner.invoke(app, [*path, "--help"], terminal_width=200)
        assert result.exit_code == 0, (path, result.output)
        for python_type in ("<bool>", "<str>", "<int", "<float", "<path>", "<list", "<text"):
            assert python_type not in result.output, (path, result.output)
    validate_help = runner.invoke(app, ["validate", "--help"], terminal_width=200).output
    assert "text|json" in validate_help and "STATE_LIMIT" in validate_help


def test_one_broken_thread_is_one_finding_not_a_cascade():
    """A thread set aside for a bad field takes its activities with it: none of them is 'never runs'."""
    hallway = (SYSTEMS / "hallway.yaml").read_text()
    line = hallway.splitlines().index("    deploy: main") + 1
    report = validate_text(hallway.replace("    deploy: main", "    deploy: fork", 1), "hallway.yaml").report
    assert [(d.rule, d.line) for d in report.sorted()] == [("bad-value", line)], [d.to_text() for d in report.sorted()]


def test_a_block_module_not_found_says_where_python_looks(tmp_path):
    composition = tmp_path / "wall.yaml"
    composition.write_text(WALL.replace("block: virtual_wall", "block: my_effects:Wall"))
    for options in ([], ["--import-blocks"]):
        result = runner.invoke(app, ["validate", *options, str(composition)])
        assert result.exit_code == 1
        assert "hint: Python looks for 'my_effects.py' (or a package of that name) beside the composition file, " \
               "in the folders on PYTHONPATH, and among installed packages" in result.output, result.output


def test_tables_print_fixed_point_and_a_ceiling_as_a_floor(tmp_path):
    """No 1.23457e+06 in a table; a percentile in the histogram's last bin is '>= 19999', not a figure."""
    import json
    from io import StringIO

    from rich.console import Console

    from hapticop.cli.report import print_results, print_timing

    thread = {"period": "1ms", "cycles": 1000, "missed_deadlines": 0, "missed_percent": None, "cpu_percent": 12.5,
              "wakeup_latency_us": {"p50": 12.0, "p99": 19999.0, "p99.9": 19999.0, "max": 1234567.8}}
    data = {"threads": {"main": thread}, "latencies": {},
            "activities": {"world": {"steps": 10, "compute_us": {"p50": 3.0, "p99": 4.5, "p99.9": 5.0, "max": 6.0}}},
            "cpu": None}
    (tmp_path / "results.json").write_text(json.dumps({"title": "run", "rows": [
        {"metric": "tiny", "value": 0.00001234, "unit": "m", "target": "", "ok": None},
        {"metric": "huge", "value": 12345678.9, "unit": "s", "target": "", "ok": True},
        {"metric": "none", "value": None, "unit": "s", "target": "", "ok": None}]}))
    out = StringIO()
    console = Console(file=out, width=200)
    print_timing(data, console, virtual=False)
    print_results(tmp_path, console)
    text = out.getvalue()
    assert "e+0" not in text and "e-0" not in text
    assert ">= 19999" in text and "1234567.8" in text
    assert "0.00001234 m" in text and "12350000 s" in text


def test_a_simulation_that_falls_behind_is_said_to_be_the_simulations_lateness():
    """A late simulated thread is named as the simulation's lateness; a late real loop is not, nor a
    simulated thread within its periods (so a device fault seen beside it is read for what it is)."""
    from hapticop.cli.report import simulation_lateness

    def thread(missed, simulation):
        return {"missed_percent": missed, "simulation": simulation}

    data = {"threads": {"simulators": thread(38.8, True), "main": thread(5.0, False),
                        "simulation": thread(0.2, True), "quiet": thread(None, True)}}
    lines = simulation_lateness(data)
    assert len(lines) == 1 and "thread simulators missed 38.8 %" in lines[0] and "simulation's" in lines[0]


def test_tests_keep_their_figures_out_of_the_output():
    """A test's measured figure goes to the `figure` fixture (listed by `pytest -v`), never printed
    into the suite's output: no print() and no capsys.disabled() in a test module."""
    import ast
    from pathlib import Path

    stray = []
    for module in sorted(Path(__file__).parent.glob("*.py")):
        for node in ast.walk(ast.parse(module.read_text())):
            if isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and node.func.id == "print":
                stray.append(f"{module.name}:{node.lineno} print()")
            if isinstance(node, ast.Attribute) and node.attr == "disabled" and getattr(node.value, "id", "") in (
                    "capsys", "capfd"):
                stray.append(f"{module.name}:{node.lineno} capsys.disabled()")
    assert stray == []
