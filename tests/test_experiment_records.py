"""The hallway and delay studies as declared experiments: their converted records (experiments/results/)
give the tables the README and docs quote, and those tables are the generated ones."""

from __future__ import annotations

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
