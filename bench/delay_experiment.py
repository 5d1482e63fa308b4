"""The delay experiment: the hallway behind an emulated link, seeded blind operators, under the virtual clock.

Each run is systems/teleop_sim.yaml with a merge patch setting the link (round trip split evenly
between the uplink and the downlink, jitter a fraction of each one-way delay, loss on both), the
predictor's forward delay, whether the energy tank sits on the Falcon's port and whether the robot's
governor runs, plus the operator (the hallway experiment's profiles, seeded variations). The link's
seeds follow the operator, so every cell sees the same operators and the same luck on the link.
Operator i is profile i mod 3 with variation i. Results are appended as JSON lines, so an
interrupted sweep keeps what it measured; `--summary` turns them into docs/teleop.md's table.

The goal cells (5 % loss, tank and governor on) get `--operators` each; the other cells get
`--others` each, a few after each round of the goal cells, so that a sweep cut short has covered
the goal cells uniformly and spread the rest over the other cells.

    nice -n 10 python bench/delay_experiment.py --operators 200 --others 3 --others-per-round 2 --workers 2
    python bench/delay_experiment.py --summary

Each record holds the cell, the operator, collisions, the stop error, the completion time against T_ref,
the oscillation index, how long it stayed above its limit and whether that was sustained, the tank's lowest
level and whether it ran empty (within EMPTY_J of its floor), and the largest round trip and loss the pings
measured. A rerun resumes: the runs already in `--out` with this setup are skipped.
"""

from __future__ import annotations

import argparse
import functools
import json
import math
import tempfile
import time
from collections import defaultdict
from concurrent.futures import ProcessPoolExecutor, as_completed
from pathlib import Path

from hallway_experiment import TIME_LIMIT_S, _median

ROOT = Path(__file__).resolve().parent.parent
RESULTS = ROOT / "bench" / "results" / "delay-experiment.jsonl"
ROUND_TRIPS_MS = (0, 50, 200, 400, 1000)
PROFILES = ("cautious", "nominal", "aggressive")
JITTER = 0.10  # of each one-way delay
EMPTY_J = 1e-3
"""A tank this close to its floor counts as empty: it is (or was about to be) scaling the cue down."""
SETUP_TAG = "tank-0.4J-pinged"
"""What the runs are made with, by name (bump it when a change outside the compositions alters results); with
a digest of the compositions it makes a record's `setup`. A record of another setup is neither resumed from nor
summarised (the first runs, a 0.1 J tank and the round trip a parameter: delay-experiment-0.1J.jsonl)."""
MAIN_SCHEDULE = ("mediator", "falcon", "downlink", "pinger", "predictor", "haptic", "tank", "uplink", "governor")
"""systems/teleop_sim.yaml's main loop; a cell takes the tank or the governor out of it."""
MAX_AGE_OVER_RTT_MS = 100  # the received setpoint's deadline: a sample's own jitter and a few losses, no more


def operator(i: int) -> tuple[str, int]:
    return PROFILES[i % len(PROFILES)], i


def cell_patch(rtt_ms: int, loss: float, tank: bool, governor: bool, seed: int) -> dict:
    """The merge patch on systems/teleop_sim.yaml for one cell and one operator's link seeds."""
    one_way = rtt_ms / 2000.0
    link = {"delay_s": one_way, "jitter_s": JITTER * one_way, "loss": loss}
    schedule = list(MAIN_SCHEDULE)
    activities: dict = {
        "uplink": {"params": {"link": {**link, "seed": 1000 + seed}}},
        "downlink": {"params": {"link": {**link, "seed": 2000 + seed}}},
        "predictor": {"params": {"prediction": {"forward_delay_s": one_way}}},
    }
    streams: dict = {}
    if not tank:
        schedule.remove("tank")
        activities["tank"] = None
        streams.update({
            "handle_force": {"from": "haptic.force"},
            "controller_force": None, "tank_level": None,
            "environment_force": {"to": ["operator.environment_force", "world.environment_force"]},
            "handle_velocity": {"to": ["haptic.handle_velocity"]}})
    if not governor:  # neither the robot's governor nor the operator's side's model of it
        schedule.remove("governor")
        activities["governor"] = None
        activities["haptic"] = {"params": {"governor": None}}
        streams.update({
            "governed_setpoint": None,
            "setpoint_received": {"to": ["ropod.velocity_setpoint"]},
            "scan_ranges": {"to": ["downlink.ranges"]},
            "scan_angles": {"to": ["downlink.angles"]}})
    return {"threads": {"main": {"schedules": {1: schedule}}}, "activities": activities, "streams": streams}


