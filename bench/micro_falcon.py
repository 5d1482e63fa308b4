"""Hand micro-benchmark (not a test) of the Novint Falcon's 1 kHz path: µs per call, and allocations.

    python bench/micro_falcon.py [--calls N] [--system SECONDS]

Kinematics, frame codec, the simulated device's 1 ms exchange, and the Falcon block's whole
cycle (sim driver, homed, operator driving, a force to render) with its host side: the cycle
less the time its simulation timer counted (device and operator), i.e. decode, forward
kinematics, velocity, Jacobian-transpose force, encode and publishing. `--system` also runs systems/hallway.yaml on the virtual clock and prints the
falcon activity's compute time per step as the runtime measures it, of which simulation
(the simulated device and the scene's operator). Numbers depend on the machine: compare
changes run on the same machine, never assert them.
"""

from __future__ import annotations

import argparse
import tempfile
from collections.abc import Callable
from pathlib import Path

import numpy as np

from hapticop.devices.falcon import FalconKinematics, Flag, FrameCodec, SimulatedFalcon, Status, new_frame
from hapticop.devices.falcon.codec import Command
from hapticop.testing import allocation_stats, time_per_call

CENTRE = np.array([0.0, 0.0, 0.125])


def cases() -> dict[str, Callable[[], object]]:
    """The per-cycle calls to measure, each with its inputs already prepared."""
    kin, codec = FalconKinematics(), FrameCodec()
    position, theta, J, M = np.array([0.01, -0.02, 0.13]), np.zeros(3), np.zeros((3, 3)), np.zeros((3, 3))
    tau, force, motor, counts = np.zeros(3), np.array([1.0, -2.0, 0.5]), np.zeros(3, dtype=np.int64), np.zeros(3, dtype=np.int64)
    kin.inverse(position, theta)
    kin.counts_from_angles(theta, counts)
    enc = counts.copy()
    tick = [0]

    def forward_moving() -> None:  # a handle moving a few counts per ms: the warm 1 kHz case
        tick[0] += 1
        i = tick[0] % 200
        enc[0], enc[1], enc[2] = counts[0] + i, counts[1] - i // 2, counts[2] + i // 3
        kin.forward(enc, theta)

    cmd, status_frame, status, command = new_frame(), new_frame(), Status(), Command()
    codec.encode_command([100, -200, 300], Flag.HOMING | Flag.LED_GREEN, cmd)
    codec.encode_status(counts, 7, 0, status_frame)

    sim = SimulatedFalcon(rng=np.random.default_rng(3), homed=True)
    reply, hand = new_frame(), np.array([0.5, -0.3, 1.0])
    codec.encode_command([100, -200, 300], Flag.HOMING | Flag.LED_GREEN, cmd)
    for _ in range(300):
        sim.exchange(cmd, 0.001, hand, out=reply)

    return {
        "kinematics: inverse": lambda: kin.inverse(position, theta),
        "kinematics: jacobian": lambda: kin.jacobian(position, J, M),
        "kinematics: forward, warm, moving": forward_moving,
        "kinematics: forces_to_motor(None)": lambda: kin.forces_to_motor(None, force, motor),
        "kinematics: forces_to_torques(p)": lambda: kin.forces_to_torques(position, force, tau),
        "kinematics: torques_to_force(p)": lambda: kin.torques_to_force(position, tau, force),
        "kinematics: counts_from_angles": lambda: kin.counts_from_angles(theta, counts),
        "codec: encode_command": lambda: codec.encode_command(motor, 7, cmd),
        "codec: decode_command": lambda: codec.decode_command(cmd, command),
        "codec: encode_status": lambda: codec.encode_status(counts, 7, 0, status_frame),
        "codec: decode_status": lambda: codec.decode_status(status_frame, status),
        "simulated: exchange 1 ms": lambda: sim.exchange(cmd, 0.001, hand, out=reply),
    }


