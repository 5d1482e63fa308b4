"""Keeping a run bounded, from the main thread, between two of its cycles.

The duration, Ctrl+C and SIGTERM, threads whose process died, and the shutdown: asked of
the coordination through `system.shutdown_requested` when the nets read it (and forced
when they take longer than the shutdown timeout), or otherwise walked down by the
runtime itself: activities, then threads, then the main thread.
"""

from __future__ import annotations

import os
import signal
import threading
from collections.abc import Callable
from enum import IntEnum
from pathlib import Path

from hapticop.composition.description import Composition
from hapticop.composition.lcsm import State
from hapticop.composition.units import format_duration
from hapticop.runtime.described import Description
from hapticop.runtime.lifecycle import FAILURE_TEXT, OK
from hapticop.runtime.logs import Logger
from hapticop.runtime.region import Region
from hapticop.runtime.report import Ending
from hapticop.runtime.scheduler import Scheduler

SECOND = 1_000_000_000
STARTUP_BOUND_NS = 60 * SECOND  # a thread's process gets this long to load before the run goes on without it
WATCH_PROCESSES_NS = 10_000_000  # a lost process is noticed within 10 ms (the streams' ages tell sooner)


class ForcedExit(BaseException):
    """A second Ctrl+C or SIGTERM: leave at once, without waiting for coordination."""


class ExitStatus(IntEnum):
    SUCCESS = 0
    FAILURE = 1
    UNAVAILABLE = 69  # devices the composition needs are not there: not started (sysexits' EX_UNAVAILABLE)
    INTERRUPTED = 130
    TERMINATED = 143


def failure(region: Region, owner: str) -> str:
    """Why an activity or thread failed, in words."""
    return FAILURE_TEXT.get(int(region.failed[region.layout.owner_index[owner]]), "failed")


def _read_by_flag_map(composition: Composition, flag: str) -> bool:
    return any(flag in fm.converting_sources or flag in fm.tracking_sources
               for fm in composition.coordination.flag_maps.values())


def _written_by_flag_map(composition: Composition, flag: str) -> bool:
    return any(flag in fm.converting_sinks or flag in fm.tracking_sinks
               for fm in composition.coordination.flag_maps.values())


def _a_child_ended() -> bool:
    """Whether any child of this process has ended and not been collected yet (it stays uncollected)."""
    try:
        return os.waitid(os.P_ALL, 0, os.WEXITED | os.WNOHANG | os.WNOWAIT) is not None
    except ChildProcessError:  # no child at all
        return False


