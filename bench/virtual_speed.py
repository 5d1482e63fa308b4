"""Benchmark: how much simulated time the virtual clock gets through per wall second, and per
second of this process's CPU time (which other work on a busy machine stretches less).

    python bench/virtual_speed.py systems/hallway.yaml systems/wall.yaml systems/teleop_sim.yaml \\
        --duration end --repeat 3
    python bench/virtual_speed.py systems/hallway.yaml --duration 10s --repeat 3 --activities 3

`--duration end` runs each composition to its own end (a hallway run: until the world judges it).
Each run is a row; with `--repeat` above 1 a summary per composition follows: min, median and max of
simulated seconds per CPU second and per wall second.

`--activities K` runs the composition with K times its application's own activities (for growth
figures only, never a shipped file): every activity that is neither the mediator, nor a device
block (one with a `driver`), nor a simulation block (`simulator = True`: worlds, operators, simulated devices)
gets K-1 copies on its schedules, each reading the streams the original reads and writing none,
and told the flags the standard coordination's sinks tell the original.
"""

from __future__ import annotations

import argparse
import copy
import os
import statistics
import tempfile
import time
from pathlib import Path

from hapticop.blocks.registry import resolve as resolve_block
from hapticop.composition.documents import dump
from hapticop.composition.layers import resolve
from hapticop.composition.units import parse_duration_ns
from hapticop.composition.yamlsource import read_file
from hapticop.runtime.system import RunOptions, run_system
from hapticop.validation import validate_path


def _copied(path: Path, times: int, into: Path) -> Path:
    """`path` with `times` times its application's activities, written under `into`."""
    tree = copy.deepcopy(resolve(read_file(path)).tree)
    tree.pop("extends", None)
    threads, activities, streams = tree["threads"], tree["activities"], tree.get("streams", {})
    copied = [name for name, spec in activities.items()
              if spec.get("block") != "mediator" and "driver" not in (spec.get("params") or {})
              and not getattr(resolve_block(spec["block"]), "simulator", False)]
    for name in copied:
        for k in range(2, times + 1):
            twin = f"{name}_{k}"
            activities[twin] = copy.deepcopy(activities[name])
            for spec in threads.values():
                for members in spec.get("schedules", {}).values():
                    if name in members:
                        members.append(twin)
            for stream in streams.values():
                readers = stream.get("to") or []
                for reader in list(readers):
                    if reader.split(".")[0] == name:
                        readers.append(f"{twin}.{reader.split('.', 1)[1]}")
    sinks = (tree.get("coordination") or {}).get("standard", {}).get("sinks") or {}
    for flag, place in list(sinks.items()):  # a copy is told what its original is told
        activity, rest = flag.split(".", 1)
        if activity in copied:
            for k in range(2, times + 1):
                sinks[f"{activity}_{k}.{rest}"] = place
    out = into / f"{path.stem}-x{times}.yaml"
    out.write_text(dump(tree))
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("files", nargs="+", type=Path)
    parser.add_argument("--duration", default="30s", help="simulated time per run, or 'end'")
    parser.add_argument("--repeat", type=int, default=1, help="runs of each composition, one row each")
    parser.add_argument("--activities", type=int, default=1, metavar="K",
                        help="K times the application's own activities (see above)")
    args = parser.parse_args()
    duration = None if args.duration == "end" else parse_duration_ns(args.duration)
    print(f"load average before: {os.getloadavg()[0]:.2f}")
    print("| composition | simulated s | wall s | CPU s | simulated s per wall s | per CPU s | cycles | load |")
    print("|---|---|---|---|---|---|---|---|")
    summaries = []
    with tempfile.TemporaryDirectory() as scaled:
        for path in args.files:
            if args.activities > 1:
                path = _copied(path, args.activities, Path(scaled))
            validated = validate_path(path)
            if not validated.report.ok:
                raise SystemExit(f"{path} is not valid:\n{validated.report}")
            per_cpu, per_wall = [], []
            for _ in range(args.repeat):
                with tempfile.TemporaryDirectory() as run_dir:
                    options = RunOptions(clock="virtual", duration_ns=duration, run_dir=Path(run_dir), echo=False)
                    started, cpu = time.perf_counter(), time.process_time()
                    ran = []
                    result = run_system(validated, options, on_start=ran.append)
                    wall, cpu = time.perf_counter() - started, time.process_time() - cpu
                simulated = ran[0].clock.now_ns() / 1e9  # where the virtual clock stopped
                cycles = sum(t["cycles"] for t in result.timing["threads"].values())
                per_cpu.append(simulated / cpu)
                per_wall.append(simulated / wall)
                print(f"| {path.name} | {simulated:g} | {wall:.2f} | {cpu:.2f} | {simulated / wall:.2f} | "
                      f"{simulated / cpu:.2f} | {cycles} | {os.getloadavg()[0]:.1f} |", flush=True)
            summaries.append((path.name, per_cpu, per_wall))
    if args.repeat > 1:
        print("\n| composition | per CPU s min / median / max | per wall s min / median / max |")
        print("|---|---|---|")
        for name, per_cpu, per_wall in summaries:
            print(f"| {name} | {min(per_cpu):.2f} / {statistics.median(per_cpu):.2f} / {max(per_cpu):.2f} | "
                  f"{min(per_wall):.2f} / {statistics.median(per_wall):.2f} / {max(per_wall):.2f} |")


if __name__ == "__main__":
    main()
