"""Asking Linux for real-time treatment: SCHED_FIFO, CPU affinity, locked memory.

These need root or CAP_SYS_NICE (and CAP_IPC_LOCK, or a memlock limit without bound, for
mlockall). Where the user may not, the system still runs with normal scheduling: before
anything starts, `missing` finds what the composition asks for that it will not get, and the
run says it in one warning; each thread's own failed attempt is only written to its log.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import os
import resource
import threading
from collections.abc import Callable

from hapticop.composition.description import Thread
from hapticop.runtime.logs import Logger

MCL_CURRENT, MCL_FUTURE = 1, 2

_lock = threading.Lock()
_noted: set[str] = set()
_memory_locked = False
_process_cpus: set[int] | None = None  # the CPUs the process may use, before any thread was pinned


def _note_once(key: str, log: Logger, message: str, *args: object) -> None:
    """Into the owner's log, once per process: the console has had the run's one warning (`missing`)."""
    with _lock:
        if key in _noted:
            return
        _noted.add(key)
    log.info(message, *args)


CAP_IPC_LOCK, CAP_SYS_NICE = 14, 23


def _capable(bit: int) -> bool:
    """Whether this process holds the capability (root normally holds them all)."""
    try:
        for line in open("/proc/self/status"):
            if line.startswith("CapEff:"):
                return bool(int(line.split()[1], 16) >> bit & 1)
    except OSError:
        pass
    return os.geteuid() == 0


def _on_a_thread(attempt: Callable[[], str | None]) -> str | None:
    """Run `attempt` on a thread of its own, which then ends: a scheduling change there is what
    the system's threads will be able to make (a container's real-time budget can refuse root too)."""
    answer: list[str | None] = [None]

    def run() -> None:
        answer[0] = attempt()

    probe = threading.Thread(target=run, name="hapticop-rt-probe")
    probe.start()
    probe.join()
    return answer[0]


def missing(threads: list[Thread], cpu_dma_latency: int | None) -> list[str]:
    """What these threads ask of Linux that this process will not get, each in a few words."""
    wanted = [spec for spec in threads if spec.priority is not None]
    cpu_sets = sorted({tuple(spec.cpus) for spec in threads if spec.cpus})

    def attempt() -> str | None:
        if wanted:
            try:
                os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(max(spec.priority for spec in wanted)))
            except OSError:
                return "SCHED_FIFO priorities (needs root or CAP_SYS_NICE)"
        return None

    def affinity() -> str | None:
        refused = []
        for cpus in cpu_sets:
            try:
                os.sched_setaffinity(0, cpus)
            except OSError as error:
                refused.append(f"CPU affinity to CPUs {', '.join(map(str, cpus))} ({error.strerror})")
        return "; ".join(refused) or None

    gaps = [gap for gap in (_on_a_thread(attempt), _on_a_thread(affinity)) if gap]
    if wanted:
        soft, _hard = resource.getrlimit(resource.RLIMIT_MEMLOCK)
        if not _capable(CAP_IPC_LOCK) and soft != resource.RLIM_INFINITY:
            gaps.insert(1, "locked memory (mlockall needs CAP_IPC_LOCK or an unlimited memlock limit)")
        if cpu_dma_latency is not None and not os.access("/dev/cpu_dma_latency", os.W_OK):
            gaps.append("/dev/cpu_dma_latency (not writable)")
    return gaps


def warn_missing(threads: list[Thread], cpu_dma_latency: int | None, log: Logger) -> list[str]:
    """The run's one warning about real time it will not get, if any; what is missing."""
    gaps = missing(threads, cpu_dma_latency)
    if gaps:
        log.warning("real time not available: %s; the threads run with what they get and their deadlines are "
                    "not protected", "; ".join(gaps))
    return gaps


