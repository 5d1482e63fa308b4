"""What the ROS 2 bridge adds between a loop's step and a ROS 2 subscriber: the age on arrival of a stamped
Twist that a 1 kHz loop published, at the bridge's cycle and rate, over a Zenoh router on loopback.

    python bench/ros2_latency.py [--seconds 20] [--rate 50] [--period 5ms]

A client written with zenoh-ros2-sdk (tests/ros2_client.py, in a process of its own) publishes /cmd_in at
20 Hz; the composition's 1 kHz loop echoes each new sample, stamped at its step; the ROS 2 bridge sends the
newest as /cmd_stamped (TwistStamped, its header the sample's stamp on the wall clock) at `--rate`; the
client takes each one's age when its callback runs. A sample is sent again at every slot until a newer one
comes (a command is repeated, as ROS 2 bases expect): only its first arrival counts. The age holds the wait
for the bridge's next cycle and its next publication slot, the CDR encoding, Zenoh through the router, and
the client's decoding. Figures go to docs/ros2.md; none is judged here.
"""

from __future__ import annotations

import argparse
import json
import socket
import subprocess
import sys
import tempfile
import textwrap
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

SYSTEM = """
version: 1
name: ros2_latency
threads:
  main: {period: 1ms, deploy: main, schedules: {0: [mediator, echo]}}
  ros2: {period: PERIOD, deploy: process, schedules: {0: [ros2]}}
activities:
  mediator: {block: mediator}
  echo: {block: echo, params: {dtype: float64, shape: [3], unit: "m/s, m/s, rad/s"}}
  ros2:
    block: ros2_bridge
    params:
      mode: client
      connect: [tcp/127.0.0.1:PORT]
      subscribe:
        cmd_in: {topic: /cmd_in, type: geometry_msgs/msg/Twist}
      publish:
        stamped: {topic: /cmd_stamped, type: geometry_msgs/msg/TwistStamped, rate: RATEHz, stale: skip}
streams:
  cmd_in: {from: ros2.cmd_in, to: [echo.input], max_age: 200ms}
  cmd_out: {from: echo.output, to: [ros2.stamped], max_age: 200ms}
"""


def main() -> None:
    from hapticop.composition.units import parse_duration_ns
    from hapticop.network import transport
    from hapticop.runtime.system import RunOptions, run_system
    from hapticop.validation import validate_path

    parser = argparse.ArgumentParser()
    parser.add_argument("--seconds", type=float, default=20.0)
    parser.add_argument("--rate", type=float, default=50.0)
    parser.add_argument("--period", default="5ms")
    args = parser.parse_args()
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    hub = transport.session([f"tcp/127.0.0.1:{port}"], [], mode="router")
    client = subprocess.Popen([sys.executable, str(ROOT / "tests" / "ros2_client.py"), str(port), "latency"],
                              stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
    try:
        with tempfile.TemporaryDirectory() as tmp:
            path = Path(tmp) / "ros2_latency.yaml"
            path.write_text(textwrap.dedent(SYSTEM.replace("PORT", str(port)).replace("RATE", f"{args.rate:g}")
                                            .replace("PERIOD", args.period)))
            validated = validate_path(path)
            assert validated.report.ok, [d.to_text() for d in validated.report.diagnostics]
            started = time.monotonic()
            run_system(validated, RunOptions(clock="realtime", duration_ns=parse_duration_ns(f"{args.seconds}s"),
                                             run_dir=Path(tmp) / "run", echo=False))
            elapsed = time.monotonic() - started
    finally:
        client.kill()
        out = client.communicate()[0]
        hub.close()
    first: dict[int, float] = {}  # a sample is sent again at every slot until a newer one: its first arrival
    for line in out.splitlines():
        if '"age_ms"' in line:
            seen = json.loads(line)
            first.setdefault(seen["stamp"], seen["age_ms"])
    ages = np.array(list(first.values()))
    ages = ages[len(ages) // 10:]  # the first tenth: start-up
    figures = {"samples": int(ages.size), "p50_ms": round(float(np.percentile(ages, 50)), 3),
               "p99_ms": round(float(np.percentile(ages, 99)), 3), "max_ms": round(float(ages.max()), 3),
               "rate_hz": args.rate, "bridge_period": args.period, "run_s": round(elapsed, 1)}
    print(json.dumps(figures))


if __name__ == "__main__":
    main()