@functools.cache
def reference_time_s(profile_name: str, variation: int, hallway: str) -> float:
    """§5's autonomous reference for this operator, as the world computes it (`metrics.autonomous_reference_s`
    at the varied profile's cruise speed), so both experiments judge completion time alike."""
    import numpy as np

    from hapticop.sim.hallway import HallwayGeometry, World
    from hapticop.sim.metrics import autonomous_reference_s
    from hapticop.sim.operator import BlindOperator

    g = HallwayGeometry.named(hallway)
    front0 = float(World.from_geometry(g).clearances(np.array([g.start]), g.footprint, kinds=("end",))[0])
    return autonomous_reference_s(front0 - g.dist2_m,
                                  BlindOperator.variant(profile_name, seed=variation).profile.cruise_speed())


def judged(record: dict) -> dict:
    """A record with T_ref and T/T_ref by the world's definition. Runs before 2026-11-25 stored the bench's own
    T_ref, from the un-varied profile's cruise speed; their measured completion times are judged again here."""
    t_ref = reference_time_s(record["profile"], record["operator"], record.get("hallway", "H1"))
    completion = record["completion_time_s"]
    return {**record, "t_ref_s": t_ref, "t_norm": completion / t_ref if completion is not None else None}


def setup() -> str:
    """This setup's name: the tag and a digest of systems/teleop_sim.yaml as resolved (comments aside)."""
    import hashlib

    from hapticop.composition.documents import dump
    from hapticop.composition.layers import resolve
    from hapticop.composition.yamlsource import read_file

    tree = resolve(read_file(ROOT / "systems" / "teleop_sim.yaml")).tree
    return f"{SETUP_TAG}:{hashlib.sha256(dump(tree).encode()).hexdigest()[:10]}"


def run_one(rtt_ms: int, loss: float, tank: bool, governor: bool, i: int, hallway: str = "H1") -> dict:
    from hapticop.composition.yamlsource import Source, read_file
    from hapticop.runtime.system import RunOptions, run_system
    from hapticop.validation import validate_source
    from hapticop.validation.patches import apply_patch

    profile, variation = operator(i)
    source = read_file(ROOT / "systems" / "teleop_sim.yaml")
    from hapticop.composition.layers import resolve

    tree = resolve(source).tree
    if not governor:  # M1 with docs/hallway-experiment.md's own parameters, not the hallway's governor tuning
        tree = apply_patch(tree, {"activities": {"haptic": {"params": {"force_model": None}}}})
        tree = apply_patch(tree, {"activities": {"haptic": {"params": {"force_model": {"kind": "braking_field"}}}}})
    tree = apply_patch(tree, cell_patch(rtt_ms, loss, tank, governor, i))
    tree = apply_patch(tree, {"activities": {
        "operator": {"params": {"variant": profile, "variation": variation, "time_limit_s": TIME_LIMIT_S}},
        "world": {"params": {"scene": hallway, "plot": False, "time_limit_s": TIME_LIMIT_S}}}})
    validated = validate_source(Source("teleop_sim.yaml", tree, source.text), state_limit=300)
    assert validated.report.ok, [d.to_text() for d in validated.report.errors]
    activities = validated.graph.loaded.activities
    tank_params = activities["tank"].params.tank if "tank" in activities else None
    with tempfile.TemporaryDirectory() as run_dir:
        started = time.perf_counter()
        run_system(validated, RunOptions(clock="virtual", seed=variation, run_dir=Path(run_dir), echo=False))
        wall = time.perf_counter() - started
        metrics = json.loads((Path(run_dir) / "metrics.json").read_text())
    t_ref = metrics["t_ref_s"]  # the world's own, by the same definition as `reference_time_s`
    completion = metrics["completion_time_s"]
    return {"rtt_ms": rtt_ms, "loss": loss, "tank": tank, "governor": governor, "operator": i, "profile": profile,
            "hallway": hallway, "wall_s": round(wall, 2), "ended_by": metrics["ended_by"], "crash": metrics["crash"],
            "collisions": metrics["n_collisions"], "e_stop_m": metrics["e_stop_m"],
            "side_clearance_min_m": metrics["side_clearance_min_m"], "completion_time_s": completion,
            "t_ref_s": t_ref, "t_norm": completion / t_ref if completion is not None else None,
            "oscillation_index_mps": metrics["oscillation_index_mps"],
            "sustained_oscillation": metrics["sustained_oscillation"], "divergence": metrics["divergence"],
            "oscillation_s": metrics.get("oscillation_s"),
            "force_peak_n": metrics["force_peak_n"], "tank_level_min_j": metrics.get("tank_level_min_j"),
            "tank_max_j": tank_params.max_j if tank_params else None,
            "tank_empty": tank_empty(metrics.get("tank_level_min_j"), tank_params),
            "round_trip_max_s": metrics.get("round_trip_max_s"), "link_loss_max": metrics.get("link_loss_max"),
            "setup": setup()}


