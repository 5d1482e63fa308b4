"""Hand micro-benchmark of the haptic control laws and the simulated world: µs per call, and allocations.

Run ``python bench/micro_haptics.py [--calls N] [--blocks SECONDS] [--beams-factor K]``.
Not a test: timings depend on the machine.
The scene is the H2 hallway start (docs/hallway-experiment.md §2): 2 m wide, robot 0.3 m off-centre, end wall 9.5 m
ahead (within the 10 m range), moving at 0.5 m/s with the handle pushed forward and sideways.
With ``--blocks``, systems/hallway.yaml also runs that long on the virtual clock and every
``compute`` of the haptic controller (cycles with and without a new scan apart) and of the
world (once the operator drives) is timed in place, wrapper included (~0.2 µs).
"""

from __future__ import annotations

import argparse
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

from hapticop.devices.sick.device_model import ANGLES_RAD
from hapticop.haptics.force_models import FORCE_MODELS, make_force_model
from hapticop.haptics.geometry import BeamGeometry
from hapticop.haptics.governor import govern_cycle, govern_scan, govern_twist
from hapticop.haptics.handle import CentringPD, handle_to_twist
from hapticop.haptics.scan_field import ScanField
from hapticop.haptics.scan_filter import MovingAverage, MovingAverageParams, MovingMedian
from hapticop.sim.hallway_task import Hallway
from hapticop.sim.operator import BlindOperator
from hapticop.sim.recording import TrajectoryRecorder
from hapticop.testing import allocation_stats, time_per_call


def beam_angles(factor: int = 1) -> np.ndarray:
    """The TiM561's beam angles, or `factor` times as many over the same field of view (a denser scanner)."""
    angles = np.asarray(ANGLES_RAD, dtype=float)
    if factor == 1:
        return angles
    return np.linspace(angles[0], angles[-1], factor * (len(angles) - 1) + 1)


