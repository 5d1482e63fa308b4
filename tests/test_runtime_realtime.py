"""The runtime on the wall clock: threads, processes, signals, a process killed from outside.

These runs are short and assert behaviour, never timing.
"""

import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest

from hapticop.composition.lcsm import State
from hapticop.runtime.system import ExitStatus

from .conftest import ROOT
from .runtime_helpers import COUNTER, IGNORES_SHUTDOWN, PATIENCE_S, compose, counting, pipeline, run_until, steps


def test_threads_in_the_main_process(tmp_path):
    result = run_until(tmp_path, pipeline("thread"),
                       lambda system: getattr(system.runners["recorder"].block, "n", 0) > 10,
                       "the recorder recorded 10 samples")
    assert result.outcome.status is ExitStatus.SUCCESS, result.outcome.reasons
    assert all(state is State.DONE for state in result.states.values())
    samples = np.load(tmp_path / "run-c" / "recorder.npz")["samples"]
    assert len(samples) > 10


def test_a_thread_in_its_own_process_shares_the_same_streams(tmp_path):
    result = run_until(tmp_path, pipeline("process"),
                       lambda system: system.state("recorder") is State.RUNNING and steps(system, "recorder") > 20,
                       "the recorder, in its own process, stepped 20 times while running")
    assert result.outcome.status is ExitStatus.SUCCESS, result.outcome.reasons
    assert result.states["threads.slow"] is State.DONE and result.states["recorder"] is State.DONE
    data = np.load(tmp_path / "run-c" / "recorder.npz")
    assert len(data["samples"]) > 10
    assert np.all(np.diff(data["stamps"]) > 0)  # every sample new, in order, across processes


def test_a_killed_process_is_detected_and_reported(tmp_path):
    def kill_when_running(system):
        def killer():
            deadline = time.monotonic() + 20
            while time.monotonic() < deadline:
                handle = system.scheduler.processes.get("slow")
                if handle and system.state("recorder") is State.RUNNING:
                    os.kill(handle.process.pid, signal.SIGKILL)
                    return
                time.sleep(0.01)
        threading.Thread(target=killer, daemon=True).start()

    result = compose(tmp_path, pipeline("process"), clock="realtime", duration="3s", on_start=kill_when_running)
    assert result.outcome.status is ExitStatus.FAILURE
    assert any("thread 'slow' was lost" in r and "exit code -9" in r for r in result.outcome.reasons)
    assert "threads.slow.lost" in result.flags
    assert result.states["threads.main"] is State.DONE  # the rest still shut down cleanly


