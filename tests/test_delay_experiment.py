"""The delay experiment's bench: its grid (goal cells and the others), every cell's composition valid, when a
tank counts as empty, and a sweep that resumes only from runs of the same setup."""

from __future__ import annotations

import importlib.util
import json
import sys
from collections import Counter
from pathlib import Path

import pytest

from hapticop.haptics.energy_tank import EnergyTankParams

ROOT = Path(__file__).resolve().parent.parent


@pytest.fixture(scope="module")
def bench():
    sys.path.insert(0, str(ROOT / "bench"))  # it imports the hallway experiment's helpers
    try:
        spec = importlib.util.spec_from_file_location("delay_experiment", ROOT / "bench" / "delay_experiment.py")
        module = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(module)
        yield module
    finally:
        sys.path.remove(str(ROOT / "bench"))


def test_the_goal_cells_get_operators_the_others_their_own_count_and_focus_only_reorders(bench):
    jobs = bench.jobs(operators=4, others=2, others_per_round=3)
    per_cell = Counter(job[:4] for job in jobs)
    goal = [cell for cell in bench.cells() if bench.is_goal(cell)]
    assert sorted(cell[0] for cell in goal) == [0, 50, 200, 400, 1000]
    assert all(cell[1:] == (0.05, True, True) for cell in goal)
    assert len(per_cell) == 40 and len(jobs) == len(set(jobs))
    assert all(per_cell[cell] == (4 if bench.is_goal(cell) else 2) for cell in per_cell)
    focused = bench.focused(jobs)
    assert sorted(focused) == sorted(jobs)
    assert focused[0] == (1000, 0.05, True, True, 2)  # the aggressive operator at the longest round trip first
    one_each = [(rtt, 0.05, True, True, 0) for rtt in bench.ROUND_TRIPS_MS]
    assert sorted(bench.focused(bench.jobs(1, 0, 0))) == sorted(one_each)  # nothing run that was not asked for


@pytest.mark.parametrize("tank", [True, False])
@pytest.mark.parametrize("governor", [True, False])
def test_every_cells_composition_is_valid(bench, tank, governor):
    from hapticop.composition.layers import resolve
    from hapticop.composition.yamlsource import Source, read_file
    from hapticop.validation import validate_source
    from hapticop.validation.patches import apply_patch

    source = read_file(ROOT / "systems" / "teleop_sim.yaml")
    tree = apply_patch(resolve(source).tree, bench.cell_patch(400, 0.05, tank, governor, seed=7))
    validated = validate_source(Source("teleop_sim.yaml", tree, source.text), state_limit=300)
    assert validated.report.ok, [d.to_text() for d in validated.report.errors]
    activities = validated.graph.loaded.activities
    assert ("tank" in activities) is tank and ("governor" in activities) is governor
    assert "pinger" in activities  # every cell measures its round trip
    link = activities["uplink"].params.link
    assert link.delay_s == pytest.approx(0.2) and link.jitter_s == pytest.approx(0.02) and link.loss == 0.05


def test_a_tank_is_empty_at_its_floor(bench):
    params = EnergyTankParams(initial_j=0.4, max_j=0.4, min_j=0.05)
    assert EnergyTankParams().initial_j == EnergyTankParams().max_j == 0.4  # full at the start
    assert bench.tank_empty(0.05 + 3e-7, params) is True
    assert bench.tank_empty(0.0505, params) is True
    assert bench.tank_empty(0.06, params) is False
    assert bench.tank_empty(None, params) is None and bench.tank_empty(0.1, None) is None