class Supervisor:
    def __init__(self, region: Region, scheduler: Scheduler, log: Logger, *, duration_ns: int | None,
                 shutdown_timeout_ns: int, finish: Callable[[], None]):
        self.region, self.scheduler, self.log = region, scheduler, log
        self.clock = scheduler.clock
        self.duration_ns, self.shutdown_timeout_ns = duration_ns, shutdown_timeout_ns
        self.finish = finish  # the main thread starts cleaning: the run ends
        composition = scheduler.composition
        self.default_shutdown = not _read_by_flag_map(composition, "system.shutdown_requested")
        self.exit_by_flag = _written_by_flag_map(composition, "system.exit")
        self.reasons: list[str] = []  # why the run failed, if it did
        self.interrupted: ExitStatus | None = None
        self.left_at_once = False  # a second Ctrl+C or SIGTERM: the run is being left at once
        self.shutdown_at: int | None = None
        self.forced = False
        self.operating_ns: int | None = None
        self.ending: Ending | None = None  # the counters as the run started ending
        self._next_watch_ns = 0

    def time_limit_ns(self) -> int | None:
        """Under the virtual clock, a run that outlives its duration by far has a shutdown that
        never ends; without a duration it runs until the composition ends it, as on the wall clock."""
        if self.duration_ns is None:
            return None
        return self.duration_ns + 2 * self.shutdown_timeout_ns + 60 * SECOND

    def check(self, description: Description) -> None:
        """Every main-thread cycle, after live changes: is it time to stop, and how far is the stop?"""
        now = self.clock.now_ns()
        started = int(self.region.system[Region.STARTED_NS])
        virtual = self.scheduler.virtual
        if self.operating_ns is None and not virtual and self.ending is None:  # an ended window starts no more
            self._watch_start(now, started)
        counted_from = started if virtual else (self.operating_ns or now)
        if self.duration_ns is not None and self.shutdown_at is None and now - counted_from >= self.duration_ns:
            self.log.info("duration %s reached", format_duration(self.duration_ns))
            self.request_shutdown()
        self._watch_processes()
        if self.shutdown_at is not None and self._processes_loading(now, started):
            self.shutdown_at = now  # the shutdown's time runs from when every thread can take part in it
        if self.shutdown_at is None and self.region.flag("system.stop"):
            self.log.info("the coordination asked to stop")
            self.request_shutdown()
        if self.exit_by_flag and self.region.flag("system.exit"):
            # The nets ended the run (after a shutdown request, or on their own). What they do not
            # coordinate (a simulation's thread running from the start) the runtime cleans itself.
            if self.shutdown_at is None:
                self.shutdown_at = now
                self._end_timing()
            if now - self.shutdown_at > self.shutdown_timeout_ns:
                self.reasons.append("what the coordination left running did not clean within "
                                    f"{format_duration(self.shutdown_timeout_ns)}")
                self.log.error(self.reasons[-1])
                self.finish()
            else:
                self._walk_down(description)
            return
        if self.shutdown_at is None:
            return
        if self.default_shutdown or self.forced:
            self._walk_down(description)
        elif now - self.shutdown_at > self.shutdown_timeout_ns:
            self.forced = True
            self.reasons.append(f"coordination did not finish the shutdown within "
                                f"{format_duration(self.shutdown_timeout_ns)}; forced")
            self.log.error(self.reasons[-1])

    def _watch_start(self, now: int, started: int) -> None:
        """Once every thread has cycled (processes take a while to start), timing restarts there.

        The start-up's slow first cycles say nothing about how the system keeps time, so the
        statistics are cleared, the cycle and CPU counters noted, and a real-time `duration`
        counts from this moment. A thread that never starts does not hold this up past a minute.
        """
        region = self.region
        if not (region.cycles > 0).all() and now - started < STARTUP_BOUND_NS:
            return
        self.operating_ns = now
        for name in ("latency", "latency_max", "busy", "busy_max", "compute", "compute_max", "missed", "e2e",
                     "e2e_max", "sim_ns"):
            getattr(region, name)[...] = 0
        region.cycles_base[:] = region.cycles
        region.cpu_base[:] = region.cpu_ns
        region.system[Region.OPERATING_NS] = now
        self.log.info("every thread runs, %.1f s after start: timing is counted from here", (now - started) / SECOND)

    def _end_timing(self) -> None:
        """The run starts ending: its figures end here; what the shutdown costs is counted apart."""
        if self.ending is None:
            self.ending = Ending.of(self.region, self.clock.now_ns())
            self.log.info("the run is ending: timing is counted up to here")

    def _processes_loading(self, now: int, started: int) -> bool:
        """Threads started in processes of their own that have not run a cycle yet: still loading
        (seconds on a busy machine). A shutdown asked meanwhile (Ctrl+C during start-up) waits
        for them, within the start-up bound, rather than forcing them."""
        if now - started >= STARTUP_BOUND_NS:
            return False
        region, index = self.region, self.region.layout.thread_index
        return any(region.go[index[thread]] and not region.cycles[index[thread]] and child.process.is_alive()
                   for thread, child in self.scheduler.processes.items())  # a dead one is lost, not loading

    def request_shutdown(self) -> None:
        if self.shutdown_at is not None:
            return
        self.shutdown_at = self.clock.now_ns()
        self._end_timing()
        if "system.shutdown_requested" in self.region.layout.flag_index:
            self.region.set_flag("system.shutdown_requested")

    def _walk_down(self, description: Description) -> None:
        """The runtime's own shutdown: activities, then threads, then the main thread."""
        region, lost = self.region, self.scheduler.lost
        composition, owner_thread = description.composition, description.owner_thread
        others = [n for n in description.activities if owner_thread.get(n) and
                  composition.activities[n].block != "mediator"]
        # Still to clean: not done, on a thread that lives, and created (an activity whose thread
        # never ran it, as after a Ctrl+C during start-up, holds nothing to give back).
        pending = [n for n in others if region.state_of(n) not in (State.DONE, State.CREATION)
                   and not lost(owner_thread[n])]
        for name in pending:
            region.set_flag(f"{name}.lcsm.request_cleaning")
        if pending:
            return
        threads = [t for t in composition.threads if t != self.scheduler.main_name]
        for name in threads:
            if region.state_of(f"threads.{name}") is not State.DONE and not lost(name):
                if self.scheduler.started:
                    region.set_flag(f"threads.{name}.lcsm.request_cleaning")
                else:  # never started: nothing to clean
                    region.state[region.layout.owner_index[f"threads.{name}"]] = State.DONE
        if all(region.state_of(f"threads.{t}") is State.DONE or lost(t) for t in threads):
            self.finish()

    def _watch_processes(self) -> None:
        """Children that ended unasked; looked at every 10 ms, not every cycle. One system call asks
        whether any child of this process has ended (without collecting it); only then is each
        looked at, which costs a system call per child (about 30 us for seven, in one main cycle)."""
        now = self.clock.now_ns()
        if now < self._next_watch_ns:
            return
        self._next_watch_ns = now + WATCH_PROCESSES_NS
        if not self.scheduler.processes or not _a_child_ended():
            return
        for child in {id(c): c for c in self.scheduler.processes.values()}.values():
            if child.reported or child.process.is_alive():
                continue
            done = all(self.region.state_of(f"threads.{t}") is State.DONE for t in child.threads)
            if done and child.process.exitcode == 0:
                continue
            child.reported = True
            names = ", ".join(f"'{t}'" for t in child.threads)
            message = (f"thread{'s' if len(child.threads) > 1 else ''} {names} "
                       f"{'were' if len(child.threads) > 1 else 'was'} lost: process {child.process.pid} "
                       f"ended with exit code {child.process.exitcode}")
            self.reasons.append(message)
            self.log.error(message)
            for thread in child.threads:
                self.region.set_flag(f"threads.{thread}.lost")

    # -- signals ------------------------------------------------------------------------
    def install_signals(self):
        """Ctrl+C or SIGTERM asks for a shutdown; the second one leaves at once (`ForcedExit`)."""
        if threading.current_thread() is not threading.main_thread():
            return None

        def handler(signum, _frame):
            if self.interrupted is not None:  # the second one: leave now
                self.region.system[Region.TERMINATE] = 1
                for other in (signal.SIGINT, signal.SIGTERM):  # a third would cut the cleaning short
                    signal.signal(other, signal.SIG_IGN)
                self.left_at_once = True
                raise ForcedExit(self.interrupted)
            self.interrupted = ExitStatus.INTERRUPTED if signum == signal.SIGINT else ExitStatus.TERMINATED
            self.log.always("%s: shutting down (again to force)", signal.Signals(signum).name)
            self.request_shutdown()

        return {s: signal.signal(s, handler) for s in (signal.SIGINT, signal.SIGTERM)}

    def restore_signals(self, previous) -> None:
        if self.left_at_once:
            return  # signals stay ignored until the process has released everything and exits
        for signum, handler in (previous or {}).items():
            signal.signal(signum, handler)

    def exit_status(self, description: Description, run_dir: Path) -> ExitStatus:
        """After the run: failure with its reasons, an interruption, or success.

        A run is a failure when an owner failed, a thread was lost or the shutdown was forced,
        and also when it is incomplete: an activity that started never reached running, or one
        that ran did not leave the results it promises. An interrupted run is incomplete by
        the user's choice: it says what is missing and keeps the interrupted status.
        """
        layout, region = self.region.layout, self.region
        failed = [owner for owner, index in layout.owner_index.items() if region.failed[index] != OK]
        for owner in failed:
            self.reasons.append(f"'{owner}' failed ({failure(region, owner)})")
        missing = self._incomplete(description, run_dir, set(failed))
        self.reasons.extend(missing)
        if self.reasons and not (self.interrupted is not None and len(self.reasons) == len(missing)):
            return ExitStatus.FAILURE  # forced shutdown, lost thread, refused scripted patch, failed owner...
        if self.interrupted is not None:
            return self.interrupted
        return ExitStatus.SUCCESS

    def _incomplete(self, description: Description, run_dir: Path, failed: set[str]) -> list[str]:
        """Activities that started but never ran, and results promised but not left."""
        region, reasons = self.region, []
        for name, resolved in description.activities.items():
            index = region.layout.owner_index.get(name)
            thread = description.owner_thread.get(name)
            if index is None or name in failed or (thread and self.scheduler.lost(thread)):
                continue  # said already
            reached = int(region.reached[index])
            if not reached & (1 << State.RUNNING):
                if reached & (1 << State.CREATION):  # its thread started it
                    furthest = max(s for s in (State.CREATION, State.RESOURCE_CONFIGURATION,
                                               State.CAPABILITY_CONFIGURATION, State.PAUSING) if reached & (1 << s))
                    reasons.append(f"'{name}' never reached running (it got as far as "
                                   f"{furthest.flag_name.replace('_', ' ')})")
                continue
            lost = [f for f in resolved.block.promises(resolved.params) if not (run_dir / f).exists()]
            if lost:
                reasons.append(f"'{name}' ran but left no {', '.join(lost)} in {run_dir}: results lost")
        return reasons