def lock_memory(log: Logger) -> None:
    """mlockall once per process, so page faults never stall a cycle."""
    global _memory_locked
    with _lock:
        if _memory_locked:
            return
        _memory_locked = True
    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6", use_errno=True)
        if libc.mlockall(MCL_CURRENT | MCL_FUTURE) != 0:
            raise OSError(ctypes.get_errno(), os.strerror(ctypes.get_errno()))
    except OSError as error:
        _note_once("mlockall", log, "cannot lock memory (mlockall: %s); page faults may delay cycles", error.strerror)


def prepare_process(threads: list[Thread], log: Logger) -> None:
    """Before any loop starts: lock memory if a thread of this process is real-time.

    mlockall walks every mapped page (tens of milliseconds with numpy loaded), so it is
    done here, once, rather than inside a cycle where it would count as missed deadlines.
    """
    global _process_cpus
    if _process_cpus is None:
        _process_cpus = os.sched_getaffinity(0)
    if any(spec.priority is not None for spec in threads):
        lock_memory(log)


def process_cpus() -> set[int]:
    return _process_cpus if _process_cpus is not None else set(range(os.cpu_count() or 1))


def plain() -> None:
    """The calling thread back to normal scheduling on every CPU of the process: a thread starts
    with its creator's policy, priority and CPUs, which are not its own (its resource
    configuration applies what it declares)."""
    normal_scheduling()
    try:
        os.sched_setaffinity(0, process_cpus())
    except OSError:
        pass  # CPUs taken away since: whatever the kernel left us


class Saved:
    """The calling thread's scheduling, to give back when a run ends on a thread it borrowed
    (a system run in-process makes its caller's thread its main loop)."""

    def __init__(self) -> None:
        self.policy, self.param = os.sched_getscheduler(0), os.sched_getparam(0)
        self.cpus = os.sched_getaffinity(0)

    def restore(self) -> None:
        try:
            os.sched_setscheduler(0, self.policy, self.param)
            os.sched_setaffinity(0, self.cpus)
        except OSError:
            pass  # nothing was changed that we may change back


def normal_scheduling() -> None:
    """The calling thread back to SCHED_OTHER, whatever it inherited from its creator."""
    if os.sched_getscheduler(0) != os.SCHED_OTHER:
        os.sched_setscheduler(0, os.SCHED_OTHER, os.sched_param(0))


def apply(spec: Thread, log: Logger) -> None:
    """Apply the thread's declared priority and affinity to the calling thread.

    A thread without a priority gets normal scheduling explicitly: a thread inherits its
    creator's policy, and threads are started by the main thread, which may be real-time.
    """
    if spec.priority is None:
        normal_scheduling()
    else:
        lock_memory(log)  # already done by prepare_process; a no-op then
        try:
            os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(spec.priority))
            log.info("SCHED_FIFO priority %d", spec.priority)
        except PermissionError:
            _note_once("fifo", log, "cannot use SCHED_FIFO (needs root or CAP_SYS_NICE): threads run with "
                       "normal scheduling and their deadlines are not protected")
    try:
        os.sched_setaffinity(0, spec.cpus or process_cpus())  # no CPUs named: not its creator's either
    except OSError as error:
        _note_once(f"cpus{spec.cpus}", log, "cannot set CPU affinity %s: %s", spec.cpus, error.strerror)


def hold_cpu_dma_latency(microseconds: int, log: Logger):
    """Keep the CPUs out of idle states slower to leave than `microseconds` while the file is open.

    The kernel's PM QoS honours the request only as long as the returned file stays open;
    closing it (or exiting) restores the default. Returns None where the file is not there
    or not writable, after saying so once.
    """
    try:
        handle = open("/dev/cpu_dma_latency", "wb", buffering=0)  # noqa: SIM115 - held for the whole run
        handle.write(int(microseconds).to_bytes(4, "little", signed=True))
    except OSError as error:
        _note_once("cpu_dma_latency", log, "cannot hold /dev/cpu_dma_latency at %d us (%s): deep CPU idle states "
                   "may delay wake-ups", microseconds, error.strerror)
        return None
    log.info("/dev/cpu_dma_latency held at %d us", microseconds)
    return handle