def tank_empty(lowest_j: float | None, params) -> bool | None:
    """Whether the tank ran empty: its lowest level within EMPTY_J of its floor, where it scales the cue down
    (None without a tank)."""
    if params is None or lowest_j is None:
        return None
    return lowest_j <= params.min_j + EMPTY_J


def cells() -> list[tuple[int, float, bool, bool]]:
    """Every cell, the goal cells (5 % loss, tank and governor on) first."""
    every = [(rtt, loss, tank, gov) for gov in (True, False) for tank in (True, False) for loss in (0.05, 0.0)
             for rtt in ROUND_TRIPS_MS]
    return sorted(every, key=lambda c: not is_goal(c))


def is_goal(cell: tuple[int, float, bool, bool]) -> bool:
    rtt, loss, tank, governor = cell
    return loss == 0.05 and tank and governor


def jobs(operators: int, others: int, others_per_round: int) -> list[tuple[int, float, bool, bool, int]]:
    """Round i: every goal cell with operator i, then the next `others_per_round` of the other cells' runs
    (each other cell with operators 0 .. others − 1), so a sweep cut short has spread its time over all."""
    pending = [(*cell, i) for i in range(others) for cell in cells() if not is_goal(cell)]
    out = []
    for i in range(operators):
        out += [(*cell, i) for cell in cells() if is_goal(cell)]
        out += pending[i * others_per_round:(i + 1) * others_per_round]
    return out + pending[operators * others_per_round:]


def focused(jobs: list[tuple[int, float, bool, bool, int]]) -> list[tuple[int, float, bool, bool, int]]:
    """The same jobs, those that tell most for their cost first: the goal cells with an aggressive operator
    (a shorter run than a cautious one's), longest round trips first; the governor, the tank and the loss
    each taken away at 1000 ms; the goal cells with a nominal operator; the same three at 400 ms; then the
    rest in order."""
    ablations = ((0.05, True, False), (0.05, False, True), (0.0, True, True))
    first = [(rtt, 0.05, True, True, 2) for rtt in sorted(ROUND_TRIPS_MS, reverse=True)]
    first += [(1000, loss, tank, governor, 2) for loss, tank, governor in ablations]
    first += [(rtt, 0.05, True, True, 1) for rtt in sorted(ROUND_TRIPS_MS, reverse=True)]
    first += [(400, loss, tank, governor, 2) for loss, tank, governor in ablations]
    wanted = set(jobs)
    first = [job for job in first if job in wanted]  # only reordered: nothing is run that was not asked for
    return first + [job for job in jobs if job not in set(first)]


def records(path: Path, of_setup: str) -> list[dict]:
    """The runs `path` holds that were made with this setup."""
    if not path.exists():
        return []
    return [judged(r) for r in map(json.loads, filter(str.strip, path.read_text().splitlines()))
            if r.get("setup") == of_setup]


