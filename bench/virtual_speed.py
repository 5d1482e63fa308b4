"""Benchmark: how much simulated time the virtual clock gets through per wall second.

    python bench/virtual_speed.py systems/hallway.yaml bench/virtual_bench.yaml --duration 30s
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
    parser.add_argument("--duration", default="30s")
    args = parser.parse_args()
    duration = parse_duration_ns(args.duration)
    print("| composition | simulated s | wall s | simulated s per wall s | cycles |")
    print("|---|---|---|---|---|")
    for path in args.files:
        validated = validate_path(path)
        with tempfile.TemporaryDirectory() as run_dir:
            options = RunOptions(clock="virtual", duration_ns=duration, run_dir=Path(run_dir), echo=False)
            started = time.perf_counter()
            result = run_system(validated, options)
            wall = time.perf_counter() - started
        cycles = sum(t["cycles"] for t in result.timing["threads"].values())
        print(f"| {path} | {duration / 1e9:g} | {wall:.2f} | {duration / 1e9 / wall:.1f} | {cycles} |")


if __name__ == "__main__":
    main()
