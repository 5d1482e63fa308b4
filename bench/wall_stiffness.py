"""The virtual wall's rendered stiffness against its declared one, on the simulated Falcon (not a test).

    python bench/wall_stiffness.py [--stiffness 500 1000 2000] [--forces 1 2 3 4 5] [--seeds 5]

For each declared stiffness and seed, systems/wall.yaml runs on the virtual clock with its scripted
hand pushing the handle down onto the wall with each force in turn: the simulated Falcon's dynamics,
the real frame codec (encoder counts in, integer motor commands out), the host's kinematics and the
simulator's, the 1 ms loop and the force limit all lie between the declared wall and the hand. The
true penetration is averaged over the last half second of each 1.5 s hold; the rendered stiffness is
the least-squares slope of force against depth over the forces. The seed moves the Falcon's power-on
pose, and so where homing leaves it and how its encoders quantise. Prints one row per declared
stiffness: the rendered mean and spread over seeds, and the worst per-force F/d ratio.
"""

from __future__ import annotations

import argparse
import json
import statistics
import tempfile
from pathlib import Path

import numpy as np

from hapticop.runtime.system import RunOptions, System
from hapticop.validation import validate_text

WALL = Path(__file__).resolve().parent.parent / "systems" / "wall.yaml"
RAMP_S, HOLD_S, AVERAGE_S = 0.5, 1.5, 0.5


def script(forces: list[float]) -> list[dict]:
    """Push with each force in turn (ramp, hold, let go), button 1 held throughout."""
    frames, t = [{"t_s": 0.0, "buttons": 1}], 0.0
    for f in forces:
        frames += [{"t_s": t + RAMP_S, "force_n": [0.0, -f, 0.0], "buttons": 1},
                   {"t_s": t + RAMP_S + HOLD_S, "force_n": [0.0, -f, 0.0], "buttons": 1}]
        t += RAMP_S + HOLD_S
    return frames + [{"t_s": t + RAMP_S, "buttons": 1}]


def measure(stiffness: float, forces: list[float], seed: int) -> list[float]:
    """Mean true depth (m) under each force, for a wall declared `stiffness` N/m."""
    text = WALL.read_text().replace("kp_n_per_m: 1000.0", f"kp_n_per_m: {stiffness!r}")
    text = text.replace("    block: scripted_hand\n", "    block: scripted_hand\n    params: "
                        + json.dumps({"script": script(forces)}) + "\n")
    validated = validate_text(text, "wall.yaml")
    assert validated.report.ok, [d.to_text() for d in validated.report.diagnostics]
    with tempfile.TemporaryDirectory() as run_dir:
        system = System(validated, RunOptions(clock="virtual", run_dir=Path(run_dir), seed=seed, echo=False))
        main = system.built.threads["main"]
        wall_y = main.runners["wall"].block.params.wall.point_m[1]
        samples: dict[float, list[float]] = {f: [] for f in forces}
        try:
            system.start_threads()
            i = 0
            while not system.flag("hand.finished"):
                system.clock.advance_to(i * 1_000_000)
                main.cycle()
                i += 1
                hand = main.runners["hand"].block
                if getattr(hand, "homed_since_ns", None) is None:  # not created yet, or not homed
                    continue
                t = (system.clock.now_ns() - hand.homed_since_ns) / 1e9 - hand.params.settle_s
                k, into = divmod(t, RAMP_S + HOLD_S)
                if 0 <= k < len(forces) and RAMP_S + HOLD_S - AVERAGE_S <= into:
                    y = main.runners["falcon_sim"].block.outputs.handle_position.value[1]
                    samples[forces[int(k)]].append(wall_y - float(y))
        finally:
            for runner in main.runners.values():
                runner.block.clean()
            system.writer.stop()
            system.built = system.main = None
            system.region.close()
    return [statistics.fmean(samples[f]) for f in forces]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--stiffness", type=float, nargs="+", default=[500.0, 1000.0, 2000.0])
    parser.add_argument("--forces", type=float, nargs="+", default=[1.0, 2.0, 3.0, 4.0, 5.0])
    parser.add_argument("--seeds", type=int, default=5)
    args = parser.parse_args()
    print(f"{'declared N/m':>12} {'rendered N/m':>13} {'spread (sd)':>11} {'rendered/declared':>17} "
          f"{'worst F/d per force':>19}")
    for k in args.stiffness:
        slopes, worst = [], 0.0
        for seed in range(args.seeds):
            depths = np.array(measure(k, args.forces, seed))
            forces = np.array(args.forces)
            slope = float(np.sum(forces * depths) / np.sum(depths * depths))  # F = k·d, through the origin
            slopes.append(slope)
            ratios = forces / depths / k
            worst = max(worst, float(np.max(np.abs(ratios - 1.0))))
        mean, sd = statistics.fmean(slopes), statistics.stdev(slopes) if len(slopes) > 1 else 0.0
        print(f"{k:12.0f} {mean:13.1f} {sd:11.2f} {mean / k:17.4f} {worst:18.2%}")


if __name__ == "__main__":
    main()
