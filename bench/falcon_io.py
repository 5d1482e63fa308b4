"""The Falcon's USB I/O loop against the virtual Falcon: frames per second and time per exchange.

    python bench/falcon_io.py [--seconds 5] [--write bench/results/falcon-io.md]

The real driver (`usb_driver.FalconUsb`) talks pyusb to the virtual backend, which models
the FT232R's latency timer in wall-clock time: a reply leaves the chip when the timer
expires (or 62 bytes wait). Runs:

- free-running at latency 1 ms and 16 ms: `exchange()` back to back, as libnifalcon's loop
  does; the rate the latency timer allows (§5 of docs/devices/falcon.md: ~1 kHz vs ~60 Hz);
- paced at 1 kHz by absolute sleeps, as the Falcon block runs on a 1 ms thread;
- host cost: the same exchanges under a virtual clock that never sleeps, so the time is the
  driver + pyusb + virtual device + simulated physics, with nothing waited for;
- the firmware load (probe, handshake, 4 kB upload at 142.9 kbaud, probe), in modelled time.

Everything beneath pyusb is a model; the figures say what the host side costs and that the
loop is timer-bound, not what a physical Falcon measures.
"""

from __future__ import annotations

import argparse
import os
import platform
import time
from pathlib import Path

import numpy as np

from hapticop.devices.falcon.codec import FrameCodec, Status, new_frame
from hapticop.devices.falcon.usb_driver import connect
from hapticop.devices.falcon.virtual_clock import VirtualClock, WallClock
from hapticop.devices.falcon.virtual_falcon import VirtualFalcon
from hapticop.devices.falcon.virtual_usb import VirtualUsbBackend
from hapticop.runtime.clock import RealtimeClock


def _loop(driver, device, seconds: float, period_ns: int | None) -> dict:
    codec, command, status = FrameCodec(), new_frame(), Status()
    codec.encode_command((100, -100, 50), 0, command)
    durations = np.zeros(int(seconds * 20_000) + 10, dtype=np.int64)
    clock = RealtimeClock()
    n = frames = missed = 0
    start = time.monotonic_ns()
    deadline = start
    cpu = time.thread_time_ns()
    physics = device.physics_ns
    while True:
        t0 = time.perf_counter_ns()
        frames += driver.exchange(command, status)
        durations[n] = time.perf_counter_ns() - t0
        n += 1
        now = time.monotonic_ns()
        if now - start >= seconds * 1e9 or n == len(durations):
            break
        if period_ns:  # like the runtime: an overrun skips the periods it covered
            deadline += period_ns
            if deadline < now:
                skipped = (now - deadline) // period_ns + 1
                missed += skipped
                deadline += skipped * period_ns
            clock.sleep_until(deadline)
    wall = (time.monotonic_ns() - start) / 1e9
    cpu_us = (time.thread_time_ns() - cpu) / 1e3 / n
    physics_us = (device.physics_ns - physics) / 1e3 / n
    us = durations[:n] / 1e3
    return {"exchanges": n, "frames_per_s": frames / wall, "p50": np.percentile(us, 50),
            "p99": np.percentile(us, 99), "max": us.max(), "cpu_us": cpu_us, "physics_us": physics_us,
            "resends": driver.resends, "missed": missed}


def _driver(clock, latency_ms: int):
    device = VirtualFalcon(clock, firmware_loaded=True)
    driver = connect(None, backend=VirtualUsbBackend(device))
    driver.set_latency(latency_ms)
    return driver, device


def _firmware_load_s() -> float:
    clock = VirtualClock()
    image = b"\xaa\x08" + bytes(i & 0xFF for i in range(4000))
    device = VirtualFalcon(clock)
    connect(image, backend=VirtualUsbBackend(device)).close()
    return clock.now()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--seconds", type=float, default=5.0, help="per run")
    parser.add_argument("--write", type=Path, help="also write the table as Markdown")
    args = parser.parse_args()
    rows = []
    for label, clock, latency, period in (
        ("free-running, latency timer 1 ms", WallClock(), 1, None),
        ("free-running, latency timer 16 ms", WallClock(), 16, None),
        ("paced at 1 kHz (absolute sleeps), latency 1 ms", WallClock(), 1, 1_000_000),
        ("host cost only (virtual clock, no waiting)", VirtualClock(), 1, None),
    ):
        driver, device = _driver(clock, latency)
        result = _loop(driver, device, args.seconds, period)
        driver.close()
        rows.append((label, result))
        print(f"{label:48s} {result['frames_per_s']:7.0f} frames/s  exchange p50 {result['p50']:7.1f} us  "
              f"p99 {result['p99']:7.1f} us  max {result['max']:8.1f} us  cpu {result['cpu_us']:6.1f} us/exchange "
              f"(of which simulated handle {result['physics_us']:5.1f} us)"
              + (f", {result['missed']} periods missed" if period else ""))
    load_s = _firmware_load_s()
    print(f"firmware load of a 4 kB test image, modelled time (probe + loader + probe): {load_s:.2f} s")
    if args.write:
        load = os.getloadavg()[0]
        lines = [f"Falcon USB I/O loop against the virtual Falcon ({platform.node()}, {os.cpu_count()} CPUs, "
                 f"load average {load:.1f} at the end, Python {platform.python_version()}, {args.seconds:g} s "
                 "per run; `python bench/falcon_io.py --write bench/results/falcon-io.md`).",
                 "Per exchange: one 64-byte read of the previous reply, one 16-byte write. Times in us.", "",
                 "| run | frames/s | exchange p50 | p99 | max | CPU per exchange | of which the simulated handle "
                 "| resends | missed periods |",
                 "|---|---|---|---|---|---|---|---|---|"]
        for label, r in rows:
            lines.append(f"| {label} | {r['frames_per_s']:.0f} | {r['p50']:.0f} | {r['p99']:.0f} | {r['max']:.0f} "
                         f"| {r['cpu_us']:.0f} | {r['physics_us']:.0f} | {r['resends']} "
                         f"| {r['missed'] if 'paced' in label else '-'} |")
        lines += ["", f"Firmware load of a 4 kB test image in modelled time (probe, handshake, upload at "
                      f"142.9 kbaud with a 16 ms latency timer, probe): {load_s:.2f} s."]
        args.write.write_text("\n".join(lines) + "\n")


if __name__ == "__main__":
    main()
