"""Benchmark: time from each scripted device fault to a zero velocity setpoint, and back.

Runs systems/faults.yaml (the hallway with the simulated Falcon and LIDAR failing on cue)
and reads the world's 1 kHz recording. Under the virtual clock the figures are the logic's
own reaction times; on the wall clock they include scheduling.

    python bench/fault_reaction.py --clock virtual --clock realtime --out bench/results/fault-reaction.md
"""

from __future__ import annotations

import argparse
import json
import math
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent


def run(clock: str) -> list:
    from hapticop.runtime.system import RunOptions, run_system
    from hapticop.sim.faults import fault_windows, reactions
    from hapticop.validation import validate_path

    validated = validate_path(ROOT / "systems" / "faults.yaml")
    assert validated.report.ok
    with tempfile.TemporaryDirectory() as tmp:
        result = run_system(validated, RunOptions(clock=clock, run_dir=Path(tmp), echo=False))
        recording = np.load(Path(tmp) / "trajectory.npz")
        meta = json.loads(str(recording["__meta__"]))
        return reactions(recording["t"], recording["cmd"], recording["robot_velocity"], meta["operator_start_ns"],
                         result.timing["started_ns"], fault_windows(validated.composition))


def ms(value: float) -> str:
    return "-" if math.isnan(value) else f"{1000 * value:.0f}"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--clock", action="append", choices=["virtual", "realtime"])
    parser.add_argument("--out", type=Path)
    args = parser.parse_args()
    lines = ["| clock | device | fault | to zero setpoint (ms) | to robot at rest (ms) | driving again after the "
             "fault cleared (ms) |", "|---|---|---|---|---|---|"]
    for clock in args.clock or ["virtual"]:
        for r in run(clock):
            lines.append(f"| {clock} | {r.window.activity} | {r.window.fault} | {ms(r.to_zero_setpoint_s)} | "
                         f"{ms(r.to_rest_s)} | {ms(r.resumed_after_s)} |")
        print("\n".join(lines), flush=True)
    if args.out:
        args.out.write_text("\n".join(lines) + "\n")


if __name__ == "__main__":
    main()
