"""Benchmark: the pysoem master at 1 kHz against the emulated ropod segment, and wheel-loss recovery.

In a private network namespace (the sandbox of hapticop.devices.ethercat.emulator), the master
brings up the seven emulated slaves and runs the ropod's cycle: write the wheel commands,
send/receive the process data, read the sensors, step the platform velocity controller
(0.2 m/s forward). The EtherCAT watchdog runs SOEM's slave check in its own thread, as in
systems/hallway_ethercat.yaml (exchange SCHED_FIFO 39, watchdog 40, emulator 45). Then a
wheel is lost and powered back several times; each time it measures how long until the
controller is held (zero velocity setpoint) and until every slave is back in OP. Losing wheel_3
also takes wheel_4, wired behind it, off the segment until wheel_3 has power again.

Measures: round-trip time of send+receive, working-counter errors, missed cycles, CPU of
the master's process and of the emulator's. Run as root:

    python bench/ethercat_cycle.py --seconds 60 --losses 5 --out bench/results/ethercat-cycle.md
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import sys
import threading
import time
from pathlib import Path

import numpy as np

from hapticop.blocks.ethercat import SMARTWHEEL_LAYOUT
from hapticop.devices.ethercat.emulator.ropod_segment import EK1100, EK1122, SWMC
from hapticop.devices.ethercat.emulator.sandbox import Sandbox, namespace_problem
from hapticop.devices.ethercat.master import ExpectedSlave, SoemMaster
from hapticop.devices.ethercat.recovery import SlaveCheck
from hapticop.devices.ropod import PlatformVelocityController
from hapticop.devices.ropod.pdo import new_rx_image, new_tx_image
from hapticop.runtime.clock import RealtimeClock

PERIOD_NS = 1_000_000
NAMES = ["ek1100", "ek1122_front", "wheel_1", "wheel_2", "ek1122_rear", "wheel_3", "wheel_4"]
PRODUCTS = [EK1100, EK1122, SWMC, SWMC, EK1122, SWMC, SWMC]
WHEELS = [2, 3, 5, 6]
LOST = 5  # bus position of wheel_3
SHORT_CYCLES = 10  # the watchdog block's lost_after_cycles


def _fifo(priority: int) -> bool:
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(priority))
        return True
    except OSError:
        return False


def _cpu_s(pid: int) -> float:
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


class Watchdog(threading.Thread):
    """SOEM's check every millisecond (or every 10 ms while healthy), raising `held`."""

    def __init__(self, master: SoemMaster, clock: RealtimeClock):
        super().__init__(daemon=True, name="watchdog")
        self.check = SlaveCheck(master, lambda message: self.events.append((clock.now_ns(), message)))
        self.master, self.clock = master, clock
        self.events: list[tuple[int, str]] = []
        self.held = False
        self.short = 0
        self.running = True

    def _fault_now(self) -> None:
        self.held = True

    def run(self) -> None:
        _fifo(40)
        deadline, last_poll = self.clock.now_ns(), 0
        while self.running:
            deadline += PERIOD_NS
            self.clock.sleep_until(deadline)
            now = self.clock.now_ns()
            self.short = self.short + 1 if self.master.last_wkc != self.master.expected_wkc else 0
            if self.check.needed() or now - last_poll >= 10 * PERIOD_NS:
                last_poll = now
                self.check.check(on_fault=self._fault_now)
            self.held = self.check.pending or self.short >= SHORT_CYCLES