def _compose_process(tmp_path, text, ready: str | None = "noise"):
    """`hapticop compose` in a process of its own, returned once activity `ready` runs."""
    path = tmp_path / "c.yaml"
    path.write_text(text)
    run_dir = tmp_path / "run"
    process = subprocess.Popen([sys.executable, "-m", "hapticop.cli", "compose", str(path), "--run-dir", str(run_dir)],
                               cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    log = run_dir / f"{ready}.log"
    deadline = time.monotonic() + 30
    while ready and time.monotonic() < deadline and not (log.exists() and "-> running" in log.read_text()):
        time.sleep(0.02)
    return process


SIMPLE = counting()


def test_a_runs_timing_ends_where_the_run_starts_ending_and_counts_the_shutdown_apart(tmp_path):
    """A cleaning hook that holds the main loop for 0.3 s makes it overrun about 300 periods while the run
    ends: they are the shutdown's, reported as such, not the run's missed deadlines or wake-up latencies."""
    text = COUNTER.replace("schedules: {0: [mediator, counter]}", "schedules: {0: [mediator, counter, slow]}")
    text += '  slow: {block: "tests.blocks:SlowClean", params: {clean_s: 0.3}}\n'
    result = run_until(tmp_path, text, lambda system: steps(system, "counter") > 50, "the counter stepped 50 times")
    assert result.outcome.status is ExitStatus.SUCCESS, result.outcome.reasons
    main = result.timing["threads"]["main"]
    assert main["missed_while_ending"] >= 290  # 0.3 s of 1 ms periods, overrun while cleaning
    assert main["missed_deadlines"] < 290 and main["cycle_us"]["max"] < 290_000, main  # none of it in the run's
    assert result.timing["activities"]["counter"]["steps"] > 50
    assert "timing is counted up to here" in (tmp_path / "run-c" / "system.log").read_text()


def test_ctrl_c_shuts_down_and_reports_interruption(tmp_path):
    process = _compose_process(tmp_path, SIMPLE)
    process.send_signal(signal.SIGINT)
    out, err = process.communicate(timeout=30)
    assert process.returncode == 130, err
    assert "exit: interrupted (130)" in err and "wake p50" in err and "Traceback" not in err


def test_sigterm_reports_termination(tmp_path):
    process = _compose_process(tmp_path, SIMPLE)
    process.send_signal(signal.SIGTERM)
    _, err = process.communicate(timeout=30)
    assert process.returncode == 143, err


def test_a_second_ctrl_c_leaves_at_once(tmp_path):
    """The nets never finish this shutdown; the second Ctrl+C does not wait for them."""
    process = _compose_process(tmp_path, SIMPLE + IGNORES_SHUTDOWN)
    process.send_signal(signal.SIGINT)
    time.sleep(0.5)
    process.send_signal(signal.SIGINT)
    _, err = process.communicate(timeout=30)
    assert process.returncode == 130, err
    assert "left at once" in err and "Traceback" not in err


SHARED = """
version: 1
name: shared
threads:
  main:
    period: 1ms
    deploy: main
    schedules: {0: [mediator, source]}
  fieldbus:
    period: 1ms
    deploy: process
    process: bus
    schedules: {0: [relay]}
  watchdog:
    period: 2ms
    deploy: process
    process: bus
    schedules: {0: [sink]}
activities:
  mediator: {block: mediator}
  source: {block: counter}
  relay: {block: echo}
  sink: {block: echo}
streams:
  count: {from: source.count, to: relay.input}
  relayed: {from: relay.output, to: sink.input}
"""


def test_threads_naming_one_process_share_it(tmp_path):
    result = compose(tmp_path, SHARED, clock="realtime", duration="1s", name="shared")
    assert result.outcome.status is ExitStatus.SUCCESS, result.outcome.reasons
    log = (tmp_path / "run-shared" / "system.log").read_text()
    pids = {line.rsplit(" ", 1)[1] for line in log.splitlines() if "runs in process" in line}
    assert len(pids) == 1  # one process for both
    assert result.timing["activities"]["relay"]["steps"] > 0 and result.timing["activities"]["sink"]["steps"] > 0
    assert all(result.states[f"threads.{t}"] is State.DONE for t in ("fieldbus", "watchdog"))


def test_a_named_process_needs_deploy_process():
    from hapticop.validation import validate_text

    report = validate_text(SHARED.replace("    deploy: process\n    process: bus\n    schedules: {0: [relay]}",
                                          "    process: bus\n    schedules: {0: [relay]}"), "s.yaml").report
    [error] = report.errors
    assert error.path == ("threads", "fieldbus", "process") and "needs 'deploy: process'" in error.message


DATA_WOKEN = """
version: 1
name: woken
threads:
  main: {period: 1ms, deploy: main, schedules: {0: [mediator]}}
  device: {period: 250ms, WAKE schedules: {0: [pingpong]}}
activities:
  mediator: {block: mediator}
  pingpong: {block: "tests.blocks:PingPong"}
"""


def test_a_data_woken_thread_cycles_when_its_device_sends(tmp_path):
    """Woken by its device, the 250 ms thread answers 200 round trips, which its deadlines alone
    would take 50 s to allow (longer than the run may wait for them)."""
    result = run_until(tmp_path, DATA_WOKEN.replace("WAKE", "wake: data,"),
                       lambda system: getattr(system.runners["pingpong"].block, "round_trips", 0) >= 200,
                       "200 round trips with the device")
    assert result.outcome.status is ExitStatus.SUCCESS, result.outcome.reasons
    assert int((tmp_path / "run-c" / "pingpong.round_trips").read_text()) >= 200


def test_a_deadline_woken_thread_answers_its_device_once_a_cycle(tmp_path):
    """Woken by its deadlines only, the thread answers at most once per cycle, however eagerly
    its device sends: the round trips are counted against the thread's own cycles."""
    result = run_until(tmp_path, DATA_WOKEN.replace("WAKE", "wake: deadline,"),
                       lambda system: getattr(system.runners["pingpong"].block, "round_trips", 0) >= 3,
                       "3 round trips with the device")
    round_trips = int((tmp_path / "run-c" / "pingpong.round_trips").read_text())
    device = result.timing["threads"]["device"]
    assert 3 <= round_trips <= device["cycles"]
    # and the thread cycled on its deadlines: no more cycles than the main loop's periods allow
    main = result.timing["threads"]["main"]
    assert device["cycles"] <= (main["cycles"] + main["missed_deadlines"]) // 250 + 2


def test_the_hallway_in_real_time_scans_from_a_simulation_process_and_leaves_nothing_behind(tmp_path):
    """The simulated scanner on the simulation thread, in a process of its own outside the
    real-time loops, scans for the LIDAR thread in another; all of it gone after the run."""
    import re

    text = (ROOT / "systems" / "hallway.yaml").read_text()
    run = tmp_path / "run-hallway"
    result = run_until(tmp_path, text, lambda system: (
        "LIDAR streaming" in _read(run / "lidar.log") and system.state("haptic") is State.RUNNING
        and steps(system, "lidar") > 5 and steps(system, "lidar_sim") > 5),
        "the LIDAR streams scans from the simulated scanner and the haptic controller runs", name="hallway",
        shutdown_timeout=f"{PATIENCE_S:g}s")  # the world judges and draws the run as it cleans, in its own process
    assert result.outcome.status is ExitStatus.SUCCESS, result.outcome.reasons
    assert result.timing["activities"]["lidar"]["steps"] > 5
    assert result.timing["activities"]["lidar_sim"]["steps"] > 5
    assert result.timing["activities"]["haptic"]["steps"] > 0
    pids = {thread: int(re.search(r"loop ended after \d+ cycles \(pid (\d+)\)",
                                  (run / f"thread-{thread}.log").read_text()).group(1))
            for thread in ("simulation", "lidar")}
    assert len({os.getpid(), *pids.values()}) == 3  # neither in the main process, nor together
    assert "lcsm cleaning -> done" in (run / "lidar_sim.log").read_text()
    assert not list((run / "links").glob("*")) and not list((run / "worlds").glob("*"))  # withdrawn
    assert not list(Path("/dev/shm").glob(f"hapticop-scene-{os.getpid()}-*"))


def _children(pid: int) -> list[int]:
    found = []
    for entry in os.listdir("/proc"):
        if entry.isdigit():
            try:
                with open(f"/proc/{entry}/stat") as stat:
                    fields = stat.read().rsplit(")", 1)[1].split()
            except OSError:
                continue
            if int(fields[1]) == pid:
                found.append(int(entry))
    return found


def _alive(pid: int) -> bool:
    try:
        with open(f"/proc/{pid}/stat") as stat:
            return stat.read().rsplit(")", 1)[1].split()[0] != "Z"
    except OSError:
        return False


def test_when_the_main_process_is_killed_its_children_clean_and_leave(tmp_path):
    """SIGKILL leaves the main process no chance to shut down: its children notice, clean their
    activities (a device block would bring its device to a safe state; here the recorder saves
    what it recorded) and end, and the shared memory goes with them."""
    process = _compose_process(tmp_path, pipeline("process"))
    run = tmp_path / "run"
    deadline = time.monotonic() + 30
    while time.monotonic() < deadline and "-> running" not in _read(run / "recorder.log"):
        time.sleep(0.02)
    children = [pid for pid in _children(process.pid) if "process_main" in _cmdline(pid) or _is_spawned(pid)]
    assert children, "the slow thread's process was not found"
    shared = _shared_memory(process.pid)  # this run's own segments, not whatever else runs on the machine
    assert shared, "the run maps no shared memory"
    process.kill()
    process.wait(timeout=10)
    deadline = time.monotonic() + 10
    while time.monotonic() < deadline and any(_alive(pid) for pid in children):
        time.sleep(0.02)
    assert not any(_alive(pid) for pid in children), "a child outlived its parent"
    assert (run / "recorder.npz").exists()  # the recorder's clean hook ran: its activity was cleaned
    deadline = time.monotonic() + 10
    while time.monotonic() < deadline and any(path.exists() for path in shared):
        time.sleep(0.05)
    assert not [path for path in shared if path.exists()]


def _shared_memory(pid: int) -> set[Path]:
    """The /dev/shm files process `pid` maps."""
    with open(f"/proc/{pid}/maps") as maps:
        return {Path(line.split(None, 5)[5].strip()) for line in maps
                if len(line.split(None, 5)) == 6 and line.split(None, 5)[5].startswith("/dev/shm/")}


def _read(path) -> str:
    try:
        return path.read_text()
    except OSError:
        return ""


def _cmdline(pid: int) -> str:
    try:
        with open(f"/proc/{pid}/cmdline", "rb") as cmdline:
            return cmdline.read().replace(b"\0", b" ").decode(errors="replace")
    except OSError:
        return ""


def _is_spawned(pid: int) -> bool:
    """A multiprocessing 'spawn' child (not its resource tracker, which must outlive it)."""
    line = _cmdline(pid)
    return "multiprocessing.spawn" in line and "resource_tracker" not in line


REALTIME = """
version: 1
name: realtime
threads:
  main: {period: 1ms, deploy: main, priority: 20, cpus: [FIRST], schedules: {0: [mediator, source, main_probe]}}
  bus: {period: 2ms, deploy: process, priority: 21, cpus: [LAST], schedules: {0: [relay, bus_probe]}}
  slow: {period: 10ms, deploy: thread, schedules: {0: [sink]}}
activities:
  mediator: {block: mediator}
  source: {block: counter}
  relay: {block: echo}
  sink: {block: echo}
  main_probe: {block: "tests.blocks:WhatItRunsWith"}
  bus_probe: {block: "tests.blocks:WhatItRunsWith"}
streams:
  count: {from: source.count, to: relay.input}
  relayed: {from: relay.output, to: sink.input}
"""


def _fifo_refused() -> str | None:
    """Why this machine will not let a thread use SCHED_FIFO, or None (tried on a thread of our own)."""
    if os.geteuid() != 0:
        return "real-time scheduling needs root (or CAP_SYS_NICE and CAP_IPC_LOCK)"
    refused: list[str] = []

    def attempt() -> None:
        try:
            os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(1))
            os.sched_setscheduler(0, os.SCHED_OTHER, os.sched_param(0))
        except OSError as error:
            refused.append(f"the kernel refuses SCHED_FIFO here: {error.strerror}")

    thread = threading.Thread(target=attempt)
    thread.start()
    thread.join()
    return refused[0] if refused else None


