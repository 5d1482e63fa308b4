"""When and where each thread runs: OS threads, processes of their own, or the virtual clock's queue.

On the wall clock every loop starts at its first deadline on the system's grid
(`deadlines.thread_start`, asked by the threads of a child process too); threads deployed
as processes are created early and wait for the mediator's go. Under the virtual clock
nothing sleeps: every started thread is stepped in this process at its deadlines, earliest
first, ties in file order, so one composition and seed always give the same run.
"""

from __future__ import annotations

import contextlib
import heapq
import multiprocessing
import signal
import threading
from dataclasses import dataclass, field
from pathlib import Path

from hapticop.composition.description import Composition
from hapticop.composition.lcsm import State
from hapticop.composition.yamlsource import plain
from hapticop.runtime import realtime
from hapticop.runtime.child import process_main
from hapticop.runtime.clock import RealtimeClock, VirtualClock
from hapticop.runtime.deadlines import thread_start
from hapticop.runtime.logs import Logger
from hapticop.runtime.pacing import Pacing
from hapticop.runtime.region import Region
from hapticop.runtime.thread import CyclicThread


@dataclass
class ChildProcess:
    name: str  # the process's name: its thread's, or the shared 'process' name
    process: multiprocessing.Process
    messages: object  # the sending end of a pipe: live changes for its threads
    threads: list[str] = field(default_factory=list)
    reported: bool = False  # its loss was reported


def _never() -> bool:
    return False


@contextlib.contextmanager
def _sigint_held():
    """Ctrl+C held back while a child process is started, then answered.

    Ctrl+C reaches the whole foreground process group: a child still loading would die of it
    with a traceback, so it starts with SIGINT blocked (the mask is inherited) and ignores it
    before unblocking. The parent's own handler, which may run on any thread's signal, only
    notes it meanwhile: raised halfway through `start`, it would leave a child reading half a
    handover.
    """
    noted: list[int] = []
    main = threading.current_thread() is threading.main_thread()
    previous = signal.signal(signal.SIGINT, lambda signum, _frame: noted.append(signum)) if main else None
    mask = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, mask)
        if main:  # None: a handler not set from Python; Python's own is the nearest
            previous = signal.default_int_handler if previous is None else previous
            signal.signal(signal.SIGINT, previous)
            if noted and callable(previous):
                previous(signal.SIGINT, None)


