"""The delay experiment as declared (experiments/delay.yaml): its grid (goal cells and the others), every cell's
composition valid and linked as the docs say, when a tank counts as empty, its tables from the results rows,
and the reference time the converted records are judged by (bench/convert_records.py)."""

from __future__ import annotations

import importlib.util
import json
from collections import Counter
from pathlib import Path

import pytest

from hapticop.experiment.checks import load
from hapticop.experiment.grid import runs
from hapticop.experiment.summaries import EMPTY_J, TANK_FLOOR_J, delay, delay_goal, tank_empty
from hapticop.experiment.table import row

ROOT = Path(__file__).resolve().parent.parent
ROUND_TRIPS = ["0", "50", "200", "400", "1000"]


@pytest.fixture(scope="module")
def loaded():
    found = load(ROOT / "experiments" / "delay.yaml", deep=False)
    assert found.report.ok, [d.to_text() for d in found.report.errors]
    return found


def is_goal(labels: dict) -> bool:
    return labels["loss"] == "5 %" and labels["tank"] == "on" and labels["governor"] == "on"


def test_the_goal_cells_get_200_operators_the_others_3_and_every_cell_comes_before_the_next_seed(loaded):
    every = runs(loaded.experiment)
    per_cell = Counter(r.cell.id for r in every)
    labels = {r.cell.id: r.cell.labels for r in every}
    goal = [c for c in per_cell if is_goal(labels[c])]
    assert sorted(int(labels[c]["rtt_ms"]) for c in goal) == [0, 50, 200, 400, 1000]
    assert len(per_cell) == 40 and len(every) == len({r.id for r in every}) == 5 * 200 + 35 * 3
    assert all(per_cell[c] == (200 if c in goal else 3) for c in per_cell)
    # a study cut short has covered the cells evenly: every cell's operator i before any cell's i + 1
    seeds = [r.seed for r in every]
    assert seeds == sorted(seeds) and {r.cell.id for r in every[:40]} == set(per_cell)
    assert {r.cell.id for r in every if r.seed >= 3} == set(goal)
    # operator i is profile i mod 3 with variation i; the links' seeds follow the operator
    run = next(r for r in every if r.seed == 7)
    sets = dict(run.sets)
    assert sets["activities.operator.params.variation"] == 7
    assert sets["activities.operator.params.variant"] == "nominal"
    assert sets["activities.uplink.params.link.seed"] == 1007
    assert sets["activities.downlink.params.link.seed"] == 2007


@pytest.mark.parametrize("tank", ["on", "off"])
@pytest.mark.parametrize("governor", ["on", "off"])
def test_every_cells_composition_is_valid(loaded, tank, governor):
    from hapticop.experiment.runner import compose, job
    from hapticop.experiment.study import composition_of
    from hapticop.validation import validate_source

    wanted = {"rtt_ms": "400", "loss": "5 %", "tank": tank, "governor": governor}
    run = next(r for r in runs(loaded.experiment) if r.cell.labels == wanted and r.seed == 2)
    e = loaded.experiment
    source, digest = compose(job(composition_of(loaded, run), run.patches, run.sets, run.seed, e.clock,
                                 e.duration_s, e.metrics))
    validated = validate_source(source, state_limit=300)
    assert validated.report.ok, [d.to_text() for d in validated.report.errors]
    activities = validated.graph.loaded.activities
    assert ("tank" in activities) is (tank == "on") and ("governor" in activities) is (governor == "on")
    assert "pinger" in activities  # every cell measures its round trip
    for name, seed in (("uplink", 1002), ("downlink", 2002)):
        link = activities[name].params.link
        assert link.delay_s == pytest.approx(0.2) and link.jitter_s == pytest.approx(0.02) and link.loss == 0.05
        assert link.seed == seed
    assert activities["predictor"].params.prediction.forward_delay_s == pytest.approx(0.2)
    haptic = activities["haptic"].params
    assert (haptic.governor is None) is (governor == "off")
    if governor == "off":  # M1 with its own parameters, not the hallway's tuning for the governor
        assert haptic.force_model == type(haptic.force_model)()
    if tank == "on":
        assert activities["tank"].params.tank.min_j == TANK_FLOOR_J  # the floor the summary judges empty by


