"""One bench run: the composition idle, then under load, each beside cyclictest.

The composition runs in its own `hapticop compose` process (as a user would run it) and
leaves timing.json in its run directory; cyclictest runs at the same time, above every
thread of the composition, for the machine's own limit under the same conditions.
"""

from __future__ import annotations

import json
import platform
import shutil
import subprocess
import sys
import time
from contextlib import nullcontext
from dataclasses import dataclass, field
from pathlib import Path

from hapticop.benchmark import cyclictest
from hapticop.benchmark.load import Load
from hapticop.benchmark.stats import Distribution

STARTUP_S = 10.0
"""Allowance for processes to start before the composition's own duration begins."""


@dataclass
class Condition:
    name: str  # "idle" or "loaded"
    timing: dict
    baseline: Distribution | None
    returncode: int
    run_dir: Path


@dataclass
class BenchRun:
    file: str
    seconds: float
    machine: dict
    conditions: list[Condition] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)


def machine() -> dict:
    import os

    return {"host": platform.node(), "kernel": platform.release(), "cpus": os.cpu_count(),
            "python": platform.python_version(), "date": time.strftime("%Y-%m-%d %H:%M:%S %Z"),
            "root": os.geteuid() == 0 if hasattr(os, "geteuid") else False}


def compose(file: str, seconds: float, run_dir: Path) -> tuple[dict, int]:
    if run_dir.exists():  # the bench's own directory from an earlier run: its logs would append to it
        shutil.rmtree(run_dir)
    command = [sys.executable, "-m", "hapticop.cli", "compose", file, "--duration", f"{seconds:g}s",
               "--run-dir", str(run_dir)]
    done = subprocess.run(command, capture_output=True, text=True)
    timing_file = run_dir / "timing.json"
    if not timing_file.exists():
        raise RuntimeError(f"'{' '.join(command)}' left no timing.json (exit {done.returncode}): "
                           f"{done.stderr.strip()[-500:]}")
    return json.loads(timing_file.read_text()), done.returncode


def run(file: str, seconds: float, out: Path, conditions: tuple[str, ...] = ("idle", "loaded"),
        say=print) -> BenchRun:
    bench = BenchRun(file, seconds, machine())
    if not cyclictest.available():
        bench.notes.append("cyclictest is not installed (Debian: apt-get install rt-tests): no machine baseline")
    if not bench.machine["root"]:
        bench.notes.append("not root: SCHED_FIFO, mlockall and /dev/cpu_dma_latency were refused, so these "
                           "figures are for normal scheduling")
    for name in conditions:
        say(f"{name}: {file} for {seconds:g} s" + (" beside cyclictest" if cyclictest.available() else ""))
        with Load(seconds + STARTUP_S + 5) if name == "loaded" else nullcontext():
            beside = cyclictest.Cyclictest(seconds + STARTUP_S / 2) if cyclictest.available() else None
            timing, code = compose(file, seconds, out / f"run-{name}")
            baseline = beside.result() if beside else None
        bench.conditions.append(Condition(name, timing, baseline, code, out / f"run-{name}"))
    return bench