def summarise(path: Path, goal_only: bool = False) -> str:
    """A row per cell; `goal_only`: the goal cells alone (governor and tank on, 5 % loss), the README's table."""
    runs = [r for r in records(path, setup())
            if not goal_only or is_goal((r["rtt_ms"], r["loss"], r["tank"], r["governor"]))]
    groups: dict[tuple, list[dict]] = defaultdict(list)
    for run in runs:
        groups[(not run["governor"], not run["tank"], -run["loss"], run["rtt_ms"])].append(run)
    lines = ["| governor | tank | loss | RTT (ms) | operators | runs with collisions | crashes | "
             "stop error within -5/+10 cm | stop error min / median / max (cm) | T/T_ref median / max | "
             "sustained oscillation | oscillation index median / max (cm/s) | tank's lowest level (J) | "
             "tank empty | measured round trip max (ms) |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for key in sorted(groups):
        group = groups[key]
        first = group[0]
        stops = [r["e_stop_m"] for r in group if r["e_stop_m"] is not None and not math.isnan(r["e_stop_m"])]
        spread = f"{100 * min(stops):.1f} / {_median(stops, 100)} / {100 * max(stops):.1f}" if stops else "-"
        norms = [r["t_norm"] for r in group if r["t_norm"] is not None and not math.isnan(r["t_norm"])]
        t_norm = f"{_median(norms, digits=2)} / {max(norms):.2f}" if norms else "-"
        osc = [r["oscillation_index_mps"] for r in group]
        tanks = [r["tank_level_min_j"] for r in group if r["tank_level_min_j"] is not None]
        empty = [r["tank_empty"] for r in group if r["tank_empty"] is not None]
        trips = [r["round_trip_max_s"] for r in group if r["round_trip_max_s"] is not None]
        lines.append(
            f"| {'on' if first['governor'] else 'off'} | {'on' if first['tank'] else 'off'} | "
            f"{100 * first['loss']:.0f} % | {first['rtt_ms']} | {len(group)} | "
            f"{sum(1 for r in group if r['collisions'])} | {sum(r['crash'] for r in group)} | "
            f"{sum(1 for s in stops if -0.05 <= s <= 0.10)} of {len(group)} | {spread} | {t_norm} | "
            f"{sum(1 for r in group if r['sustained_oscillation'])} | "
            f"{_median(osc, 100)} / {100 * max(osc):.1f} | {f'{min(tanks):.3f}' if tanks else '-'} | "
            f"{f'{sum(empty)} of {len(empty)}' if empty else '-'} | {f'{1000 * max(trips):.0f}' if trips else '-'} |")
    return "\n".join(lines) + "\n"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--operators", type=int, default=200, help="operators per goal cell")
    parser.add_argument("--others", type=int, default=3, help="operators per other cell")
    parser.add_argument("--others-per-round", type=int, default=2, help="other cells' runs after each goal round")
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--out", type=Path, default=RESULTS)
    parser.add_argument("--summary", action="store_true", help="only summarise what --out holds")
    parser.add_argument("--readme", action="store_true", help="with --summary: the goal cells only")
    parser.add_argument("--limit", type=int, default=None, help="run at most this many of the pending runs")
    args = parser.parse_args()
    if not args.summary:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        done = {(r["rtt_ms"], r["loss"], r["tank"], r["governor"], r["operator"]) for r in records(args.out, setup())}
        todo = [job for job in focused(jobs(args.operators, args.others, args.others_per_round)) if job not in done]
        print(f"{len(done)} runs of this setup already in {args.out}, {len(todo)} to go", flush=True)
        with ProcessPoolExecutor(args.workers) as pool, args.out.open("a") as out:
            pending = {pool.submit(run_one, *job): job for job in todo[:args.limit]}
            for future in as_completed(pending):  # written as each ends: a sweep cut short keeps every finished run
                try:
                    record = future.result()
                except Exception as error:  # noqa: BLE001 - one run's failure is reported, the sweep goes on
                    print("failed:", pending[future], repr(error), flush=True)
                    continue
                out.write(json.dumps(record) + "\n")
                out.flush()
                print(record["rtt_ms"], record["loss"], record["tank"], record["governor"], record["operator"],
                      record["ended_by"], record["collisions"], record["e_stop_m"], record["wall_s"], flush=True)
    print(summarise(args.out, goal_only=args.readme))


if __name__ == "__main__":
    main()