def cases(factor: int = 1) -> dict[str, Callable[[], object]]:
    """The per-cycle calls to measure, each with its inputs already prepared (`factor` times the beams)."""
    h2 = Hallway.named("H2")
    raw_angles = beam_angles(factor)
    engine = h2.engine()
    engine.place_robot(np.array(h2.start))
    raw = engine.scan(raw_angles, np.empty(len(raw_angles), np.float32), 0.05, 10.0)
    average = MovingAverage()
    angles = average.configure(raw_angles)
    ranges = average.apply(raw).copy()
    median = MovingMedian()
    median.configure(raw_angles)
    handle = np.array([0.01, 0.0, -0.02])
    twist = np.array([0.5, 0.0, 0.1])
    force = np.zeros(3)
    n = len(raw_angles)
    field = ScanField(MovingAverageParams(), raw_angles)
    run: dict[str, Callable[[], object]] = {
        f"scan filter: moving average {n}→{len(angles)}": lambda: average.apply(raw),
        f"scan filter: median of 5, {n}": lambda: median.apply(raw),
        "scan field: filter and place (per scan)": lambda: field.apply(raw),
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
    run["governor S1: scan + cycle"] = lambda: govern_twist(twist, ranges, beams, executed)
    run["governor S1: scan only (15 Hz)"] = lambda: govern_scan(ranges, beams)
    gap = govern_scan(ranges, beams)
    run["governor S1: cycle only (per cycle)"] = lambda: govern_cycle(twist, beams, gap, executed)
    pd = CentringPD()
    run["centring PD + driving map"] = lambda: (pd.compute(handle, force, env_force=force),
                                                 handle_to_twist(handle, executed))
    if factor == 1:
        run.update(world_cases())
    return run


def world_cases() -> dict[str, Callable[[], object]]:
    """The simulated world's per-cycle calls: the judge's clearance, the recorder, the operator's hand."""
    run: dict[str, Callable[[], object]] = {}
    pose = np.array([3.0, 0.2, 0.1])
    for name in ("H1", "H4"):
        g = Hallway.named(name)
        engine = g.engine()

        def clearances(engine=engine, g=g) -> object:
            engine.place_robot(pose)
            return engine.clearances(g.front)

        run[f"world: footprint clearances (all, end wall, sides), {name}"] = clearances
    recorder = TrajectoryRecorder(10_000_000)
    two, three = np.zeros(2), np.zeros(3)
    run["world: recorder append"] = lambda: recorder.append(
        1.0, pose, robot_velocity=two, cmd=two, handle_position=three, handle_velocity=three, force_env=three,
        force_hand=three, force_device=three, clearance=0.5, front_clearance=0.5, side_clearance=0.5)
    for variant in ("nominal", "tremor"):
        operator = BlindOperator.variant(variant)
        clock = [0.0]
        felt, position, velocity, out = (np.array([0.1, 0.0, 0.5]), np.array([0.001, 0.0, -0.01]), np.zeros(3),
                                         np.zeros(3))

        def step(operator=operator, clock=clock, felt=felt, position=position, velocity=velocity, out=out):
            clock[0] += 0.001
            operator.step(clock[0], felt, position, out, velocity)

        run[f"operator step, {variant}"] = step
    return run


def block_computes(seconds: float) -> dict[str, np.ndarray]:
    """Run systems/hallway.yaml on the virtual clock; µs of every haptic and world compute, by kind of cycle."""
    from hapticop.blocks.haptic import HapticController
    from hapticop.runtime.system import RunOptions, run_system
    from hapticop.sim.scene_world import SceneWorld
    from hapticop.validation import validate_path

    samples: dict[str, list[int]] = {"haptic block, no new scan": [], "haptic block, new scan": [],
                                     "world block, operator driving": []}
    clock = time.perf_counter_ns

    def haptic(self: HapticController, compute=HapticController.compute) -> None:
        new_scan = self.inputs.ranges.fresh
        started = clock()
        compute(self)
        samples["haptic block, new scan" if new_scan else "haptic block, no new scan"].append(clock() - started)

    def world(self: SceneWorld, compute=SceneWorld.compute) -> None:
        driving = self.started_ns is not None
        started = clock()
        compute(self)
        if driving:
            samples["world block, operator driving"].append(clock() - started)

    originals = HapticController.compute, SceneWorld.compute
    HapticController.compute, SceneWorld.compute = haptic, world  # type: ignore[method-assign]
    try:
        path = Path(__file__).resolve().parent.parent / "systems" / "hallway.yaml"
        validated = validate_path(path)
        with tempfile.TemporaryDirectory() as run_dir:
            run_system(validated, RunOptions(clock="virtual", duration_ns=int(seconds * 1e9), run_dir=Path(run_dir),
                                             echo=False))
    finally:
        HapticController.compute, SceneWorld.compute = originals  # type: ignore[method-assign]
    return {k: np.array(v, dtype=np.float64) / 1e3 for k, v in samples.items()}


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--calls", type=int, default=5000)
    parser.add_argument("--blocks", type=float, default=0.0, metavar="SECONDS",
                        help="also time the haptic and world blocks in a virtual-clock hallway run this long")
    parser.add_argument("--beams-factor", type=int, default=1, metavar="K",
                        help="K times the TiM561's 811 beams over its field of view (the scan's laws only)")
    args = parser.parse_args(argv)
    n = len(beam_angles(args.beams_factor))
    print(f"{n - 2} beams after the moving average; {n} raw beams for the filters.")
    print(f"{'call':44s} {'median µs':>10s} {'p99 µs':>8s} {'grown B':>8s} {'peak B':>7s}")
    for label, fn in cases(args.beams_factor).items():
        median, p99 = time_per_call(fn, args.calls)
        grown, peak = allocation_stats(fn)
        print(f"{label:44s} {median:10.1f} {p99:8.1f} {grown:8d} {peak:7d}")
    if args.blocks > 0:
        print(f"\nsystems/hallway.yaml, {args.blocks:g} s on the virtual clock")
        print(f"{'block compute':44s} {'median µs':>10s} {'p99 µs':>8s} {'cycles':>8s}")
        for label, us in block_computes(args.blocks).items():
            if us.size:
                print(f"{label:44s} {np.median(us):10.1f} {np.percentile(us, 99):8.1f} {us.size:8d}")


if __name__ == "__main__":
    main()
