"""Benchmark: the framework's own cost per cycle of each 1 kHz loop, without the machine's noise.

    python bench/cycle_overhead.py systems/hallway.yaml --cycles 5000

What is measured and how: hapticop/benchmark/overhead.py (`hapticop bench` runs the same).
"""

from __future__ import annotations

import argparse
import platform
from pathlib import Path

from hapticop.benchmark.overhead import measure, publish_us


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("file", type=Path, nargs="?", default=Path("systems/hallway.yaml"))
    parser.add_argument("--cycles", type=int, default=5_000)
    args = parser.parse_args()
    print(f"Python {platform.python_version()}, {args.file}, {args.cycles} cycles")
    print("| loop | activities | cycle p50 us | cycle p99 | framework p50 us | framework p99 |")
    print("|---|---|---|---|---|---|")
    for name, f in measure(args.file, args.cycles).items():
        print(f"| {name} | {f['activities']} | {f['cycle_p50']:.1f} | {f['cycle_p99']:.1f} | "
              f"{f['framework_p50']:.1f} | {f['framework_p99']:.1f} |")
    print(f"one publish (3 floats, one latest slot): {publish_us():.2f} us")


if __name__ == "__main__":
    main()