def test_a_tank_is_empty_at_its_floor():
    assert EMPTY_J == 1e-3
    assert tank_empty(0.05 + 3e-7, 0.05) is True
    assert tank_empty(0.0505, 0.05) is True
    assert tank_empty(0.06, 0.05) is False
    assert tank_empty(None, 0.05) is None and tank_empty(0.1, None) is None
    assert tank_empty(0.0) is True and tank_empty(0.002) is False  # systems/teleop_sim.yaml's floor, 0 J


def delay_row(rtt, seed, *, loss="5 %", tank="on", governor="on", lowest=0.2, empty=False, status="done"):
    metrics = {"n_collisions": 0, "crash": False, "e_stop_m": 0.02, "t_norm": 1.05, "oscillation_index_mps": 0.08,
               "sustained_oscillation": False, "tank_level_min_j": lowest, "tank_empty": empty,
               "round_trip_max_s": int(rtt) / 1000 + 0.001}
    labels = {"rtt_ms": rtt, "loss": loss, "tank": tank, "governor": governor}
    return row(f"{rtt}{loss}{tank}{governor}-s{seed}", "cell", labels, seed, "test",
               {"status": status, "metrics": metrics if status == "done" else {}})


def test_the_table_counts_the_finished_runs_of_each_cell():
    rows = [delay_row("1000", 0), delay_row("1000", 1, lowest=0.0, empty=True), delay_row("400", 0),
            delay_row("400", 1, status="failed")]
    fresh = delay_row("200", 0, lowest=0.0005)  # a run of `experiment run`: no tank_empty of its own
    del fresh["metric.tank_empty"]
    table = delay(rows + [fresh])
    found = next(line for line in table.splitlines() if "| 1000 |" in line).split(" | ")
    assert found[4] == "2" and found[-2] == "1 of 2" and found[-1] == "1001 |"
    assert found[-3] == "0.000"
    found = next(line for line in table.splitlines() if "| 400 |" in line).split(" | ")
    assert found[4] == "1"  # the failed run is not counted
    found = next(line for line in table.splitlines() if "| 200 |" in line).split(" | ")
    assert found[-2] == "1 of 1"  # judged empty from its lowest level against the floor


def test_the_readme_table_holds_the_goal_cells_only():
    """Governor and tank on, 5 % loss: the cells the goals judge; the others stay in the full table."""
    rows = [delay_row("200", 0), delay_row("200", 0, loss="0 %"),
            delay_row("200", 0, tank="off", lowest=None, empty=None), delay_row("200", 0, governor="off")]
    full = [line for line in delay(rows).splitlines() if line.startswith("| o")]
    assert [line for line in delay_goal(rows).splitlines() if line.startswith("| o")] == [
        next(line for line in full if line.startswith("| on | on | 5 %"))]
    assert len(full) == 4


@pytest.fixture(scope="module")
def convert():
    spec = importlib.util.spec_from_file_location("convert_records", ROOT / "bench" / "convert_records.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_the_reference_time_is_the_worlds_own(convert):
    """T_ref as the hallway runs' worlds computed it (their metrics.json, kept in the sweep's records), to the
    bit: the converted delay records are judged by the one definition both experiments use."""
    sweep = ROOT / "bench" / "results" / "hallway-sweep.jsonl"
    records = [r for r in map(json.loads, sweep.read_text().splitlines()) if r["model"] == "braking_field+governor"]
    seen = {(r["profile"], r["variation"], r["hallway"]): r["metrics"]["t_ref_s"] for r in records
            if r["hallway"] in ("H1", "H4", "H6")}  # the hallways whose robot starts facing the end wall
    assert len(seen) >= 30
    for (profile, variation, hallway), t_ref in list(seen.items())[::7]:
        assert convert.reference_time_s(profile, variation, hallway) == t_ref
    record = {"profile": "nominal", "operator": 4, "hallway": "H1", "completion_time_s": 12.0, "t_norm": 9.9}
    assert convert.judged(record)["t_norm"] == 12.0 / convert.reference_time_s("nominal", 4, "H1")
    assert convert.judged({**record, "completion_time_s": None})["t_norm"] is None
