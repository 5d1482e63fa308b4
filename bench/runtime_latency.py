"""Benchmark: how well hapticop's threads keep a 1 kHz cycle, beside cyclictest.

Two 1 kHz threads (SCHED_FIFO 40 and 39) and a 15 Hz thread, first all in the main
process, then with the second 1 kHz thread in its own process; each idle and with both
cores loaded by stress-ng; cyclictest (SCHED_FIFO 80, mlockall, 1 kHz) runs in the same
script for the machine's own limit. Run as root; needs rt-tests and stress-ng (Debian).

    python bench/runtime_latency.py --seconds 60 --out bench/results/runtime-latency.md
"""

from __future__ import annotations

import argparse
import json
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from hapticop.benchmark.cyclictest import parse as parse_cyclictest

COMPOSITION = """\
version: 1
name: bench_{deploy}
threads:
  main:
    period: 1ms
    priority: 40
    deploy: main
    schedules: {{0: [mediator, source]}}
  fieldbus:
    period: 1ms
    priority: 39
    deploy: {deploy}
    schedules: {{0: [relay]}}
  scanner:
    period: 15Hz
    schedules: {{0: [sink]}}
activities:
  mediator: {{block: mediator}}
  source: {{block: counter}}
  relay: {{block: echo}}
  sink: {{block: echo}}
streams:
  count: {{from: source.count, to: relay.input}}
  relayed: {{from: relay.output, to: sink.input}}
"""


def cyclictest(seconds: int) -> dict:
    out = subprocess.run(["cyclictest", "-m", "-p", "80", "-i", "1000", "-l", str(seconds * 1000), "-q", "-h", "20000"],
                         capture_output=True, text=True, check=True).stdout
    distribution = parse_cyclictest(out)
    return {**distribution.summary(), "cycles": distribution.count, "missed": None}


def hapticop(deploy: str, seconds: int, work: Path) -> dict:
    path = work / f"bench-{deploy}.yaml"
    path.write_text(COMPOSITION.format(deploy=deploy))
    run_dir = work / f"run-{deploy}-{time.time_ns()}"
    subprocess.run([sys.executable, "-m", "hapticop.cli", "compose", str(path), "--duration", f"{seconds}s",
                    "--run-dir", str(run_dir)], check=True, capture_output=True)
    return json.loads((run_dir / "timing.json").read_text())


class Load:
    def __init__(self, enabled: bool, seconds: int):
        self.enabled, self.seconds, self.process = enabled, seconds, None

    def __enter__(self):
        if self.enabled:
            self.process = subprocess.Popen(["stress-ng", "--cpu", "2", "--timeout", f"{self.seconds}s", "--quiet"])
            time.sleep(1)
        return self

    def __exit__(self, *exc):
        if self.process:
            self.process.terminate()
            self.process.wait()


def row(label: str, t: dict) -> str:
    lat = t.get("wakeup_latency_us", t)
    cycles = t.get("cycles", 0)
    missed = t.get("missed_deadlines")
    miss = "-" if missed is None else f"{missed} ({100 * missed / max(1, cycles + missed):.3f} %)"
    return f"| {label} | {lat['p50']:.0f} | {lat['p99']:.0f} | {lat['p99.9']:.0f} | {lat['max']:.0f} | {miss} |"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--seconds", type=int, default=60)
    parser.add_argument("--out", type=Path)
    args = parser.parse_args()
    for tool in ("cyclictest", "stress-ng"):
        if not shutil.which(tool):
            sys.exit(f"{tool} is missing: apt-get install rt-tests stress-ng")
    lines = [f"{args.seconds} s per run, 1 kHz, wake-up latency in us.", "",
             "| run | p50 | p99 | p99.9 | max | missed deadlines |", "|---|---|---|---|---|---|"]
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        for loaded in (False, True):
            condition = "loaded" if loaded else "idle"
            with Load(loaded, args.seconds * 3 + 30):
                lines.append(row(f"cyclictest, {condition}", cyclictest(args.seconds)))
                for deploy in ("thread", "process"):
                    data = hapticop(deploy, args.seconds, work)
                    layout = "one process" if deploy == "thread" else "fieldbus in its own process"
                    for thread in ("main", "fieldbus", "scanner"):
                        lines.append(row(f"hapticop {thread} [{layout}], {condition}", data["threads"][thread]))
            print("\n".join(lines), flush=True)
    text = "\n".join(lines) + "\n"
    if args.out:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text(text)
    print(text)


if __name__ == "__main__":
    main()
