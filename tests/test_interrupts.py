"""Ctrl+C at any moment of `hapticop compose`: no traceback, no leaked shared memory, no process
left, exit status 130.

Ctrl+C in a terminal reaches the whole foreground process group, children included, so each
run gets a session of its own and the signal goes to that group. The moments are found by
what the run shows (a module loaded, a line logged), never by how long it has been.
"""

from __future__ import annotations

import json
import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def _loading(process: subprocess.Popen, _run_dir: Path, _stderr: Path) -> bool:
    """numpy's core is mapped: the command's modules are being loaded (it is not yet validating)."""
    try:
        return "_multiarray_umath" in Path(f"/proc/{process.pid}/maps").read_text()
    except OSError:
        return False


def _spawning(_process, run_dir: Path, _stderr: Path) -> bool:
    """The first thread's own process is started; others may still be on their way."""
    log = run_dir / "system.log"
    return log.exists() and "runs in process" in log.read_text()


def _connecting(_process, _run_dir: Path, stderr: Path) -> bool:
    """The run has started: the mediator is starting threads and devices are connecting."""
    return "running (realtime clock)" in stderr.read_text()


def _interrupt(tmp_path: Path, moment, presses: int) -> tuple[int, str, list[str], list[int]]:
    run_dir, stderr = tmp_path / "run", tmp_path / "stderr"
    with open(stderr, "w") as err:
        process = subprocess.Popen(
            [sys.executable, "-m", "hapticop.cli", "compose", "systems/hallway.yaml", "--duration", "60s",
             "--run-dir", str(run_dir), "--control", str(tmp_path / "control.sock")],
            cwd=ROOT, stdout=subprocess.DEVNULL, stderr=err, start_new_session=True)
        try:
            while not moment(process, run_dir, stderr):
                assert process.poll() is None, stderr.read_text()
                time.sleep(0.005)
            for _ in range(presses):
                os.killpg(process.pid, signal.SIGINT)
            status = process.wait(timeout=120)
        finally:
            if process.poll() is None:
                os.killpg(process.pid, signal.SIGKILL)
                process.wait()
    log = (run_dir / "system.log").read_text() if (run_dir / "system.log").exists() else ""
    segments = re.findall(r"shared memory (\S+),", log)
    children = [int(pid) for pid in re.findall(r"runs in process (\d+)", log)]
    return status, stderr.read_text(), segments, children


def _alive(pid: int) -> bool:
    try:
        return "multiprocessing" in Path(f"/proc/{pid}/cmdline").read_text()
    except OSError:
        return False


@pytest.mark.parametrize(("moment", "presses"), [
    (_loading, 1), (_spawning, 1), (_connecting, 1), (_spawning, 2), (_connecting, 2),
], ids=["loading", "spawning", "connecting", "spawning-twice", "connecting-twice"])
def test_ctrl_c_leaves_cleanly_at_every_moment_of_start_up(tmp_path, moment, presses):
    status, stderr, segments, children = _interrupt(tmp_path, moment, presses)
    assert status == 130, stderr
    assert "Traceback" not in stderr and "leaked" not in stderr, stderr
    if moment is not _loading:
        assert segments, "the run logs the name of its shared memory"
    assert not [name for name in segments if Path("/dev/shm", name).exists()]
    assert not [pid for pid in children if _alive(pid)]
    assert not (tmp_path / "control.sock").exists()
    timing = tmp_path / "run" / "timing.json"
    if timing.exists():  # the figures end where the stop was asked, even when the threads ran after it
        for name, thread in json.loads(timing.read_text())["threads"].items():
            assert thread["cycles"] >= 0 and thread["missed_deadlines"] >= 0, (name, thread)


def test_a_command_started_with_ctrl_c_ignored_takes_it_from_the_start():
    """A shell's background job inherits Ctrl+C ignored; a run takes it once it runs, so the command
    must take it before as well (ignored until then, one sent while the run's processes started was lost)."""
    probe = "import signal, hapticop.cli; print(signal.getsignal(signal.SIGINT) is signal.default_int_handler)"
    done = subprocess.run([sys.executable, "-c", probe], cwd=ROOT, capture_output=True, text=True, timeout=120,
                          preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_IGN))
    assert done.stdout.strip() == "True", done.stderr


def test_importing_the_simulation_starts_no_process():
    """MuJoCo's GL backend would import GLFW, which starts a Python process to probe its library: a child
    that Ctrl+C at start-up interrupts mid-reply (the traceback the test above looks for, 1 run in 10-25
    on a busy machine). The simulation imports MuJoCo without a GL backend, and its children inherit that."""
    probe = ("import os, sys; import hapticop.sim.engine, hapticop.sim.scene_files; "
             "print('glfw' in sys.modules, os.environ.get('MUJOCO_GL'))")
    env = {k: v for k, v in os.environ.items() if k != "MUJOCO_GL"}
    done = subprocess.run([sys.executable, "-c", probe], cwd=ROOT, capture_output=True, text=True, timeout=120, env=env)
    assert done.stdout.split() == ["False", "disable"], done.stderr
