"""The hallway experiment: force models against operator profiles, under the virtual clock.

Each run is systems/hallway.yaml with a merge patch choosing the force model (``MODEL+governor``
adds the robot-side speed governor S1), the operator
profile and a seeded operator variation (whose hand the simulated Falcon's handle carries); it runs
to its end in simulated time and the world activity's metrics are collected. Results are appended as JSON lines, so an
interrupted sweep keeps what it measured; `--summary` turns them into the README table.

    python bench/hallway_experiment.py --variations 50 --workers 2
    python bench/hallway_experiment.py --summary

The sweep over every hallway and operator profile (docs/hallway-experiment.md §4) keeps every metric of
every run (its ``metrics`` and the targets it ``missed``) and summarises each hallway on its own:

    python bench/hallway_experiment.py --sweep --hallways H1 H2 H3 H4 H5 H6 --variations 50 \
        --out bench/results/hallway-sweep.jsonl
    python bench/hallway_experiment.py --sweep --summary --out bench/results/hallway-sweep.jsonl
"""

from __future__ import annotations

import argparse
import json
import tempfile
import time
from collections import defaultdict
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
RESULTS = ROOT / "bench" / "results" / "hallway-experiment.jsonl"
TIME_LIMIT_S = 50.0
"""Every operator reaches the end wall well before this (the slowest cautious run so far stopped
at 36 s); an operator who never lets go of the handle would otherwise hold the run to 90 s."""


def run_one(model: str, profile: str, variation: int, hallway: str, braking_field: dict | None = None) -> dict:
    """One seeded run. ``braking_field+governor`` is the hallway's own tuning; ``braking_field`` alone
    drops that tuning (a precursor for the governor) and runs M1 with docs/hallway-experiment.md's parameters."""
    from hapticop.composition.layers import resolve
    from hapticop.composition.yamlsource import Source, read_file
    from hapticop.runtime.system import RunOptions, run_system
    from hapticop.sim.operator import BlindOperator
    from hapticop.validation import validate_source
    from hapticop.validation.patches import apply_patch

    force_model, _, robot_side = model.partition("+")
    robot_side, _, shared = robot_side.partition("+")  # "+shared": the robot's safety filter on top (S2)
    source = resolve(read_file(ROOT / "systems" / ("hallway_shared.yaml" if shared == "shared" else "hallway.yaml")))
    governor = robot_side == "governor"
    tuned = force_model == "braking_field" and (governor or braking_field is not None)
    tree = source.tree
    if not tuned:  # the model's own defaults, not the hallway's tuning of M1
        tree = apply_patch(tree, {"activities": {"haptic": {"params": {"force_model": None}}}})
    haptic = {"force_model": {"kind": force_model, **(braking_field or {})}, "governor": {} if governor else None}
    hand_kg = BlindOperator.variant(profile, seed=variation).profile.m_h_kg  # moves with the simulated handle
    limit = 90.0 if hallway == "H6" else TIME_LIMIT_S  # H6 is twice as long
    patch = {"activities": {"haptic": {"params": haptic},
                            "operator": {"params": {"variant": profile, "variation": variation,
                                                    "time_limit_s": limit}},
                            "falcon_sim": {"params": {"hand_mass_kg": hand_kg}},
                            "world": {"params": {"hallway": hallway, "plot": False, "time_limit_s": limit}}}}
    tree = apply_patch(tree, patch)
    validated = validate_source(Source("hallway.yaml", tree, source.text), state_limit=300)
    assert validated.report.ok, [d.to_text() for d in validated.report.errors]
    with tempfile.TemporaryDirectory() as run_dir:
        started = time.perf_counter()
        result = run_system(validated, RunOptions(clock="virtual", seed=variation, run_dir=Path(run_dir), echo=False))
        wall = time.perf_counter() - started
        metrics = json.loads((Path(run_dir) / "metrics.json").read_text())
        results = json.loads((Path(run_dir) / "results.json").read_text())
    ok = {row["metric"].split(" (")[0]: row["ok"] for row in results["rows"]}
    missed = [row["metric"] for row in results["rows"] if row["ok"] is False]
    activities = result.timing["activities"]
    return {"model": model, "profile": profile, "variation": variation, "hallway": hallway, "wall_s": round(wall, 2),
            "ended_by": metrics["ended_by"], "crash": metrics["crash"], "collisions": metrics["n_collisions"],
            "e_stop_m": metrics["e_stop_m"], "side_clearance_min_m": metrics["side_clearance_min_m"],
            "completion_time_s": metrics["completion_time_s"], "force_peak_n": metrics["force_peak_n"],
            "force_rms_n": metrics["force_rms_n"], "force_rate_rms_nps": metrics["force_rate_rms_nps"],
            "stop_ok": ok.get("stop error against dist2 = 0.5 m"),
            "haptic_compute_us": activities["haptic"]["compute_us"],
            "ropod_compute_us": activities["ropod"]["compute_us"], "metrics": metrics, "missed": missed}


