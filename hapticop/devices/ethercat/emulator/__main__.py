"""`python -m hapticop.devices.ethercat.emulator IFACE`: run the emulated ropod segment on an interface."""

from __future__ import annotations

import argparse
import os
import signal
import sys
from pathlib import Path

import numpy as np


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m hapticop.devices.ethercat.emulator",
                                     description="Emulated ropod EtherCAT segment on a network interface (root).")
    parser.add_argument("interface", help="the interface the master's frames arrive on (e.g. a veth peer)")
    parser.add_argument("--control", type=Path, help="Unix socket for faults and status (JSON lines)")
    parser.add_argument("--truth", type=Path, help="file the robot's true pose is published to (in /dev/shm)")
    parser.add_argument("--seed", type=int, default=0, help="seed of the simulated robot's noise")
    parser.add_argument("--priority", type=int, default=0,
                        help="SCHED_FIFO priority (1-98): hardware answers in microseconds whatever the CPU is doing")
    args = parser.parse_args(argv)
    if args.priority:
        try:
            os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(args.priority))
        except OSError as error:
            print(f"note: runs without real-time priority ({error.strerror})", file=sys.stderr)
    from hapticop.devices.ethercat.emulator.ropod_segment import RopodSegment
    from hapticop.devices.ethercat.emulator.server import FrameServer

    server = FrameServer(args.interface, RopodSegment(rng=np.random.default_rng(args.seed)), args.control, args.truth,
                         log=lambda message: print(message, file=sys.stderr, flush=True))

    def stop(*_):
        server.running = False

    signal.signal(signal.SIGTERM, stop)
    signal.signal(signal.SIGINT, stop)
    try:
        server.run()
    except OSError as error:
        print(f"error: {error}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
