"""The hallway experiment's sweep summary: a row per operator and control, every run counted, a picture per hallway."""

import importlib.util
import json
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def bench_module():
    spec = importlib.util.spec_from_file_location("hallway_experiment", ROOT / "bench" / "hallway_experiment.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def record(model, profile, seed, *, sustained=False, side=0.5, missed=()):
    metrics = {"n_collisions": 0, "crash": False, "e_stop_m": 0.01, "side_clearance_min_m": side, "t_norm": 1.0,
               "oscillation_index_mps": 0.07, "oscillation_s": 2.5 if sustained else 0.3,
               "sustained_oscillation": sustained, "hold_speed_mps": 0.0, "force_rate_rms_nps": 3.0,
               "frac_modified": 0.1 if model.endswith("shared") else None}
    return {"model": model, "profile": profile, "variation": seed, "hallway": "H2", "e_stop_m": 0.01,
            "metrics": metrics, "missed": list(missed)}


def test_the_summary_sets_shared_control_beside_the_operator_alone_and_draws_each_hallway(tmp_path):
    bench = bench_module()
    runs = [record("braking_field+governor", "nominal", 0, side=0.27, missed=["least side clearance (dist1 = 0.4 m)"]),
            record("braking_field+governor", "nominal", 1, sustained=True,
                   missed=["oscillation above 0.02 m/s (1 s rms), longest"]),
            record("braking_field+governor+shared", "nominal", 0, side=0.36)]
    path = tmp_path / "sweep.jsonl"
    path.write_text("".join(json.dumps(r) + "\n" for r in runs))
    table = bench.summarise_sweep(path)
    alone = next(line for line in table.splitlines() if "| nominal | operator alone |" in line).split(" | ")
    shared = next(line for line in table.splitlines() if "| nominal | shared control |" in line).split(" | ")
    assert alone[2:4] == ["2", "0"]  # two runs, none met every target
    assert alone[11] == "1"  # one sustained oscillation
    assert "least side clearance (1)" in alone[-1] and "oscillation above 0.02 m/s (1)" in alone[-1]
    assert shared[2:4] == ["1", "1"] and shared[7] == "0.36 / 0.36"
    pictures = bench.plot_sweep(path, tmp_path / "figures")
    assert [p.name for p in pictures] == ["hallway-sweep-H2.png"]
    assert pictures[0].read_bytes()[:4] == b"\x89PNG"


def test_the_readme_table_has_a_row_per_hallway_and_control_and_names_who_missed_what(tmp_path):
    bench = bench_module()
    runs = [record("braking_field+governor", "nominal", 0, side=0.27, missed=["least side clearance (dist1 = 0.4 m)"]),
            record("braking_field+governor", "aggressive", 0, side=0.25,
                   missed=["least side clearance (dist1 = 0.4 m)"]),
            record("braking_field+governor", "tremor", 0, sustained=True,
                   missed=["oscillation above 0.02 m/s (1 s rms), longest"]),
            record("braking_field+governor+shared", "nominal", 0, side=0.36)]
    path = tmp_path / "sweep.jsonl"
    path.write_text("".join(json.dumps(r) + "\n" for r in runs))
    rows = [line.split(" | ") for line in bench.summarise_for_readme(path).splitlines() if line.startswith("| H2")]
    assert [row[1] for row in rows] == ["operator alone", "shared control"]
    alone, shared = rows
    assert alone[2:5] == ["3", "0", "3"] and alone[5] == "0.25" and alone[7] == "1" and alone[9] == "0"
    assert alone[10] == ("least side clearance: aggressive 1, nominal 1; "
                         "oscillation above 0.02 m/s: tremor 1 |")
    assert shared[9:] == ["1", "none |"]