def _median(values: list, scale: float = 1.0, digits: int = 1) -> str:
    import statistics

    values = [v for v in values if v is not None]
    return f"{scale * statistics.median(values):.{digits}f}" if values else "-"


def summarise(path: Path) -> str:
    runs = [json.loads(line) for line in path.read_text().splitlines() if line.strip()]
    groups: dict[tuple[str, str], list[dict]] = defaultdict(list)
    for run in runs:
        groups[(run["model"], run["profile"])].append(run)
    lines = ["| force model | operator | runs | crashes | runs with collisions | stop error within -5/+10 cm | "
             "stop error min / median / max (cm) | least side clearance, min / median (m) | median time (s) | "
             "median peak force (N) |",
             "|---|---|---|---|---|---|---|---|---|---|"]
    for (model, profile), group in sorted(groups.items()):
        stops = [r["e_stop_m"] for r in group if r["e_stop_m"] is not None]
        spread = (f"{100 * min(stops):.1f} / {_median(stops, 100)} / {100 * max(stops):.1f}" if stops else "-")
        sides = [r["side_clearance_min_m"] for r in group if r["side_clearance_min_m"] is not None]
        side = f"{min(sides):.2f} / {_median(sides, digits=2)}" if sides else "-"
        lines.append(
            f"| {model} | {profile} | {len(group)} | {sum(r['crash'] for r in group)} | "
            f"{sum(1 for r in group if r['collisions'])} | {sum(1 for s in stops if -0.05 <= s <= 0.10)} | "
            f"{spread} | {side} | {_median([r['completion_time_s'] for r in group])} | "
            f"{_median([r['force_peak_n'] for r in group], digits=2)} |")
    lines += ["", "1 kHz step compute time (median over runs of each run's median, virtual clock, one process):"]
    for model in sorted({r["model"] for r in runs}):
        mine = [r for r in runs if r["model"] == model]
        lines.append(f"- {model}: haptic controller "
                     f"{_median([r['haptic_compute_us']['p50'] for r in mine], digits=0)} us, "
                     f"ropod controller {_median([r['ropod_compute_us']['p50'] for r in mine], digits=0)} us")
    return "\n".join(lines) + "\n"