def falcon_block():
    """The real Falcon block (sim driver) in a scene of its own, homed, the operator driving,
    a force coming in; returns a call of one cycle and the timer of its simulation part."""
    import logging
    from types import SimpleNamespace

    from hapticop.blocks.falcon import Falcon, FalconParams
    from hapticop.runtime.clock import VirtualClock
    from hapticop.runtime.context import ActivityContext, InputPort, OutputPort, SimulationTimer
    from hapticop.sim.hallway import HallwayGeometry, World
    from hapticop.sim.operator import BlindOperator
    from hapticop.sim.scene import Scene, open_scene

    geometry = HallwayGeometry.named("H1")
    open_scene(Scene("bench", geometry, World.from_geometry(geometry), BlindOperator.variant("nominal")))
    clock, sim_ns = VirtualClock(), np.zeros(1, dtype=np.int64)
    inputs = SimpleNamespace(**{n: InputPort(n, q, clock.now_ns) for n, q in Falcon.inputs.items()})
    outputs = SimpleNamespace(**{n: OutputPort(n, q, clock.now_ns) for n, q in Falcon.outputs.items()})
    context = ActivityContext("falcon", FalconParams(scene="bench"), inputs, outputs, {}, clock,
                              logging.getLogger("bench.falcon"), np.random.default_rng(0), Path(tempfile.mkdtemp()),
                              simulation=SimulationTimer(sim_ns, 0))
    block = Falcon(context)

    def tick() -> None:
        clock.advance_to(clock.now_ns() + 1_000_000)

    assert block.configure_resources()
    while not block.configure_capabilities():
        tick()
    block.scene.operator_since_ns = clock.now_ns()
    inputs.force.value[:] = (0.5, -1.0, 2.0)

    def cycle() -> None:
        block.compute()
        tick()

    for _ in range(500):
        cycle()
    return cycle, sim_ns


def time_host_side(calls: int) -> tuple[float, float, float, float]:
    """(median, p99) µs of a whole Falcon block cycle and of its host side (less simulation)."""
    import time

    cycle, sim_ns = falcon_block()
    whole, host = np.empty(calls), np.empty(calls)
    clock = time.perf_counter_ns
    for i in range(calls):
        sim_before, started = int(sim_ns[0]), clock()
        cycle()
        whole[i] = clock() - started
        host[i] = whole[i] - (int(sim_ns[0]) - sim_before)
    return (float(np.median(whole)) / 1e3, float(np.percentile(whole, 99)) / 1e3,
            float(np.median(host)) / 1e3, float(np.percentile(host, 99)) / 1e3)


def system(seconds: float) -> None:
    """The falcon activity's cost in the hallway composition, as the runtime's report gives it."""
    from hapticop.runtime.system import RunOptions, run_system
    from hapticop.validation import validate_path

    path = Path(__file__).resolve().parent.parent / "systems" / "hallway.yaml"
    validated = validate_path(path)
    with tempfile.TemporaryDirectory() as run_dir:
        options = RunOptions(clock="virtual", duration_ns=int(seconds * 1e9), run_dir=Path(run_dir), echo=False)
        result = run_system(validated, options)
    falcon = result.timing["activities"]["falcon"]
    c = falcon["compute_us"]
    print(f"\nhallway.yaml, virtual clock, {seconds:g} s: falcon activity {falcon['steps']} steps, compute "
          f"p50 {c['p50']} us, p99 {c['p99']} us, of which simulation {falcon.get('simulation_us_per_step')} us "
          "per step (mean; device + operator)")


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--calls", type=int, default=5000)
    parser.add_argument("--system", type=float, default=0.0, help="also run the hallway for this many seconds")
    args = parser.parse_args(argv)
    print(f"numpy {np.__version__}, {args.calls} calls each")
    print(f"{'call':44s} {'median µs':>10s} {'p99 µs':>8s} {'grown B':>8s} {'peak B':>7s}")
    for label, fn in cases().items():
        median, p99 = time_per_call(fn, args.calls)
        grown, peak = allocation_stats(fn)
        print(f"{label:44s} {median:10.1f} {p99:8.1f} {grown:8d} {peak:7d}")
    whole, whole99, host, host99 = time_host_side(args.calls)
    print(f"{'Falcon block compute (sim driver, whole)':44s} {whole:10.1f} {whole99:8.1f}")
    print(f"{'  of which host side (less simulation)':44s} {host:10.1f} {host99:8.1f}")
    if args.system > 0:
        system(args.system)


if __name__ == "__main__":
    main()