def test_a_sweep_resumes_and_summarises_only_the_runs_of_its_setup(bench, tmp_path):
    setup = bench.setup()
    assert setup.startswith(bench.SETUP_TAG + ":")

    def run(rtt, operator, *, lowest=0.2, empty=False, of=setup):
        return {"rtt_ms": rtt, "loss": 0.05, "tank": True, "governor": True, "operator": operator,
                "profile": "nominal", "hallway": "H1", "completion_time_s": 12.0, "collisions": 0, "crash": False,
                "e_stop_m": 0.02, "t_norm": 1.05, "oscillation_index_mps": 0.08,
                "sustained_oscillation": False, "tank_level_min_j": lowest, "tank_empty": empty,
                "round_trip_max_s": rtt / 1000 + 0.001, "setup": of}

    path = tmp_path / "runs.jsonl"
    runs = [run(1000, 0), run(1000, 1, lowest=0.0, empty=True), run(400, 0), run(400, 1, of="tank-0.1J:0")]
    path.write_text("".join(json.dumps(r) + "\n" for r in runs) + json.dumps({"rtt_ms": 0}) + "\n")
    kept = bench.records(path, setup)
    assert [(r["rtt_ms"], r["operator"]) for r in kept] == [(1000, 0), (1000, 1), (400, 0)]
    table = bench.summarise(path)
    row = next(line for line in table.splitlines() if "| 1000 |" in line).split(" | ")
    assert row[4] == "2" and row[-2] == "1 of 2" and row[-1] == "1001 |"
    assert row[-3] == "0.000"
    row = next(line for line in table.splitlines() if "| 400 |" in line).split(" | ")
    assert row[4] == "1"  # the other setup's run is not counted


def test_the_readme_table_holds_the_goal_cells_only(bench, tmp_path):
    """Governor and tank on, 5 % loss: the cells the goals judge; the others stay in the full table."""
    base = {"operator": 0, "profile": "cautious", "hallway": "H1", "completion_time_s": 20.0, "collisions": 0,
            "crash": False, "e_stop_m": 0.02, "t_norm": 1.05,
            "oscillation_index_mps": 0.08, "sustained_oscillation": False, "tank_level_min_j": 0.2,
            "tank_empty": False, "round_trip_max_s": 0.2, "setup": bench.setup()}
    runs = [{**base, "rtt_ms": 200, "loss": 0.05, "tank": True, "governor": True},
            {**base, "rtt_ms": 200, "loss": 0.0, "tank": True, "governor": True},
            {**base, "rtt_ms": 200, "loss": 0.05, "tank": False, "governor": True, "tank_level_min_j": None,
             "tank_empty": None},
            {**base, "rtt_ms": 200, "loss": 0.05, "tank": True, "governor": False}]
    path = tmp_path / "runs.jsonl"
    path.write_text("".join(json.dumps(r) + "\n" for r in runs))
    rows = [line for line in bench.summarise(path, goal_only=True).splitlines() if line.startswith("| o")]
    assert rows == [next(line for line in bench.summarise(path).splitlines() if line.startswith("| on | on | 5 %"))]
    assert len([line for line in bench.summarise(path).splitlines() if line.startswith("| o")]) == 4


def test_the_reference_time_is_the_worlds_own(bench):
    """T_ref as the hallway runs' worlds computed it (their metrics.json, kept in the sweep's records), to the
    bit: both experiments judge completion time by one definition."""
    sweep = ROOT / "bench" / "results" / "hallway-sweep.jsonl"
    runs = [r for r in map(json.loads, sweep.read_text().splitlines()) if r["model"] == "braking_field+governor"]
    seen = {(r["profile"], r["variation"], r["hallway"]): r["metrics"]["t_ref_s"] for r in runs}
    assert len(seen) >= 30
    for (profile, variation, hallway), t_ref in list(seen.items())[:60]:
        assert bench.reference_time_s(profile, variation, hallway) == t_ref
    record = {"profile": "nominal", "operator": 4, "hallway": "H1", "completion_time_s": 12.0, "t_norm": 9.9}
    assert bench.judged(record)["t_norm"] == 12.0 / bench.reference_time_s("nominal", 4, "H1")
    assert bench.judged({**record, "completion_time_s": None})["t_norm"] is None
