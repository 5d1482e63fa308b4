"""Hand micro-benchmark (not a test) of the Novint Falcon's 1 kHz path: µs per call, and allocations.

    python bench/micro_falcon.py [--calls N] [--system SECONDS]

Kinematics, frame codec, the simulated device's 1 ms exchange, the Falcon block's cycle (sim
driver, homed, a force to render: receive and decode, forward kinematics, velocity, publishing,
Jacobian-transpose force, encode and send) and its simulator's (the frame in, one period of
physics, the frame out, the true handle state published). `--system` also runs
systems/hallway.yaml on the virtual clock and prints the compute time per step of the falcon,
falcon_sim and operator activities as the runtime measures it. Numbers depend on the machine:
compare changes run on the same machine, never assert them.
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
    tau, force, motor, counts = (np.zeros(3), np.array([1.0, -2.0, 0.5]), np.zeros(3, dtype=np.int64),
                                 np.zeros(3, dtype=np.int64))
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


def _block(cls, name: str, params, clock, run_dir: Path):
    """One block with its own ports, as the runtime would make it (no streams: the caller copies)."""
    import logging
    from types import SimpleNamespace

    from hapticop.runtime.context import ActivityContext, InputPort, OutputPort

    inputs = SimpleNamespace(**{n: InputPort(n, q, clock.now_ns) for n, q in cls.inputs.items()})
    outputs = SimpleNamespace(**{n: OutputPort(n, q, clock.now_ns) for n, q in cls.outputs.items()})
    block = cls(ActivityContext(name, params, inputs, outputs, {}, clock, logging.getLogger(f"bench.{name}"),
                                np.random.default_rng(0), run_dir))
    block.create()
    return block


def falcon_blocks():
    """The Falcon block (sim driver) and the Falcon simulator on their link, homed, a hand holding the grip
    near the centre, a force coming in; returns one cycle of each: (Falcon read and write, simulator)."""
    from hapticop.blocks.falcon import Falcon, FalconParams
    from hapticop.devices.falcon.homing import HomingHand
    from hapticop.runtime.clock import VirtualClock
    from hapticop.sim.devices.falcon import FalconSimulator, FalconSimulatorParams

    clock, run_dir = VirtualClock(), Path(tempfile.mkdtemp())
    device = _block(FalconSimulator, "falcon_sim", FalconSimulatorParams(), clock, run_dir)
    falcon = _block(Falcon, "falcon", FalconParams(driver="sim", simulator="falcon_sim"), clock, run_dir)
    device.configure_resources()
    assert falcon.configure_resources()
    homing, hand = HomingHand(), device.inputs.hand_force.value
    position, velocity = device.outputs.handle_position.value, device.outputs.handle_velocity.value

    def tick() -> None:
        clock.advance_to(clock.now_ns() + 1_000_000)

    while True:
        device.compute()
        if falcon.configure_capabilities():
            break
        homing.push(clock.now_ns() / 1e9, position + CENTRE, velocity, hand)
        tick()
    falcon.inputs.force.value[:] = (0.5, -1.0, 2.0)

    def host() -> None:
        falcon.compute()
        falcon.flush()

    def simulator() -> None:
        tick()
        np.multiply(position, -200.0, out=hand)  # a hand holding the grip near the centre
        device.compute()

    for _ in range(500):
        simulator()
        host()
    return host, simulator


def time_blocks(calls: int) -> tuple[float, float, float, float]:
    """(median, p99) µs of the Falcon block's cycle (the host side) and of its simulator's."""
    import time

    host, simulator = falcon_blocks()
    host_us, device_us = np.empty(calls), np.empty(calls)
    clock = time.perf_counter_ns
    for i in range(calls):
        started = clock()
        simulator()
        between = clock()
        host()
        host_us[i], device_us[i] = clock() - between, between - started
    return (float(np.median(host_us)) / 1e3, float(np.percentile(host_us, 99)) / 1e3,
            float(np.median(device_us)) / 1e3, float(np.percentile(device_us, 99)) / 1e3)


def system(seconds: float) -> None:
    """The falcon activity's cost in the hallway composition, as the runtime's report gives it."""
    from hapticop.runtime.system import RunOptions, run_system
    from hapticop.validation import validate_path

    path = Path(__file__).resolve().parent.parent / "systems" / "hallway.yaml"
    validated = validate_path(path)
    with tempfile.TemporaryDirectory() as run_dir:
        options = RunOptions(clock="virtual", duration_ns=int(seconds * 1e9), run_dir=Path(run_dir), echo=False)
        result = run_system(validated, options)
    for name in ("falcon", "falcon_sim", "operator"):
        activity = result.timing["activities"][name]
        c = activity["compute_us"]
        print(f"hallway.yaml, virtual clock, {seconds:g} s: {name} {activity['steps']} steps, compute p50 "
              f"{c['p50']} us, p99 {c['p99']} us, of which simulation {activity.get('simulation_us_per_step')} us "
              "per step (mean)")


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
    host, host99, device, device99 = time_blocks(args.calls)
    print(f"{'Falcon block cycle (compute + flush)':44s} {host:10.1f} {host99:8.1f}")
    print(f"{'Falcon simulator block cycle':44s} {device:10.1f} {device99:8.1f}")
    if args.system > 0:
        system(args.system)


if __name__ == "__main__":
    main()
