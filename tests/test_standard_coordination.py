"""`coordination.standard`: what it writes out, that the hallway's is the nets once written by hand,
and `hapticop expand`."""

from __future__ import annotations

from typer.testing import CliRunner

from hapticop.cli import app
from hapticop.composition.description import Coordination
from hapticop.composition.yamlsource import plain, read_file
from hapticop.coordination.petri import Net
from hapticop.validation import validate_path, validate_text

from .conftest import CORPUS, ROOT, SYSTEMS

BY_HAND = ROOT / "tests" / "fixtures" / "hallway_coordination_by_hand.yaml"
# The only names that differ: the standard names an activity's places after the whole activity name.
RENAMED = {"mediator": {"REQ_CLEAN_WATCHDOG": "REQ_CLEAN_ETHERCAT_WATCHDOG", "WATCHDOG_DONE": "ETHERCAT_WATCHDOG_DONE"}}
KINDS = ("converting_sources", "tracking_sources", "converting_sinks", "tracking_sinks")


def _nets(coordination: Coordination, renamed: dict[str, dict[str, str]]) -> dict:
    """Each net as the coordinator fires it (transitions in order, arcs, initial marking, terminal places),
    places renamed."""
    out = {}
    for name, spec in coordination.nets.items():
        net, rename = Net.from_spec(spec, name), renamed.get(name, {})
        places = [rename.get(p, p) for p in net.places]
        arcs = [({places[i]: w for i, w in inputs}, {places[i]: w for i, w in outputs}, {places[i] for i in empty})
                for inputs, outputs, empty in net.arcs]
        out[name] = (list(net.transitions), arcs, {places[i]: int(n) for i, n in enumerate(net.initial) if n},
                     sorted(rename.get(p, p) for p in spec.terminal), sorted(places))
    return out


def _bindings(coordination: Coordination, renamed: dict[str, dict[str, str]]) -> set:
    """Every flag-map binding as (net, kind, flag, place): what the coordinator reads and writes each step."""
    return {(fmap.net, kind, flag, renamed.get(fmap.net, {}).get(place, place))
            for fmap in coordination.flag_maps.values()
            for kind in KINDS for flag, place in getattr(fmap, kind).items()}


def test_the_hallway_expands_into_the_nets_it_had_by_hand():
    """Same nets in the same order, same transitions in the same firing order with the same arcs, same
    markings and terminal places, same flag-map bindings and coupling flags: the coordinator does the same,
    step for step, so the run cannot differ (test_hallway_application checks the run itself)."""
    by_hand = Coordination.model_validate(plain(read_file(BY_HAND).tree)["coordination"])
    expanded = validate_path(SYSTEMS / "hallway.yaml").composition.coordination
    assert list(expanded.nets) == list(by_hand.nets) == ["mediator", "thread_lcsm", "thread_scheduler"]
    assert _nets(expanded, {}) == _nets(by_hand, RENAMED)
    assert _bindings(expanded, {}) == _bindings(by_hand, RENAMED)
    assert set(expanded.flags) == set(by_hand.flags)


def test_the_hallway_coordination_is_mostly_gone():
    """The file holds what is particular to the hallway: under a quarter of its content lines."""
    lines = [line for line in (SYSTEMS / "hallway.yaml").read_text().splitlines()
             if line.strip() and not line.lstrip().startswith("#")]
    start = lines.index("coordination:") + 1
    end = next((i for i in range(start, len(lines)) if not lines[i].startswith(" ")), len(lines))
    assert 1 + end - start < len(lines) / 4


runner = CliRunner()


def test_expand_prints_a_file_that_validates_to_the_same_coordination():
    result = runner.invoke(app, ["expand", str(SYSTEMS / "hallway.yaml")])
    assert result.exit_code == 0, result.output
    assert "standard:" not in result.stdout and "REQ_CLEAN_ETHERCAT_WATCHDOG" in result.stdout
    again = validate_text(result.stdout, "expanded.yaml")
    assert again.report.diagnostics == [], "\n".join(d.to_text() for d in again.report.diagnostics)
    original = validate_path(SYSTEMS / "hallway.yaml").composition.coordination
    assert again.composition.coordination.nets == original.nets
    assert again.composition.coordination.flag_maps == original.flag_maps