def run(seconds: float, losses: int) -> dict:
    clock = RealtimeClock()
    expected = [ExpectedSlave(n, p, *SMARTWHEEL_LAYOUT) if p == SWMC else ExpectedSlave(n, p)
                for n, p in zip(NAMES, PRODUCTS)]
    with Sandbox() as box:
        master = SoemMaster(box.interface, expected, receive_timeout_us=2000, frame_timeout_us=2000, cycle_ns=PERIOD_NS)
        master.open()
        rx, tx = new_rx_image(4), new_tx_image(4)

        def write_outputs():
            for wheel, position in enumerate(WHEELS):
                master.write_outputs(position, rx[wheel])

        master.bring_up(on_safeop=write_outputs)
        controller = PlatformVelocityController()
        setpoint, zero, measured = np.array([0.2, 0.0, 0.0]), np.zeros(3), np.zeros(3)
        watchdog = Watchdog(master, clock)
        watchdog.start()
        realtime = _fifo(39)
        n = max(int(seconds * 1000), 3500) + 10
        rtt = np.zeros(n, np.int64)
        wkc = np.zeros(n, np.int32)
        held_at = np.zeros(n, np.bool_)
        stamp = np.zeros(n, np.int64)
        missed = 0

        def cycles(count: int, start: int, deadline: int, record: bool):
            nonlocal missed
            for i in range(start, start + count):
                deadline += PERIOD_NS
                clock.sleep_until(deadline)
                now = clock.now_ns()
                if now - deadline >= PERIOD_NS:  # overran: skip the periods it covered
                    skipped = (now - deadline) // PERIOD_NS
                    deadline += skipped * PERIOD_NS
                    if record:
                        missed += int(skipped)
                write_outputs()
                t1 = clock.now_ns()
                w = master.exchange()
                t2 = clock.now_ns()
                for wheel, position in enumerate(WHEELS):
                    master.read_inputs(position, tx[wheel])
                held = watchdog.held
                controller.step(zero if held else setpoint, tx, rx, measured, stop=held)
                if record:
                    rtt[i], wkc[i], held_at[i], stamp[i] = t2 - t1, w, held, now
            return deadline

        deadline = cycles(500, 0, clock.now_ns(), False)  # settle: the robot starts rolling
        usage0, emu0, wall0 = resource.getrusage(resource.RUSAGE_SELF), _cpu_s(box.process.pid), time.monotonic()
        steady = int(seconds * 1000)
        deadline = cycles(steady, 0, deadline, True)
        usage1, emu1, wall1 = resource.getrusage(resource.RUSAGE_SELF), _cpu_s(box.process.pid), time.monotonic()
        wall = wall1 - wall0
        cpu_master = (usage1.ru_utime + usage1.ru_stime - usage0.ru_utime - usage0.ru_stime) / wall
        r = rtt[:steady] / 1000.0
        ok = wkc[:steady] == master.expected_wkc
        result = {
            "cycles": steady, "seconds": wall, "realtime_priority": realtime,
            "rtt_us": {"p50": float(np.percentile(r[ok], 50)), "p99": float(np.percentile(r[ok], 99)),
                       "p99.9": float(np.percentile(r[ok], 99.9)), "max": float(r.max())},
            "wkc_errors": int((~ok).sum()), "no_frame": int((wkc[:steady] < 0).sum()),
            "missed_cycles": missed, "held_cycles": int(held_at[:steady].sum()),
            "cpu_master_process": cpu_master, "cpu_emulator": (emu1 - emu0) / wall,
            "losses": [],
        }
        for _ in range(losses):
            held_at[:] = False
            deadline = cycles(1500, 0, deadline, False)  # driving again at speed
            lost_ns = clock.now_ns()
            box.fault("lose", slave=LOST)
            deadline = cycles(500, 0, deadline, True)
            restored_ns = clock.now_ns()
            box.fault("restore", slave=LOST)
            deadline = cycles(3000, 500, deadline, True)
            first_held = int(np.argmax(held_at[:3500])) if held_at[:3500].any() else None
            back = [i for i in range(500, 3500) if not held_at[i] and wkc[i] == master.expected_wkc]
            ops = [t for t, m in watchdog.events if m == "wheel_3: SAFE-OP -> OP" and t > restored_ns]
            result["losses"].append({
                "to_zero_setpoint_ms": (stamp[first_held] - lost_ns) / 1e6 if first_held is not None else None,
                "restore_to_op_ms": (ops[0] - restored_ns) / 1e6 if ops else None,
                "restore_to_released_ms": (stamp[back[0]] - restored_ns) / 1e6 if back else None,
                "loss_to_released_ms": (stamp[back[0]] - lost_ns) / 1e6 if back else None,
            })
        watchdog.running = False
        watchdog.join()
        result["watchdog_log"] = [m for _, m in watchdog.events[-12:]]
        master.close()
        result["final_states"] = [s["state"] for s in box.fault("status")["slaves"]]
    return result


def _table(result: dict) -> str:
    r = result["rtt_us"]
    losses = result["losses"]

    def med(key):
        values = [x[key] for x in losses if x[key] is not None]
        return f"{np.median(values):.1f} (min {min(values):.1f}, max {max(values):.1f})" if values else "-"

    return "\n".join([
        f"pysoem 1 kHz against the emulated ropod segment, {result['cycles']} cycles in {result['seconds']:.1f} s "
        f"(SCHED_FIFO: {'yes' if result['realtime_priority'] else 'no'})",
        "",
        "| round trip p50 | p99 | p99.9 | max | WKC errors (no frame) | missed cycles "
        "| CPU master process | CPU emulator |",
        "|---|---|---|---|---|---|---|---|",
        f"| {r['p50']:.0f} us | {r['p99']:.0f} us | {r['p99.9']:.0f} us | {r['max']:.0f} us | "
        f"{result['wkc_errors']} ({result['no_frame']}) | {result['missed_cycles']} | "
        f"{100 * result['cpu_master_process']:.0f} % | {100 * result['cpu_emulator']:.0f} % |",
        "",
        f"Wheel 3 lost (power off) {len(losses)} times, powered back after 0.5 s (median, min, max in ms):",
        "",
        "| loss to zero setpoint | power back to OP | power back to setpoints released | loss to released |",
        "|---|---|---|---|",
        f"| {med('to_zero_setpoint_ms')} | {med('restore_to_op_ms')} | {med('restore_to_released_ms')} | "
        f"{med('loss_to_released_ms')} |",
    ])


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=60.0)
    parser.add_argument("--losses", type=int, default=5)
    parser.add_argument("--out", type=Path, help="write the table (and the JSON beside it) here")
    args = parser.parse_args()
    problem = namespace_problem()
    if problem:
        print(f"error: {problem}", file=sys.stderr)
        return 1
    result = run(args.seconds, args.losses)
    table = _table(result)
    print(table)
    if args.out:
        args.out.write_text(f"# EtherCAT cycle\n\n`python bench/ethercat_cycle.py --seconds {args.seconds:g} "
                            f"--losses {args.losses}`\n\n{table}\n")
        args.out.with_suffix(".json").write_text(json.dumps(result, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
