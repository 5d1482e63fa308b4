"""Hand micro-benchmark (not a test): microseconds to parse one 811-point scan, and per client poll.

    python bench/micro_sick.py [telegram.bin ...]

Without arguments it times a telegram the simulator builds (a room, 3-4 hex digits per value,
like the real captures); with files, it times those (e.g. tests/fixtures/sick/cola_a/*.bin).
Numbers depend on the machine; use them to compare changes, not as real-time claims.
"""

from __future__ import annotations

import statistics
import sys
import time
from pathlib import Path

import numpy as np

from hapticop.devices.sick import cola, scan
from hapticop.devices.sick.client import ColaClient
from hapticop.devices.sick.device_model import TiMDevice
from hapticop.devices.sick.simulator import TiMSimulator
from hapticop.testing import time_per_call


def _parse(name: str, telegram: bytes) -> None:
    body = cola.unframe(telegram)
    header = scan.parse_scan(body, None)
    count = header.dist.count
    ranges, angles = np.empty(count, np.float32), np.empty(count, np.float32)
    rssi = np.empty(header.rssi.count, np.uint16) if header.rssi else None
    for label, call in (
        ("ranges", lambda: scan.parse_scan(body, ranges)),
        ("ranges + angles", lambda: scan.parse_scan(body, ranges, angles)),
        ("ranges + angles + rssi", lambda: scan.parse_scan(body, ranges, angles, out_rssi=rssi)),
    ):
        if label.endswith("rssi") and rssi is None:
            continue
        median, p99 = time_per_call(call, 2000)
        print(f"parse_scan {name} ({count} points, {len(telegram)} B), {label:22s} "
              f"median {median:6.1f} µs  p99 {p99:6.1f} µs")


def _poll_costs(seconds: float = 2.0) -> None:
    """Client poll against the stepped simulator: idle polls and polls that parse a scan."""
    with TiMSimulator() as sim, ColaClient(sim.host, sim.port) as client:
        idle, busy = [], []
        for t in range(0, int(seconds * 1e9), 1_000_000):
            sim.step(t)
            scans = client.scans
            start = time.perf_counter_ns()
            client.poll(t)
            elapsed = (time.perf_counter_ns() - start) / 1e3
            if t > 200_000_000:  # after start-up
                (busy if client.scans > scans else idle).append(elapsed)
    print(f"ColaClient.poll: nothing to read median {statistics.median(idle):.1f} µs; "
          f"with a scan median {statistics.median(busy):.1f} µs, max {max(busy):.1f} µs ({len(busy)} scans)")


def main(paths: list[str]) -> None:
    if paths:
        for path in paths:
            _parse(Path(path).stem, Path(path).read_bytes())
    else:
        device = TiMDevice()
        device.advance(0)
        _parse("simulated", device.scan_telegram(1))
    _poll_costs()


if __name__ == "__main__":
    main(sys.argv[1:])