def test_expand_refuses_a_file_with_errors():
    result = runner.invoke(app, ["expand", str(CORPUS / "invalid" / "invalid-standard-clash.yaml")])
    assert result.exit_code == 1
    assert "standard-clash" in result.output and "not expanded" in result.output
    assert runner.invoke(app, ["expand"]).exit_code == 2


def test_an_extending_file_changes_the_declaration():
    """bench.yaml takes the operator's end away as a merge patch on the declaration."""
    bench = validate_path(SYSTEMS / "bench.yaml").composition.coordination
    assert "finished" not in bench.nets["mediator"].transitions
    assert "world.finished" not in bench.flag_maps["mediator"].converting_sources
    assert "shutdown" in bench.nets["mediator"].transitions


def test_the_desk_selects_only_what_it_renders():
    """No thread waits for a request, so no thread net; the robot's thread is left on schedule 0."""
    desk = validate_path(SYSTEMS / "desk.yaml").composition.coordination
    assert list(desk.nets) == ["mediator", "thread_scheduler", "hold"]
    assert set(desk.flag_maps["thread_scheduler"].converting_sinks) == {
        "threads.main.select_schedule.1", "threads.lidar.select_schedule.1"}
    assert desk.nets["mediator"].transitions["finished"].outputs == {"EXIT": 1}  # the runtime cleans the rest


BASE = """
version: 1
threads:
  main: {period: 1ms, deploy: main, schedules: {0: [mediator], 1: [mediator]}}
  sensors: {period: 15Hz, start: on_request, schedules: {0: [], 1: [lidar], 2: []}}
activities:
  mediator: {block: mediator}
  lidar: {block: lidar}
coordination:
  standard:
"""


def test_defaults_and_choices():
    """By default every on-request thread is started and schedule 1 selected wherever it exists."""
    coordination = validate_text(BASE + "    select: {sensors: 2}\n").composition.coordination
    assert coordination.flag_maps["thread_lcsm"].converting_sinks == {
        "threads.sensors.lcsm.request_running": "REQ_RUN_SENSORS",
        "threads.sensors.lcsm.request_cleaning": "REQ_CLEAN_SENSORS"}
    assert set(coordination.flag_maps["thread_scheduler"].converting_sinks) == {
        "threads.main.select_schedule.1", "threads.sensors.select_schedule.2"}
    assert list(coordination.nets["thread_scheduler"].transitions) == ["select_schedules"]


def test_a_level_into_a_standard_place_is_refused_where_it_is_written():
    text = BASE + "    sources: {lidar.lcsm.running: OPERATING}\n"
    report = validate_text(text, "x.yaml").report
    [error] = report.errors
    assert error.rule == "standard-clash" and "place 'OPERATING'" in error.message
    assert (error.path, error.line) == (("coordination", "standard", "sources", "lidar.lcsm.running"), 11)


def test_a_finding_about_an_expanded_entry_points_at_the_declaration():
    text = BASE + "    sinks: {lidar.go: OPERATING}\n"
    [error] = validate_text(text, "x.yaml").report.errors
    assert error.rule == "unknown-flag" and error.line == 11, error.to_text()
    assert error.path == ("coordination", "flag_maps", "mediator", "tracking_sinks", "lidar.go")
    assert "written out from coordination.standard.sinks.lidar.go" in error.hint


def test_the_reachability_checks_explore_the_expansion():
    """Cut short, the exploration of the expanded mediator net says so, at the 'standard:' line."""
    text = BASE + "    wait_for: [lidar]\n    clean:\n      devices: [lidar]\n"
    report = validate_text(text, "x.yaml", state_limit=5).report
    [warning] = [w for w in report.warnings if "net 'mediator'" in w.message]
    assert warning.rule == "net-state-limit"
    assert warning.line == 10
