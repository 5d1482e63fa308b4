"""`hapticop compose` for a composition on several hosts: one side (`--host`), or every side here.

Each host runs a runtime of its own, so "every side here" is one `hapticop compose FILE --host H`
child per host, each in a run directory of its own under one parent. The simulated world and its
operator may sit on different hosts and find each other through the run directory's published facts
(`hapticop.published`), so the children share those. When one side ends, the others are given a
grace period to see it through their bridges and end too, then are interrupted; Ctrl+C interrupts all.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

FACT_KINDS = ("operators", "worlds", "links")  # what `hapticop.published` keeps under a run directory
GRACE_S = 10.0


def run_every_host(file: Path, hosts: list[str], parent: Path, passed: list[str]) -> int:
    """Run each host's side as a child beside the others; the worst exit status of them."""
    shared = parent / "facts"
    children: dict[str, subprocess.Popen] = {}
    for host in hosts:
        run_dir = parent / host
        run_dir.mkdir(mode=0o700, exist_ok=True)
        for kind in FACT_KINDS:
            (shared / kind).mkdir(parents=True, exist_ok=True)
            link = run_dir / kind
            if not link.exists():
                link.symlink_to(shared / kind, target_is_directory=True)
        children[host] = subprocess.Popen(
            [sys.executable, "-m", "hapticop.cli", "compose", str(file), "--host", host, "--run-dir", str(run_dir),
             *passed], start_new_session=True)

    def interrupt(*_: object) -> None:
        for child in children.values():
            if child.poll() is None:
                os.killpg(child.pid, signal.SIGINT)

    previous = {s: signal.signal(s, interrupt) for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        ended_at = None
        while any(child.poll() is None for child in children.values()):
            if ended_at is None and any(child.poll() is not None for child in children.values()):
                ended_at = time.monotonic()
            if ended_at is not None and time.monotonic() - ended_at > GRACE_S:
                interrupt()
                ended_at = float("inf")
            time.sleep(0.1)
    finally:
        for s, handler in previous.items():
            signal.signal(s, handler)
    return max(child.returncode for child in children.values())