def summarise_sweep(path: Path) -> str:
    """One table per hallway, a row per operator profile: how many runs met each target (every metric is in
    the records; this is the part the README shows)."""
    runs = [json.loads(line) for line in path.read_text().splitlines() if line.strip()]
    runs = [r for r in runs if "metrics" in r]
    out = []
    for hallway in sorted({r["hallway"] for r in runs}):
        out += [f"### {hallway}", "",
                "| operator | runs | all targets met | crashes | runs with collisions | stop error in target | "
                "stop error min / median / max (cm) | least side clearance (m) | T/T_ref median / max | "
                "sustained oscillation | longest oscillation (s) | drift while stopped, max (cm/s) | "
                "force rate rms, max (N/s) | targets missed (runs) |",
                "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
        for profile in sorted({r["profile"] for r in runs if r["hallway"] == hallway}):
            group = [r for r in runs if r["hallway"] == hallway and r["profile"] == profile]
            ms = [r["metrics"] for r in group]

            def values(key, ms=ms):
                return [m[key] for m in ms if m.get(key) is not None]

            stops = values("e_stop_m")
            stop_ok = sum(1 for r in group if "stop error" not in " ".join(r["missed"]) and r["e_stop_m"] is not None)
            missed = defaultdict(int)
            for r in group:
                for name in r["missed"]:
                    missed[name.split(" (")[0]] += 1
            t_norm, osc_s, hold, rate = values("t_norm"), values("oscillation_s"), values("hold_speed_mps"), \
                values("force_rate_rms_nps")
            side = values("side_clearance_min_m")
            out.append(
                f"| {profile} | {len(group)} | {sum(1 for r in group if not r['missed'])} | "
                f"{sum(m['crash'] for m in ms)} | {sum(1 for m in ms if m['n_collisions'])} | {stop_ok} | "
                + (f"{100 * min(stops):.1f} / {_median(stops, 100)} / {100 * max(stops):.1f}" if stops else "-")
                + f" | {min(side):.2f} | " if side else " | - | ")
            out[-1] += (f"{_median(t_norm, digits=2)} / {max(t_norm):.2f}" if t_norm else "-") + \
                f" | {sum(1 for m in ms if m['sustained_oscillation'])} | " + \
                (f"{max(osc_s):.2f}" if osc_s else "-") + " | " + (f"{100 * max(hold):.2f}" if hold else "-") + \
                " | " + (f"{max(rate):.1f}" if rate else "-") + " | " + \
                (", ".join(f"{k} ({v})" for k, v in sorted(missed.items())) or "none") + " |"
        out.append("")
    return "\n".join(out)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--models", nargs="+", default=["none", "thesis", "braking_field+governor"])
    parser.add_argument("--profiles", nargs="+", default=["cautious", "nominal", "aggressive"])
    parser.add_argument("--variations", type=int, default=50)
    parser.add_argument("--hallway", default="H1")
    parser.add_argument("--hallways", nargs="+", help="several hallways (H1-H6); overrides --hallway")
    parser.add_argument("--sweep", action="store_true",
                        help="the full experiment: M1 + S1 over --hallways x --profiles (default: all five "
                        "variants, each seed a varied operator), every metric per run, a table per hallway")
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--out", type=Path, default=RESULTS)
    parser.add_argument("--summary", action="store_true", help="only summarise what --out holds")
    args = parser.parse_args()
    hallways = args.hallways or [args.hallway]
    if args.sweep:
        if args.models == parser.get_default("models"):
            args.models = ["braking_field+governor"]
        if args.profiles == parser.get_default("profiles"):
            args.profiles = ["cautious", "nominal", "aggressive", "tremor", "hands_off"]
    if not args.summary:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        done = set()
        if args.out.exists():
            done = {(r["model"], r["profile"], r["variation"], r["hallway"])
                    for r in map(json.loads, args.out.read_text().splitlines()) if r}
        jobs = [(m, p, v, h) for v in range(args.variations) for h in hallways for m in args.models
                for p in args.profiles if (m, p, v, h) not in done]
        with ProcessPoolExecutor(args.workers) as pool, args.out.open("a") as out:
            for record in pool.map(run_one, *zip(*jobs)) if jobs else []:
                out.write(json.dumps(record) + "\n")
                out.flush()
                print(record["hallway"], record["model"], record["profile"], record["variation"], record["ended_by"],
                      record["e_stop_m"], record["wall_s"], record["missed"], flush=True)
    print(summarise_sweep(args.out) if args.sweep else summarise(args.out))


if __name__ == "__main__":
    main()
