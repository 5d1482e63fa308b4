"""The hallway and delay studies as declared experiments: their converted records (experiments/results/)
give the tables the README and docs quote, and those tables are the generated ones."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from hapticop.experiment.checks import load
from hapticop.experiment.grid import runs
from hapticop.experiment.regions import regions
from hapticop.experiment.report import summary
from hapticop.experiment.table import read

ROOT = Path(__file__).resolve().parent.parent
EXPERIMENTS = sorted((ROOT / "experiments").glob("*.yaml"))
DOCS = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]


@pytest.mark.parametrize("file", EXPERIMENTS, ids=lambda p: p.stem)
def test_every_converted_record_is_a_declared_run_once(file):
    loaded = load(file, deep=False)
    assert loaded.report.ok, [d.to_text() for d in loaded.report.errors]
    table = read(file.parent / "results" / file.stem)
    ids = table.column("run_id").to_pylist()
    assert len(ids) == len(set(ids)) > 1000
    assert set(ids) <= {r.id for r in runs(loaded.experiment)}


def test_the_generated_tables_in_the_readme_and_docs_are_up_to_date():
    found = 0
    for doc in DOCS:
        for name, name_of_summary, body in regions(doc.read_text()):
            table = read(ROOT / "experiments" / "results" / name)
            assert body == summary(name_of_summary, table).rstrip("\n") + "\n", (
                f"{doc.name}: the {name} {name_of_summary} table is stale: "
                f"hapticop experiment report experiments/{name}.yaml --docs")
            found += 1
    assert found >= 7  # the README's hallway table and the six per hallway, at least


def test_the_experiment_schema_is_current_and_every_experiment_file_satisfies_it():
    import jsonschema

    from hapticop.composition.yamlsource import plain, read_file
    from hapticop.experiment.schema import SCHEMA_FILE, experiment_schema, schema_text

    assert SCHEMA_FILE.read_text() == schema_text(), "run `hapticop schema --write`"
    jsonschema.Draft202012Validator.check_schema(experiment_schema())
    for file in [*EXPERIMENTS, *sorted((ROOT / "tests" / "experiments").glob("*study.yaml")),
                 *sorted((ROOT / "docs" / "examples").glob("*.yaml"))]:
        tree = plain(read_file(file).tree)
        if "composition" in tree:
            jsonschema.validate(tree, experiment_schema())


def test_the_worked_example_validates_and_a_reduced_version_of_it_runs(tmp_path):
    """docs/experiments.md's study, cut to one seed of four cells and three simulated seconds a run."""
    from hapticop.experiment.report import write_report
    from hapticop.experiment.study import run_study

    example = ROOT / "docs" / "examples" / "force_models.yaml"
    shown = (ROOT / "docs" / "experiments.md").read_text().split("## A worked example")[1].split("\n    hapticop")[0]
    lines = {line.split("#")[0].rstrip() for line in example.read_text().splitlines()}
    quoted = [line[4:].split("#")[0].rstrip() for line in shown.splitlines() if line.startswith("    ")]
    assert len(quoted) > 20 and all(line in lines for line in quoted), "docs/experiments.md shows another file"
    loaded = load(example)
    assert loaded.report.ok, [d.to_text() for d in loaded.report.errors]
    experiment = loaded.experiment
    assert len(runs(experiment)) == 2 * 2 * 3 * 10
    experiment.seeds.count = 1
    experiment.factors[2].values = ["nominal"]
    experiment.patch = {"activities": {"operator": {"params": {"time_limit_s": 3.0}},
                                       "world": {"params": {"time_limit_s": 3.0, "plot": False}}}}
    assert run_study(loaded, tmp_path / "out", workers=2) == (4, 0)
    table = read(tmp_path / "out")
    assert sorted(table.column("factor.force_model").to_pylist()) == ["M1", "M1", "thesis", "thesis"]
    page = write_report(experiment, table, tmp_path / "report").read_text()
    assert "mean peak force <= 8 N" in page and page.count("| nominal | 1 | 0 |") == 4
    for hallway in ("H1", "H3"):  # the paths per scene: both force models' runs drawn in each hallway
        picture = tmp_path / "report" / "plots" / f"paths-{hallway}.png"
        assert picture.read_bytes()[:4] == b"\x89PNG" and f"(plots/paths-{hallway}.png)" in page
    for run in table.to_pylist():
        xs, ys = json.loads(run["path"])
        assert len(xs) == len(ys) > 20 and xs[-1] > xs[0] + 0.5  # three seconds down the hallway
