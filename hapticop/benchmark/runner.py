"""A bench: the composition idle, then under load, each beside cyclictest, `repeat` times.

The composition runs in its own `hapticop compose` process (as a user would run it) and
leaves timing.json in its run directory; cyclictest runs at the same time, above every
thread of the composition, for the machine's own limit under the same conditions. Each
round also measures the framework's per-cycle work and the virtual clock's speed, which
need no real-time conditions. Repeating gives the spread a noisy machine puts on every figure.
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
    round: int = 1


@dataclass
class BenchRun:
    file: str
    seconds: float
    machine: dict
    conditions: list[Condition] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)
    overhead: list[dict] = field(default_factory=list)  # per round: hapticop.benchmark.overhead.measure
    virtual_speed: list[float] = field(default_factory=list)  # per round: simulated s per wall s
    repeat: int = 1


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


VIRTUAL_S = 10.0
"""Simulated seconds of the virtual-clock speed measure."""


def virtual_speed(file: str, seconds: float = VIRTUAL_S) -> float:
    """Simulated seconds per second of this process's CPU time of `file` on the virtual clock (set-up
    included): the wall time on a quiet machine, and what a busy one does not stretch."""
    import tempfile

    from hapticop.runtime.system import RunOptions, run_system
    from hapticop.validation import validate_path

    validated = validate_path(Path(file))
    with tempfile.TemporaryDirectory() as run_dir:
        options = RunOptions(clock="virtual", duration_ns=int(seconds * 1e9), run_dir=Path(run_dir), echo=False)
        started = time.process_time()
        run_system(validated, options)
        return seconds / (time.process_time() - started)


def run(file: str, seconds: float, out: Path, conditions: tuple[str, ...] = ("idle", "loaded"),
        say=print, repeat: int = 1) -> BenchRun:
    from hapticop.benchmark.overhead import measure

    bench = BenchRun(file, seconds, machine(), repeat=repeat)
    if not cyclictest.available():
        bench.notes.append("cyclictest is not installed (Debian: apt-get install rt-tests): no machine baseline")
    if not bench.machine["root"]:
        bench.notes.append("not root: SCHED_FIFO, mlockall and /dev/cpu_dma_latency were refused, so these "
                           "figures are for normal scheduling")
    for round_ in range(1, repeat + 1):
        say(f"round {round_}/{repeat}: the framework's per-cycle work and the virtual clock's speed")
        bench.overhead.append(measure(Path(file)))
        bench.virtual_speed.append(virtual_speed(file))
        for name in conditions:
            say(f"round {round_}/{repeat}, {name}: {file} for {seconds:g} s"
                + (" beside cyclictest" if cyclictest.available() else ""))
            run_dir = out / (f"run-{name}" if repeat == 1 else f"run-{round_}-{name}")
            with Load(seconds + STARTUP_S + 5) if name == "loaded" else nullcontext():
                beside = cyclictest.Cyclictest(seconds + STARTUP_S / 2) if cyclictest.available() else None
                timing, code = compose(file, seconds, run_dir)
                baseline = beside.result() if beside else None
            bench.conditions.append(Condition(name, timing, baseline, code, run_dir, round_))
    return bench
