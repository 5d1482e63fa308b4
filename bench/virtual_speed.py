"""Benchmark: how much simulated time the virtual clock gets through per wall second, and per
second of this process's CPU time (which other work on a busy machine stretches less).

    python bench/virtual_speed.py systems/hallway.yaml bench/virtual_bench.yaml --duration 30s
    python bench/virtual_speed.py systems/hallway.yaml systems/teleop_sim.yaml --duration end --repeat 3

`--duration end` runs each composition to its own end (a hallway run: until the world judges it).
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

from hapticop.composition.units import parse_duration_ns
from hapticop.runtime.system import RunOptions, run_system
from hapticop.validation import validate_path


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("files", nargs="+", type=Path)
    parser.add_argument("--duration", default="30s", help="simulated time per run, or 'end'")
    parser.add_argument("--repeat", type=int, default=1, help="runs of each composition, one row each")
    args = parser.parse_args()
    duration = None if args.duration == "end" else parse_duration_ns(args.duration)
    print("| composition | simulated s | wall s | CPU s | simulated s per wall s | per CPU s | cycles |")
    print("|---|---|---|---|---|---|---|")
    for path in args.files:
        validated = validate_path(path)
        for _ in range(args.repeat):
            with tempfile.TemporaryDirectory() as run_dir:
                options = RunOptions(clock="virtual", duration_ns=duration, run_dir=Path(run_dir), echo=False)
                started, cpu = time.perf_counter(), time.process_time()
                ran = []
                result = run_system(validated, options, on_start=ran.append)
                wall, cpu = time.perf_counter() - started, time.process_time() - cpu
            simulated = ran[0].clock.now_ns() / 1e9  # where the virtual clock stopped
            cycles = sum(t["cycles"] for t in result.timing["threads"].values())
            print(f"| {path} | {simulated:g} | {wall:.2f} | {cpu:.2f} | {simulated / wall:.2f} | {simulated / cpu:.2f} "
                  f"| {cycles} |")


if __name__ == "__main__":
    main()
