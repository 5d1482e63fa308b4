"""The hallway sweep's summaries (hapticop.experiment.summaries, figures): a row per operator and control, every
run counted, the README's short table, and a picture per hallway, from rows as the results table holds them."""

from hapticop.experiment.figures import hallway_sweep as draw_sweep
from hapticop.experiment.summaries import hallway_readme, hallway_sweep
from hapticop.experiment.table import row


def record(control, profile, seed, *, sustained=False, side=0.5, missed=(), status="done"):
    metrics = {"n_collisions": 0, "crash": False, "e_stop_m": 0.01, "side_clearance_min_m": side, "t_norm": 1.0,
               "oscillation_index_mps": 0.07, "oscillation_s": 2.5 if sustained else 0.3,
               "sustained_oscillation": sustained, "hold_speed_mps": 0.0, "force_rate_rms_nps": 3.0,
               "frac_modified": 0.1 if control == "shared control" else None, "missed": list(missed)}
    labels = {"control": control, "hallway": "H2", "profile": profile}
    return row(f"{control}-{profile}-s{seed}", "cell", labels, seed, "test",
               {"status": status, "metrics": metrics if status == "done" else {}})


ALONE, SHARED = "operator alone", "shared control"


def test_the_summary_sets_shared_control_beside_the_operator_alone_and_draws_each_hallway(tmp_path):
    rows = [record(ALONE, "nominal", 0, side=0.27, missed=["least side clearance (dist1 = 0.4 m)"]),
            record(ALONE, "nominal", 1, sustained=True, missed=["oscillation above 0.02 m/s (1 s rms), longest"]),
            record(ALONE, "nominal", 2, status="failed"),  # a failed run is in the report's failures, not here
            record(SHARED, "nominal", 0, side=0.36)]
    table = hallway_sweep(rows)
    assert table.startswith("### H2\n")
    alone = next(line for line in table.splitlines() if "| nominal | operator alone |" in line).split(" | ")
    shared = next(line for line in table.splitlines() if "| nominal | shared control |" in line).split(" | ")
    assert alone[2:4] == ["2", "0"]  # two runs, none met every target
    assert alone[11] == "1"  # one sustained oscillation
    assert "least side clearance (1)" in alone[-1] and "oscillation above 0.02 m/s (1)" in alone[-1]
    assert shared[2:4] == ["1", "1"] and shared[7] == "0.36 / 0.36"
    pictures = draw_sweep(rows, tmp_path / "figures")
    assert [p.name for p in pictures] == ["hallway-sweep-H2.png"]
    assert pictures[0].read_bytes()[:4] == b"\x89PNG"


def test_the_readme_table_has_a_row_per_hallway_and_control_and_names_who_missed_what():
    rows = [record(ALONE, "nominal", 0, side=0.27, missed=["least side clearance (dist1 = 0.4 m)"]),
            record(ALONE, "aggressive", 0, side=0.25, missed=["least side clearance (dist1 = 0.4 m)"]),
            record(ALONE, "tremor", 0, sustained=True, missed=["oscillation above 0.02 m/s (1 s rms), longest"]),
            record(SHARED, "nominal", 0, side=0.36)]
    found = [line.split(" | ") for line in hallway_readme(rows).splitlines() if line.startswith("| H2")]
    assert [r[1] for r in found] == ["operator alone", "shared control"]
    alone, shared = found
    assert alone[2:5] == ["3", "0", "3"] and alone[5] == "0.25" and alone[7] == "1" and alone[9] == "0"
    assert alone[10] == ("least side clearance: aggressive 1, nominal 1; "
                         "oscillation above 0.02 m/s: tremor 1 |")
    assert shared[9:] == ["1", "none |"]


def test_the_hallway_reports_pictures_are_drawn_with_its_tables(tmp_path):
    """experiments/hallway.yaml names the hallway_sweep summary: its report draws the pictures beside the
    tables (and `--docs` into docs/figures/, which README.md and docs/hallway-experiment.md show)."""
    from pathlib import Path

    import pyarrow as pa

    from hapticop.experiment.checks import load
    from hapticop.experiment.report import write_report

    root = Path(__file__).resolve().parent.parent
    experiment = load(root / "experiments" / "hallway.yaml", deep=False).experiment
    rows = [record(ALONE, "nominal", 0), record(SHARED, "cautious", 1)]
    page = write_report(experiment, pa.Table.from_pylist(rows), tmp_path / "report").read_text()
    assert "![hallway-sweep-H2](plots/hallway-sweep-H2.png)" in page
    assert (tmp_path / "report" / "plots" / "hallway-sweep-H2.png").read_bytes()[:4] == b"\x89PNG"
    shown = (root / "docs" / "hallway-experiment.md").read_text() + (root / "README.md").read_text()
    assert all(f"figures/hallway-sweep-H{i}.png" in shown for i in range(1, 7))
