"""Once: the hallway sweep's and the delay experiment's JSON-line records (bench/results/*.jsonl, made by the
scripts that experiments/hallway.yaml and experiments/delay.yaml replaced) as the tables of those two files,
so that `hapticop experiment report` reads them and a resumed `experiment run` skips them. The output is committed
(experiments/results/); the records stay as they were.

    python bench/convert_records.py

Each record becomes the row of the run the experiment file declares for it (its cell by the factors'
labels, its seed): its metrics as they were measured, `missed` the targets its world judged missed, the
wall time it took, and `message` saying where it came from. The delay records' T/T_ref is judged again by
the world's definition (T_ref from the varied operator's cruise speed), as their summary always did, and
only the records of the setup the README quotes (`tank-0.4J-pinged:c203a6ecee`) are kept.
"""

from __future__ import annotations

import functools
import json
import shutil
from pathlib import Path

from hapticop import __version__
from hapticop.experiment.checks import load
from hapticop.experiment.grid import runs
from hapticop.experiment.study import composition_text
from hapticop.experiment.table import append, open_table, row

ROOT = Path(__file__).resolve().parent.parent
CONTROLS = {"braking_field+governor": "operator alone", "braking_field+governor+shared": "shared control"}
DELAY_SETUP = "tank-0.4J-pinged:c203a6ecee"


def convert(experiment_file: Path, records: Path, labels_of, metrics_of) -> int:
    loaded = load(experiment_file, deep=False)
    experiment = loaded.experiment
    by_key = {(tuple(sorted(r.cell.labels.items())), r.seed): r for r in runs(experiment)}
    out = experiment_file.parent / "results" / experiment_file.stem
    shutil.rmtree(out, ignore_errors=True)
    open_table(out, experiment.name, experiment.meaning(composition_text(loaded)), __version__)
    rows, seen = [], set()
    for record in map(json.loads, filter(str.strip, records.read_text().splitlines())):
        found = labels_of(record)
        if found is None:
            continue
        labels, seed = found
        run = by_key[(tuple(sorted(labels.items())), seed)]
        assert run.id not in seen, run.id
        seen.add(run.id)
        outcome = {"status": "done", "message": f"converted from bench/results/{records.name}",
                   "wall_s": record["wall_s"], "composition_hash": "", "metrics": metrics_of(record)}
        rows.append(row(run.id, run.cell.id, run.cell.labels, run.seed, __version__, outcome))
    append(out, rows)
    return len(rows)


def hallway_labels(record: dict):
    return {"control": CONTROLS[record["model"]], "hallway": record["hallway"], "profile": record["profile"]}, \
        record["variation"]


def hallway_metrics(record: dict) -> dict:
    return {**record["metrics"], "missed": record["missed"]}


@functools.cache
def reference_time_s(profile: str, variation: int, hallway: str) -> float:
    """§5's autonomous reference for this operator, as the world computes it (`autonomous_reference_s` at the
    varied profile's cruise speed over the robot's start clearance to the end wall less dist2), so both
    experiments judge completion time alike."""
    import numpy as np

    from hapticop.sim.hallway_task import Hallway
    from hapticop.sim.metrics import autonomous_reference_s
    from hapticop.sim.operator import BlindOperator

    task = Hallway.named(hallway)
    front_m = float(task.clearances(np.array([task.start]))[0, 1])
    return autonomous_reference_s(front_m - task.dist2_m,
                                  BlindOperator.variant(profile, seed=variation).profile.cruise_speed())


def judged(record: dict) -> dict:
    """A delay record with T_ref and T/T_ref by the world's definition. Runs before 2026-11-25 stored the
    script's own T_ref, from the un-varied profile's cruise speed; their measured completion times are judged
    again here, as the script's summary always did."""
    t_ref = reference_time_s(record["profile"], record["operator"], record.get("hallway", "H1"))
    completion = record["completion_time_s"]
    return {**record, "t_ref_s": t_ref, "t_norm": completion / t_ref if completion is not None else None}


def delay_labels(record: dict):
    if record.get("setup") != DELAY_SETUP:
        return None
    on = {True: "on", False: "off"}
    return {"rtt_ms": str(record["rtt_ms"]), "loss": f"{100 * record['loss']:.0f} %", "tank": on[record["tank"]],
            "governor": on[record["governor"]]}, record["operator"]


def delay_metrics(record: dict) -> dict:
    record = judged(record)
    names = {"collisions": "n_collisions"}
    kept = ("ended_by", "crash", "collisions", "e_stop_m", "side_clearance_min_m", "completion_time_s", "t_ref_s",
            "t_norm", "oscillation_index_mps", "sustained_oscillation", "divergence", "oscillation_s",
            "force_peak_n", "tank_level_min_j", "tank_max_j", "tank_empty", "round_trip_max_s", "link_loss_max")
    return {names.get(k, k): record.get(k) for k in kept}


def main() -> None:
    results = ROOT / "bench" / "results"
    n = convert(ROOT / "experiments" / "hallway.yaml", results / "hallway-sweep.jsonl", hallway_labels,
                hallway_metrics)
    print(f"hallway: {n} runs")
    if (ROOT / "experiments" / "delay.yaml").exists():
        n = convert(ROOT / "experiments" / "delay.yaml", results / "delay-experiment.jsonl", delay_labels,
                    delay_metrics)
        print(f"delay: {n} runs")


if __name__ == "__main__":
    main()
