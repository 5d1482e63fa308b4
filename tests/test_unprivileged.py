"""A run by an ordinary user after root's: it works, in its own directories, and says in one
warning line which real-time settings it does not get.

CI runs as root, so the test's subprocess drops to `nobody` itself. The interpreter may live
where `nobody` cannot read (a root-only home), so the subprocess loads what the run needs and
starts the shared-memory tracker while still root, then drops its rights and runs the command.
Threads stay in the main process: a child process would have to start the interpreter again.
"""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import pytest

from .conftest import ROOT

NOBODY = 65534

COMPOSITION = """
version: 1
name: unprivileged
cpu_dma_latency: 0
threads:
  main: {period: 1ms, priority: 20, deploy: main, schedules: {0: [mediator, source]}}
  worker: {period: 2ms, priority: 10, cpus: [4095], schedules: {0: [sink]}}   # a CPU no machine here has
activities:
  mediator: {block: mediator}
  source: {block: echo, params: {dtype: float64}}
  sink: {block: echo, params: {dtype: float64}}
streams:
  values: {from: source.output, to: sink.input}
  back: {from: sink.output, to: source.input}
"""

AS_NOBODY = """
import os, sys
from io import StringIO
from multiprocessing import resource_tracker
from pathlib import Path

from rich.console import Console

from hapticop.cli import main
from hapticop.cli.report import print_results, print_timing
from hapticop.runtime.system import RunOptions, run_system
from hapticop.validation import validate_path

path, warm_up = sys.argv[1], sys.argv[2]
# Everything a run loads, loaded as root: a virtual-clock run of the same file, printed away.
result = run_system(validate_path(path), RunOptions(clock="virtual", duration_ns=10_000_000, run_dir=Path(warm_up),
                                                    echo=False))
print_timing(result.timing, Console(file=StringIO()), True)
print_results(result.outcome.run_dir, Console(file=StringIO()))
resource_tracker.ensure_running()
os.setgroups([])
os.setgid({nobody})
os.setuid({nobody})
os.environ.pop("XDG_RUNTIME_DIR", None)
sys.argv = ["hapticop", "compose", path, "--duration", "300ms"]
main()
""".replace("{nobody}", str(NOBODY))


@pytest.mark.skipif(os.geteuid() != 0, reason="needs root to become another user")
def test_an_ordinary_user_runs_after_root_with_one_warning_about_real_time():
    root_runs = Path("/dev/shm/hapticop-0") if Path("/dev/shm").is_dir() else Path("/tmp/hapticop-0")
    root_runs.mkdir(mode=0o700, exist_ok=True)  # as a run by root leaves it: the ordinary user cannot enter it
    place = Path(tempfile.mkdtemp(prefix="hapticop-unprivileged-"))
    run_dir = None
    theirs = [Path(f"/dev/shm/hapticop-{NOBODY}"), Path(f"/tmp/hapticop-{NOBODY}")]
    made = [path for path in theirs if not path.exists()]  # removed at the end: nobody ran here before
    try:
        os.chmod(place, 0o755)
        composition = place / "unprivileged.yaml"
        composition.write_text(COMPOSITION)
        os.chmod(composition, 0o644)
        done = subprocess.run([sys.executable, "-c", AS_NOBODY, str(composition), str(place / "warm-up")],
                              cwd=ROOT, capture_output=True, text=True, timeout=120)
        found = re.search(r"logs in (\S+)", done.stderr)
        run_dir = Path(found.group(1)) if found else None
        assert done.returncode == 0, done.stderr
        # The run's own lines (validation's own finding about CPU 4095 comes before the run).
        warnings = [line for line in done.stderr.splitlines() if line.startswith("[") and "warning" in line]
        assert len(warnings) == 1, done.stderr
        (warning,) = warnings
        assert warning.startswith("[system] warning: real time not available: SCHED_FIFO priorities"), warning
        assert "locked memory" in warning and "CPU affinity to CPUs 4095 (Invalid argument)" in warning
        assert "/dev/cpu_dma_latency" in warning
        assert "Traceback" not in done.stderr and "internal error" not in done.stderr
        assert run_dir is not None and run_dir.parent.name == f"hapticop-{NOBODY}", done.stderr
        info = run_dir.stat()
        assert info.st_uid == NOBODY and info.st_mode & 0o777 == 0o700
        assert all(p.stat().st_uid == NOBODY and p.stat().st_mode & 0o077 == 0 for p in run_dir.iterdir())
        sockets = Path(f"/tmp/hapticop-{NOBODY}")
        assert "control socket" in (run_dir / "system.log").read_text()
        assert sockets.stat().st_uid == NOBODY and sockets.stat().st_mode & 0o777 == 0o700
    finally:
        shutil.rmtree(place, ignore_errors=True)
        if run_dir is not None and run_dir.parent.name == f"hapticop-{NOBODY}":
            shutil.rmtree(run_dir, ignore_errors=True)
        for path in made:
            shutil.rmtree(path, ignore_errors=True)
