"""Hand micro-benchmark (not a test): microseconds per controller cycle, simulator step and block cycle.

    python bench/micro_ropod.py [cycles] [--no-blocks]

Runs controller and plant in closed loop at 1 kHz (a turning 0.3 m/s setpoint), then times
each `step` alone on the warmed-up state. Then it runs the hallway composition in virtual
time until the robot drives, and times the fieldbus and watchdog blocks as their threads run
them: `compute` alone, and the activity's whole step (input refresh and LCSM around it), and
one whole exchange with the simulated ropod (its step, the master's read and write).
Numbers depend on the machine; use them to compare changes, not as real-time claims.
"""

from __future__ import annotations

import heapq
import sys
import tempfile
from collections.abc import Callable
from pathlib import Path

import numpy as np

from hapticop.devices.ropod.pdo import new_rx_image, new_tx_image
from hapticop.devices.ropod.plant import RopodPlant
from hapticop.devices.ropod.velocity_controller import PlatformVelocityController
from hapticop.testing import time_per_call

HALLWAY = Path(__file__).resolve().parent.parent / "systems" / "hallway.yaml"
FIELDBUS_BLOCKS = ("ropod_plant", "ethercat", "ropod", "ethercat_watchdog")


def library_cases() -> dict[str, Callable[[], object]]:
    ctrl, plant = PlatformVelocityController(), RopodPlant()
    tx, rx, v_meas = new_tx_image(4), new_rx_image(4), np.zeros(3)
    setpoint = np.array([0.3, 0.0, 0.3])
    plant.write_sensors(tx)
    for _ in range(1000):
        ctrl.step(setpoint, tx, rx, v_meas)
        plant.step(rx, 0.001, tx)
    kin, bank = ctrl.kinematics, ctrl.bank
    delta, enable = ctrl.delta.tolist(), ctrl.unit_enable.tolist()
    errors, outputs = np.concatenate([ctrl.v_sp - ctrl.v_meas, ctrl.wheel_speed_sp - ctrl.phidot]).tolist(), [0.0] * 11
    return {
        "controller.step": lambda: ctrl.step(setpoint, tx, rx, v_meas),
        "plant.step (RK4, 1 substep)": lambda: plant.step(rx, 0.001, tx),
        "  controller bank (11 ch)": lambda: bank.step_values(errors, outputs),
        "  kinematics.evaluate": lambda: kin.evaluate(delta, enable),
    }


def block_cases(run_dir: Path, warm_up_s: float = 4.0) -> tuple[object, dict[str, Callable[[], object]]]:
    """The hallway in virtual time until the robot drives; then each block's cycle, the clock
    advancing 1 ms per call (the simulated ropod steps by the elapsed time)."""
    from hapticop.runtime.system import RunOptions, System
    from hapticop.validation import validate_path

    validated = validate_path(HALLWAY)
    system = System(validated, RunOptions(clock="virtual", run_dir=run_dir, echo=False))
    threads, queue, order = system.built.threads, system.scheduler.queue, list(system.composition.threads)
    heapq.heappush(queue, (0, order.index(system.scheduler.main_name), system.scheduler.main_name))
    while queue and queue[0][0] < warm_up_s * 1e9:  # Scheduler.run_virtual, stopped part way
        deadline, rank, name = heapq.heappop(queue)
        system.clock.advance_to(deadline)
        threads[name].cycle()
        heapq.heappush(queue, (deadline + threads[name].period, rank, name))
    states = {name: system.state(name).name for name in FIELDBUS_BLOCKS}
    if set(states.values()) != {"RUNNING"}:
        raise RuntimeError(f"the fieldbus blocks are not all running after {warm_up_s} s: {states}")
    clock = system.clock

    def stepping(fn: Callable[[], object]) -> Callable[[], object]:
        def call() -> None:
            clock.advance_to(clock.now_ns() + 1_000_000)
            fn()
        return call

    cases: dict[str, Callable[[], object]] = {"(clock advance alone)": stepping(lambda: None)}
    for name in FIELDBUS_BLOCKS:
        runner = system.built.runners[name]
        cases[f"{name}: compute"] = stepping(runner.block.compute)
        cases[f"{name}: activity step"] = stepping(runner.step)
    plant, master = system.built.runners["ropod_plant"].block, system.built.runners["ethercat"].block

    def exchange() -> None:
        plant.compute()
        master.compute()
        master.flush()

    cases["exchange (plant, master r+w)"] = stepping(exchange)
    return system, cases


def report(cases: dict[str, Callable[[], object]], cycles: int) -> None:
    for name, fn in cases.items():
        median, p99 = time_per_call(fn, cycles)
        print(f"{name:32s} median {median:7.1f} us   p99 {p99:7.1f} us")


def main(cycles: int = 2000, blocks: bool = True) -> None:
    print(f"numpy {np.__version__}, {cycles} calls x 5 runs")
    report(library_cases(), cycles)
    if not blocks:
        return
    with tempfile.TemporaryDirectory() as tmp:
        system, cases = block_cases(Path(tmp))
        try:
            report(cases, cycles)
        finally:
            system.writer.stop()
            system.built = system.main = None
            system.region.close()


if __name__ == "__main__":
    args = [a for a in sys.argv[1:] if not a.startswith("--")]
    main(int(args[0]) if args else 2000, "--no-blocks" not in sys.argv)
