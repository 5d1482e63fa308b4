"""The entry point of a process running threads deployed out of the main process.

The child rebuilds the composition from the plain tree it is handed, attaches to the parent's
shared region by name, builds only its own threads (one, or those sharing a named process),
and runs their loops. Ctrl+C is the parent's to handle: the child starts with SIGINT blocked,
ignores it from its first line, and leaves when its threads are done or the region says
terminate. If the parent dies without saying so (SIGKILL, the OOM killer), the kernel tells the
child (PR_SET_PDEATHSIG): it cleans its activities, which brings their devices to a safe state,
and ends within `ORPHAN_BOUND_S`.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import os
import signal
import sys
import threading
import time
from pathlib import Path

from hapticop.composition.loader import load_tree
from hapticop.runtime import realtime
from hapticop.runtime.assembly import build, layout_of
from hapticop.runtime.clock import RealtimeClock
from hapticop.runtime.deadlines import thread_start
from hapticop.runtime.logs import Level, LogWriter
from hapticop.runtime.region import Region

ORPHAN_BOUND_S = 1.0  # from the parent's death to this process's end, cleaned or not
PR_SET_PDEATHSIG = 1


def process_main(tree: dict, flags: list[str], rings: dict[str, int], region_name: str, threads: list[str],
                 run_dir: str, seed: int, messages) -> None:
    """The parent hands over the validated tree as plain data and the flag list, so this process
    neither parses YAML nor builds the graph again: it starts in a fraction of the time. The
    first thread runs on this process's main thread (`rings`: the recorder rings the run reserved, laid out
    as the parent did); others it shares the process with get
    threads of their own."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT})  # blocked by the parent while it started us
    parent = os.getppid()
    loaded = load_tree(tree)
    try:
        region = Region.attach(layout_of(loaded, flags, rings), region_name)
    except FileNotFoundError:
        return  # the run ended (an interrupted start-up) before this process got going: nothing to do
    _leave_with_parent(parent, region, threads)
    clock = RealtimeClock()
    writer = LogWriter(Path(run_dir), echo=sys.stderr).start()
    built = build(loaded, region, threads, clock, writer, seed, apply_realtime=True)
    composition = loaded.composition
    realtime.prepare_process([composition.threads[t] for t in threads],
                             writer.logger("system", Level.INFO, clock.now_ns))
    first = built.threads[threads[0]]
    first.supervisor = _LiveChanges(built, region, threads, messages)

    def run(thread: str) -> None:
        index = region.layout.thread_index[thread]
        while not region.go[index] and not region.system[Region.TERMINATE]:
            time.sleep(0.001)  # created early; runs once the mediator starts the thread
        start = thread_start(composition, thread, int(region.system[Region.EPOCH_NS]), clock.now_ns())
        built.threads[thread].run_realtime(start, lambda: False)

    others = [threading.Thread(target=run, args=(t,), name=f"hapticop-{t}", daemon=True) for t in threads[1:]]
    try:
        for other in others:
            other.start()
        run(threads[0])
        for other in others:
            other.join()
    finally:
        writer.stop()
        built = None  # drop the views into the region before it is released (rebound, not deleted: run() reads it)
        region.close()


def _leave_with_parent(parent: int, region: Region, threads: list[str]) -> None:
    """When the parent dies, clean this process's threads (their activities first: zero forces,
    zero wheel commands) and leave; whatever has not cleaned by the bound is left at once."""

    def orphaned(_signum=None, _frame=None) -> None:
        for thread in threads:
            region.set_flag(f"threads.{thread}.lcsm.request_cleaning")
        for delay, action, args in ((0.8 * ORPHAN_BOUND_S, _terminate, (region,)), (ORPHAN_BOUND_S, os._exit, (1,))):
            timer = threading.Timer(delay, action, args=args)
            timer.daemon = True  # a process that finished cleaning in time does not wait for it
            timer.start()

    signal.signal(signal.SIGTERM, orphaned)
    libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6", use_errno=True)
    libc.prctl(PR_SET_PDEATHSIG, signal.SIGTERM, 0, 0, 0)
    if os.getppid() != parent:  # it died before the request took effect
        orphaned()


def _terminate(region: Region) -> None:
    system = getattr(region, "system", None)  # None: the process has already let the region go
    if system is not None:
        system[Region.TERMINATE] = 1  # every loop of this process leaves at once


class _LiveChanges:
    """Applies the parent's live changes between two cycles of this process's first thread."""

    def __init__(self, built, region: Region, threads: list[str], messages):
        self.built, self.region, self.messages = built, region, messages
        self.indices = [region.layout.thread_index[t] for t in threads]
        self.seen = 0

    def __call__(self) -> None:
        control = self.region.control
        total = 0
        for index in self.indices:
            total += int(control[index])
        if total == self.seen:
            return  # the common case: a few memory reads
        self.seen = total
        while self.messages.poll():
            thread, (kind, *args) = self.messages.recv()
            if kind == "params":
                name, params, changed = args
                runner = self.built.runners[name]
                runner.retune(type(runner.block.params).model_validate(params), frozenset(changed))
            elif kind == "schedules":
                self.built.threads[thread].replace_schedules({int(k): v for k, v in args[0].items()})
            elif kind == "max_age":
                reader, max_age = args
                activity, port = reader.split(".")
                getattr(self.built.runners[activity].block.inputs, port).max_age_ns = max_age