def _status(pid: int, field: str) -> int:
    for line in open(f"/proc/{pid}/status").read().splitlines():
        if line.startswith(f"{field}:"):
            return int(line.split()[1])
    raise AssertionError(f"no {field} in /proc/{pid}/status")


def test_real_time_threads_get_their_policy_priority_cpus_locked_memory_and_frozen_gc(tmp_path):
    """What the composition asks for is what the kernel gives each thread: SCHED_FIFO at its
    priority on its CPUs, memory locked in every process with a real-time thread, the garbage
    collector's furniture frozen once running; a thread without a priority keeps normal scheduling."""
    if reason := _fifo_refused():
        pytest.skip(reason)
    cpus = sorted(os.sched_getaffinity(0))
    text = REALTIME.replace("FIRST", str(cpus[0])).replace("LAST", str(cpus[-1]))
    process = _compose_process(tmp_path, text, ready=None)
    run = tmp_path / "run"
    try:
        deadline = time.monotonic() + 30
        while not all((run / f"{p}.runs").exists() for p in ("main_probe", "bus_probe")):
            assert process.poll() is None, process.communicate()[1][-3000:]
            assert time.monotonic() < deadline, "the probes never ran"
            time.sleep(0.02)
        told = {p: [int(n) for n in (run / f"{p}.runs").read_text().split()] for p in ("main_probe", "bus_probe")}
        (main_pid, main_tid, main_frozen), (bus_pid, bus_tid, bus_frozen) = told["main_probe"], told["bus_probe"]
        assert main_pid == main_tid == process.pid  # deploy: main is the main process's own thread
        assert bus_pid != process.pid and bus_pid in _children(process.pid)
        for pid, tid, priority, cpu in ((main_pid, main_tid, 20, cpus[0]), (bus_pid, bus_tid, 21, cpus[-1])):
            assert os.sched_getscheduler(tid) == os.SCHED_FIFO
            assert os.sched_getparam(tid).sched_priority == priority
            assert os.sched_getaffinity(tid) == {cpu}
            assert _status(pid, "VmLck") > 0  # mlockall(MCL_CURRENT | MCL_FUTURE) took
            # every other thread ('slow', the control socket's, the log writer's) runs as it asked: normally,
            # anywhere, even those a real-time thread started (they would inherit its policy and CPUs)
            others = [int(t) for t in os.listdir(f"/proc/{pid}/task") if int(t) != tid]
            borrowed = {t: (os.sched_getscheduler(t), os.sched_getaffinity(t)) for t in others if _alive(t)}
            assert all(s == (os.SCHED_OTHER, set(cpus)) for s in borrowed.values()), (pid, tid, borrowed)
        assert main_frozen > 0 and bus_frozen > 0  # gc.freeze() ran in each process before its activities ran
    finally:
        process.send_signal(signal.SIGINT)
        try:
            _, err = process.communicate(timeout=30)
        except subprocess.TimeoutExpired:
            process.kill()
            _, err = process.communicate()
    assert process.returncode == 130, err[-3000:]
    said = err + "".join(log.read_text() for log in run.glob("*.log"))
    assert "SCHED_FIFO priority 21" in said
    assert not [w for w in ("cannot use SCHED_FIFO", "cannot lock memory", "cannot set CPU") if w in said]


def test_a_run_in_process_gives_its_callers_thread_back_as_it_was(tmp_path):
    """A system run in-process makes the calling thread its real-time main loop; afterwards that
    thread schedules as before (not SCHED_FIFO pinned to one CPU for the rest of the process)."""
    if reason := _fifo_refused():
        pytest.skip(reason)
    before = os.sched_getscheduler(0), os.sched_getparam(0).sched_priority, os.sched_getaffinity(0)
    cpus = sorted(before[2])
    text = REALTIME.replace("FIRST", str(cpus[0])).replace("LAST", str(cpus[-1]))
    result = run_until(tmp_path, text, lambda system: (tmp_path / "run-c" / "main_probe.runs").exists()
                       and system.state("sink") is State.RUNNING, "the main loop ran its activities, and the sink runs")
    assert result.outcome.status is ExitStatus.SUCCESS, result.outcome.reasons
    assert (os.sched_getscheduler(0), os.sched_getparam(0).sched_priority, os.sched_getaffinity(0)) == before