class Scheduler:
    def __init__(self, composition: Composition, region: Region, clock: RealtimeClock | VirtualClock, log: Logger):
        # The composition at start: its threads (but their schedules) and its coordination
        # never change live, so this is all the scheduler and the supervisor read of it.
        self.composition, self.region, self.clock, self.log = composition, region, clock, log
        self.virtual = isinstance(clock, VirtualClock)
        self.main_name = next(t for t, spec in composition.threads.items() if spec.deploy == "main")
        self.processes: dict[str, ChildProcess] = {}  # by thread
        self.os_threads: dict[str, threading.Thread] = {}
        self.queue: list[tuple[int, int, str]] = []  # virtual clock: (deadline, file order, thread)
        self.started = False

    def local_threads(self) -> list[str]:
        """The threads built in this process: all of them under the virtual clock."""
        return [t for t, spec in self.composition.threads.items() if self.virtual or spec.deploy != "process"]

    def first_deadline(self, thread: str) -> int:
        return thread_start(self.composition, thread, int(self.region.system[Region.EPOCH_NS]), self.clock.now_ns())

    def spawn_processes(self, tree, run_dir: Path, seed: int) -> None:
        """Create the processes now, before memory is locked and before any loop runs
        (forking a large locked process stalls the parent); they wait for the mediator."""
        groups: dict[str, list[str]] = {}
        for name, spec in self.composition.threads.items():
            if spec.deploy == "process":
                groups.setdefault(spec.process_name(name), []).append(name)
        layout = self.region.layout
        for process_name, threads in groups.items():
            context = multiprocessing.get_context("spawn")
            receiving, sending = context.Pipe(duplex=False)
            process = context.Process(
                target=process_main,
                args=(plain(tree), layout.flags[: layout.declared_flags], dict(layout.rings), self.region.name,
                      threads, str(run_dir), seed, receiving),
                name=f"hapticop-{process_name}", daemon=True,
            )
            with _sigint_held():
                process.start()
            receiving.close()
            child = ChildProcess(process_name, process, sending, threads)
            for thread in threads:
                self.processes[thread] = child
                self.log.info("thread '%s' runs in process %d", thread, process.pid)

    def start_threads(self, threads: dict[str, CyclicThread]) -> bool:
        """Start every thread but the main one (the mediator's resource configuration)."""
        if self.started:
            return True
        self.started = True
        now = self.clock.now_ns()
        for order, (name, spec) in enumerate(self.composition.threads.items()):
            if name == self.main_name:
                continue
            if self.virtual:
                heapq.heappush(self.queue, (now, order, name))
            elif spec.deploy == "process":
                self.region.go[self.region.layout.thread_index[name]] = 1
            else:
                os_thread = threading.Thread(target=threads[name].run_realtime,
                                             args=(self.first_deadline(name), _never),
                                             name=f"hapticop-{name}", daemon=True)
                self.os_threads[name] = os_thread
                os_thread.start()
        self.log.info("threads started")
        return True

    def send(self, thread: str, message: tuple) -> None:
        """A live change for a thread in another process; that process notices the counter."""
        self.processes[thread].messages.send((thread, message))
        self.region.control[self.region.layout.thread_index[thread]] += 1

    def lost(self, thread: str) -> bool:
        """The thread's process ended unasked (and was reported)."""
        child = self.processes.get(thread)
        return child is not None and child.reported

    def run_realtime(self, main: CyclicThread) -> None:
        """The main thread's loop, on this (the process's main) thread, until it is done."""
        hold = None
        borrowed = realtime.Saved()  # the caller's thread: given back as it was when the run ends
        wanted = self.composition.cpu_dma_latency
        if wanted is not None and any(spec.priority is not None for spec in self.composition.threads.values()):
            hold = realtime.hold_cpu_dma_latency(wanted, self.log)
        try:
            main.run_realtime(self.first_deadline(self.main_name), _never)
        finally:
            borrowed.restore()
            if hold is not None:
                hold.close()

    def run_virtual(self, threads: dict[str, CyclicThread], limit_ns: int | None, pacing: Pacing | None = None) -> bool:
        """Step every started thread at its deadlines (a `pacing`'s, for a replay); False if the run
        outlived `limit_ns`."""
        order = {name: i for i, name in enumerate(self.composition.threads)}
        queue = self.queue
        heapq.heappush(queue, (self.clock.now_ns(), order[self.main_name], self.main_name))
        while queue:
            deadline, rank, name = heapq.heappop(queue)
            if limit_ns is not None and deadline > limit_ns:
                return False
            self.clock.advance_to(deadline)
            thread = threads[name]
            if pacing is not None:
                pacing.before(name, deadline)
            thread.cycle()
            if name == self.main_name and thread.done:
                break
            if not thread.done:
                following = deadline + thread.period if pacing is None else pacing.next_ns(
                    name, deadline, thread.period, thread.lifecycle.state is State.RUNNING)
                heapq.heappush(queue, (following, rank, name))
        return True

    def stop(self) -> None:
        """Every loop still running is told to leave at once; then threads and processes are joined."""
        self.region.system[Region.TERMINATE] = 1 if any(
            self.region.state_of(f"threads.{t}") is not State.DONE for t in self.composition.threads) else 0
        for os_thread in self.os_threads.values():
            os_thread.join(timeout=2)
        for child in self.processes.values():
            child.process.join(timeout=2)
            if child.process.is_alive():
                child.process.terminate()
                child.process.join(timeout=2)
