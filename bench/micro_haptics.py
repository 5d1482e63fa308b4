"""Hand micro-benchmark of the haptic control laws: µs per call with 809 beams, and allocations.

Run ``python bench/micro_haptics.py [--calls N]``. Not a test: timings depend on the machine.
The scene is the H2 hallway start (notes §2): 2 m wide, robot 0.3 m off-centre, end wall 9.5 m
ahead (within the 10 m range), moving at 0.5 m/s with the handle pushed forward and sideways.
"""

from __future__ import annotations

import argparse
from collections.abc import Callable

import numpy as np

from hapticop.haptics.force_models import FORCE_MODELS, make_force_model
from hapticop.haptics.geometry import BeamGeometry
from hapticop.haptics.governor import govern_twist
from hapticop.haptics.handle import CentringPD, handle_to_twist
from hapticop.haptics.scan_filter import MovingAverage, MovingMedian
from hapticop.haptics.synthetic import cast, hallway, tim561_angles
from hapticop.measure import allocation_stats, time_per_call


def cases() -> dict[str, Callable[[], object]]:
    """The per-cycle calls to measure, each with its inputs already prepared."""
    raw_angles = tim561_angles()
    raw = cast(raw_angles, hallway(2.0, 10.0), origin=(0.75, 0.3), heading=np.radians(8.0)).astype(np.float32)
    average = MovingAverage()
    angles = average.configure(raw_angles)
    ranges = average.apply(raw).copy()
    median = MovingMedian()
    median.configure(raw.shape[0])
    handle = np.array([0.01, 0.0, -0.02])
    twist = np.array([0.5, 0.0, 0.1])
    force = np.zeros(3)
    run: dict[str, Callable[[], object]] = {
        "scan filter: moving average 811→809": lambda: average.apply(raw),
        "scan filter: median of 5, 811": lambda: median.apply(raw),
    }
    for name in FORCE_MODELS:
        model = make_force_model(name, angles)
        run[f"{name}: compute (scan + render)"] = (
            lambda model=model: model.compute(handle, ranges, twist, force, 0.05)
        )
        run[f"{name}: render only (per cycle)"] = (
            lambda model=model: model.render(handle, twist, force, 0.05)
        )
    beams = BeamGeometry(angles)
    executed = np.zeros(3)
    run["governor S1"] = lambda: govern_twist(twist, ranges, beams, executed)
    pd = CentringPD()
    run["centring PD + driving map"] = lambda: (pd.compute(handle, force, env_force=force),
                                                 handle_to_twist(handle, executed))
    return run


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--calls", type=int, default=5000)
    args = parser.parse_args(argv)
    print("809 beams after the moving average; 811 raw beams for the filters.")
    print(f"{'call':44s} {'median µs':>10s} {'p99 µs':>8s} {'grown B':>8s} {'peak B':>7s}")
    for label, fn in cases().items():
        median, p99 = time_per_call(fn, args.calls)
        grown, peak = allocation_stats(fn)
        print(f"{label:44s} {median:10.1f} {p99:8.1f} {grown:8d} {peak:7d}")


if __name__ == "__main__":
    main()
