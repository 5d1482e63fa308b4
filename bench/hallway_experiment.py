"""The hallway experiment: force models against operator profiles, under the virtual clock.

Each run is systems/hallway.yaml with a merge patch choosing the force model (``MODEL+governor``
adds the robot-side speed governor S1), the operator
profile and a seeded operator variation (whose hand the simulated Falcon's handle carries); it runs
to its end in simulated time and the world activity's metrics are collected. Results are appended as JSON lines, so an
interrupted sweep keeps what it measured; `--summary` turns them into the table of docs/hallway-experiment.md.

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
from concurrent.futures import ProcessPoolExecutor, as_completed
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
    limit = 90.0 if hallway == "H6" else TIME_LIMIT_S  # H6 is twice as long
    patch = {"activities": {"haptic": {"params": haptic},
                            "operator": {"params": {"variant": profile, "variation": variation,
                                                    "time_limit_s": limit}},
                            "world": {"params": {"scene": hallway, "plot": False, "time_limit_s": limit}}}}
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


MODEL_NAMES = {"braking_field+governor": "operator alone", "braking_field+governor+shared": "shared control"}


def _runs(path: Path) -> list[dict]:
    return [r for r in map(json.loads, path.read_text().splitlines()) if r and "metrics" in r]


def summarise_sweep(path: Path) -> str:
    """One table per hallway, a row per operator profile and model: how many runs met each target and the
    spread of the metrics the targets judge (every metric of every run is in the records)."""
    runs = _runs(path)
    out = []
    for hallway in sorted({r["hallway"] for r in runs}):
        out += [f"### {hallway}", "",
                "| operator | control | runs | all targets met | runs with collisions | stop error in target | "
                "stop error min / median / max (cm) | least side clearance min / median (m) | "
                "T/T_ref median / max | oscillation index max (m/s) | longest above 2 cm/s, max (s) | "
                "sustained oscillation (runs) | drift while stopped, max (cm/s) | force rate rms, max (N/s) | "
                "command changed > 10 %, median share | targets missed (runs) |",
                "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
        here = [r for r in runs if r["hallway"] == hallway]
        for profile in PROFILES:
            for model in MODEL_NAMES:
                group = [r for r in here if r["profile"] == profile and r["model"] == model]
                if group:
                    out.append(_row(profile, MODEL_NAMES[model], group))
        out.append("")
    return "\n".join(out)


def summarise_for_readme(path: Path) -> str:
    """The README's table: a row per hallway and control, every operator together, and which operators
    missed which target (docs/hallway-experiment.md §12 has the table per operator)."""
    runs = _runs(path)
    out = ["| hallway | control | runs | collisions | stops within -5/+10 cm | least side clearance (m) | "
           "T/T_ref, max | sustained oscillations | force rate rms, max (N/s) | every target met | "
           "targets missed: operator runs |",
           "|---|---|---|---|---|---|---|---|---|---|---|"]
    for hallway in sorted({r["hallway"] for r in runs}):
        for model, control in MODEL_NAMES.items():
            group = [r for r in runs if r["hallway"] == hallway and r["model"] == model]
            if not group:
                continue
            ms = [r["metrics"] for r in group]
            stops = sum(1 for m in ms if m["e_stop_m"] is not None and -0.05 <= m["e_stop_m"] <= 0.10)
            sides = [m["side_clearance_min_m"] for m in ms if m["side_clearance_min_m"] is not None]
            t_norm = [m["t_norm"] for m in ms if m.get("t_norm") is not None]
            rates = [m["force_rate_rms_nps"] for m in ms if m.get("force_rate_rms_nps") is not None]
            missed: dict[str, dict[str, int]] = defaultdict(lambda: defaultdict(int))
            for r in group:
                for name in r["missed"]:
                    missed[name.split(" (")[0]][r["profile"]] += 1
            cells = [hallway, control, len(group), sum(1 for m in ms if m["n_collisions"]), stops,
                     f"{min(sides):.2f}" if sides else "-", f"{max(t_norm):.2f}" if t_norm else "-",
                     sum(1 for m in ms if m["sustained_oscillation"]), f"{max(rates):.1f}" if rates else "-",
                     sum(1 for r in group if not r["missed"]),
                     "; ".join(f"{target}: " + ", ".join(f"{p} {n}" for p, n in sorted(who.items()))
                               for target, who in sorted(missed.items())) or "none"]
            out.append("| " + " | ".join(str(c) for c in cells) + " |")
    return "\n".join(out) + "\n"


def _row(profile: str, control: str, group: list[dict]) -> str:
    ms = [r["metrics"] for r in group]

    def values(key: str) -> list[float]:
        return [m[key] for m in ms if m.get(key) is not None]

    def spread(key: str, scale: float = 1.0, digits: int = 1, maximum: bool = True) -> str:
        v = values(key)
        if not v:
            return "-"
        return (f"{scale * min(v):.{digits}f} / {_median(v, scale, digits)}"
                + (f" / {scale * max(v):.{digits}f}" if maximum else ""))

    def largest(key: str, scale: float = 1.0, digits: int = 2) -> str:
        v = values(key)
        return f"{scale * max(v):.{digits}f}" if v else "-"

    missed: dict[str, int] = defaultdict(int)
    for r in group:
        for name in r["missed"]:
            missed[name.split(" (")[0]] += 1
    stop_ok = sum(1 for r in group if r["e_stop_m"] is not None and not any("stop error" in m for m in r["missed"]))
    t_norm = values("t_norm")
    modified = values("frac_modified")
    cells = [profile, control, len(group), sum(1 for r in group if not r["missed"]),
             sum(1 for m in ms if m["n_collisions"]), stop_ok, spread("e_stop_m", 100),
             spread("side_clearance_min_m", digits=2, maximum=False),
             f"{_median(t_norm, digits=2)} / {max(t_norm):.2f}" if t_norm else "-",
             largest("oscillation_index_mps", digits=3), largest("oscillation_s"),
             sum(1 for m in ms if m["sustained_oscillation"]), largest("hold_speed_mps", 100),
             largest("force_rate_rms_nps", digits=1), _median(modified, digits=3) if modified else "-",
             ", ".join(f"{k} ({v})" for k, v in sorted(missed.items())) or "none"]
    return "| " + " | ".join(str(c) for c in cells) + " |"


PROFILES = ("cautious", "nominal", "aggressive", "tremor", "hands_off")
FIGURE_METRICS = (  # (key, label, scale, target band or line)
    ("e_stop_m", "stop error (cm, + early)", 100.0, (-5.0, 10.0)),
    ("side_clearance_min_m", "least side clearance (m)", 1.0, (None, None)),  # the target: per hallway
    ("oscillation_s", "oscillation above 2 cm/s (1 s rms), longest (s)", 1.0, (None, 2.0)),
    ("t_norm", "completion time / T_ref", 1.0, (None, 1.2)),
)


def plot_sweep(path: Path, folder: Path) -> list[Path]:
    """A picture per hallway: each judged metric per run, by operator profile, the operator alone beside shared
    control, with the target drawn."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from hapticop.sim.hallway import HallwayGeometry

    runs = _runs(path)
    folder.mkdir(parents=True, exist_ok=True)
    written = []
    for hallway in sorted({r["hallway"] for r in runs}):
        here = [r for r in runs if r["hallway"] == hallway]
        fig, axes = plt.subplots(1, len(FIGURE_METRICS), figsize=(4.2 * len(FIGURE_METRICS), 3.6))
        for ax, (key, label, scale, (low, high)) in zip(axes, FIGURE_METRICS):
            for offset, (model, name), colour in zip((-0.15, 0.15), MODEL_NAMES.items(), ("tab:blue", "tab:orange")):
                xs, ys = [], []
                for i, profile in enumerate(PROFILES):
                    for r in here:
                        value = r["metrics"].get(key)
                        if r["profile"] == profile and r["model"] == model and value is not None:
                            xs.append(i + offset)
                            ys.append(scale * value)
                ax.scatter(xs, ys, s=14, alpha=0.7, color=colour, label=name)
            if key == "side_clearance_min_m":  # dist1 - 10 cm of this hallway
                low = HallwayGeometry.named(hallway).dist1_m - 0.10
            for bound in (low, high):
                if bound is not None:
                    ax.axhline(bound, color="tab:red", linewidth=0.8, linestyle="--")
            ax.set_xticks(range(len(PROFILES)), PROFILES, rotation=30, fontsize=8)
            ax.set_title(label, fontsize=9)
            ax.grid(alpha=0.3)
        axes[0].legend(fontsize=8)
        fig.suptitle(f"hallway {hallway}: every run (dashed: the target)", fontsize=10)
        fig.tight_layout()
        target = folder / f"hallway-sweep-{hallway}.png"
        fig.savefig(target, dpi=90)
        plt.close(fig)
        written.append(target)
    return written


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
    parser.add_argument("--figures", type=Path, help="with --sweep: draw a picture per hallway into this folder")
    parser.add_argument("--readme", action="store_true", help="with --sweep --summary: the README's short table")
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
        # Seed by seed, each model over every cell before the next: stopped early, the sweep has as many
        # seeds as fitted, uniformly over the cells, the first model's first.
        jobs = [(m, p, v, h) for v in range(args.variations) for m in args.models for h in hallways
                for p in args.profiles if (m, p, v, h) not in done]
        with ProcessPoolExecutor(args.workers) as pool, args.out.open("a") as out:
            # Written as each run ends, not in order: an interrupted sweep keeps every run it finished.
            for future in as_completed([pool.submit(run_one, *job) for job in jobs]):
                record = future.result()
                out.write(json.dumps(record) + "\n")
                out.flush()
                print(record["hallway"], record["model"], record["profile"], record["variation"], record["ended_by"],
                      record["e_stop_m"], record["wall_s"], record["missed"], flush=True)
    if args.sweep and args.readme:
        print(summarise_for_readme(args.out))
        return
    print(summarise_sweep(args.out) if args.sweep else summarise(args.out))
    if args.sweep and args.figures:
        for picture in plot_sweep(args.out, args.figures):
            print(f"picture: {picture}")


if __name__ == "__main__":
    main()
