"""`extends`: a composition written as the differences from another."""

from __future__ import annotations

import textwrap

from hapticop.validation import validate_path

BASE = """\
version: 1
name: base
threads:
  main: {period: 1ms, deploy: main, schedules: {0: [mediator, source]}}
  slow: {period: 10ms, schedules: {0: [sink]}}
activities:
  mediator: {block: mediator}
  source: {block: counter}
  sink: {block: echo}
streams:
  count: {from: source.count, to: sink.input}
"""


def write(tmp_path, name: str, text: str):
    path = tmp_path / name
    path.write_text(textwrap.dedent(text))
    return path


def test_the_extending_file_merges_onto_its_base(tmp_path):
    write(tmp_path, "base.yaml", BASE)
    path = write(tmp_path, "variant.yaml", """\
        extends: base.yaml
        name: variant
        threads:
          slow: {period: 5ms}
          probe: {period: 1ms, schedules: {0: []}}
        """)
    validated = validate_path(path)
    assert validated.report.ok, [d.to_text() for d in validated.report.diagnostics]
    composition = validated.composition
    assert composition.name == "variant"
    assert composition.threads["slow"].period == 5_000_000 and composition.threads["slow"].schedules == {0: ["sink"]}
    assert "probe" in composition.threads


def test_findings_are_placed_in_the_file_that_wrote_the_value(tmp_path):
    base = write(tmp_path, "base.yaml", BASE.replace("period: 10ms", "period: 10parsecs"))
    variant = write(tmp_path, "variant.yaml", """\
        extends: base.yaml
        threads:
          main: {priority: 99}
        """)
    report = validate_path(variant).report
    where = {d.dotted_path: (d.file, d.line) for d in report.errors}
    assert where["threads.main.priority"] == (str(variant), 3)
    assert where["threads.slow.period"] == (str(base), 5)


def test_a_missing_or_circular_base_is_a_located_error(tmp_path):
    missing = write(tmp_path, "missing.yaml", "# variant\nextends: nowhere.yaml\n")
    [finding] = validate_path(missing).report.errors
    assert (finding.rule, finding.line) == ("extends", 2) and "nowhere.yaml" in finding.message
    write(tmp_path, "a.yaml", "extends: b.yaml\n")
    loop = write(tmp_path, "b.yaml", "extends: a.yaml\n")
    [finding] = validate_path(loop).report.errors
    assert finding.rule == "extends" and "extends itself" in finding.message


def test_the_bench_extends_the_hallway():
    from pathlib import Path

    root = Path(__file__).resolve().parent.parent
    bench = validate_path(root / "systems" / "bench.yaml")
    assert bench.report.ok
    hallway = validate_path(root / "systems" / "hallway.yaml").composition
    composition = bench.composition
    assert set(composition.threads) == set(hallway.threads) | {"probe_above", "probe_below"}
    loops = [t.priority for name, t in hallway.threads.items() if t.priority and name not in ("simulators",
                                                                                             "simulation")]
    top, low = max(loops), min(loops)  # the probes bracket the application's loops, not its simulated hardware
    assert composition.threads["probe_above"].priority > top and composition.threads["probe_below"].priority < low
    assert composition.activities.keys() == hallway.activities.keys()
    assert composition.duration and len(composition.latencies) == 3


def test_a_finding_a_variant_causes_in_its_base_points_at_the_variant(tmp_path):
    """Deleting or replacing an activity in the variant breaks lines of the base: the finding names the
    variant's line that did it, and the base's line in its hint."""
    base = write(tmp_path, "base.yaml", BASE)
    deleted = write(tmp_path, "deleted.yaml", "extends: base.yaml\nactivities:\n  sink: null\n")
    report = validate_path(deleted).report
    assert {(d.rule, d.file, d.line) for d in report.errors} == {("unknown-activity", str(deleted), 3)}
    assert {d.hint.split("; ", 1)[1] for d in report.errors} == {
        f"what it blames is written at {base}:5:40; this line changes 'sink'",
        f"what it blames is written at {base}:11:35; this line changes 'sink'"}
    replaced = write(tmp_path, "replaced.yaml", "extends: base.yaml\nactivities:\n  sink: {block: counter}\n")
    [error] = validate_path(replaced).report.errors
    assert (error.rule, error.file, error.line) == ("unknown-port", str(replaced), 3)
    assert error.hint == f"what it blames is written at {base}:11:35; this line changes 'sink'"
