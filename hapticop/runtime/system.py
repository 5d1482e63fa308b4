"""`hapticop compose`: a validated composition turned into a running system.

The main process creates the shared region, builds the threads deployed in it, and runs
the main thread, whose mediator activity owns the coordination: it starts the other
threads (as threads, or as processes attached to the same region), steps the nets every
cycle, and applies live patches at cycle boundaries. Around it, a supervisor on the main
thread keeps the run bounded: the duration, Ctrl+C and SIGTERM, a shutdown that
coordination must finish in time, and threads whose process died.

With the virtual clock nothing sleeps: every thread is stepped in the main process, at its
deadlines in simulated time, in a fixed order, so one composition and seed always give
the same run.
"""

from __future__ import annotations

import dataclasses
import heapq
import multiprocessing
from collections import deque
import signal
import sys
import threading
from dataclasses import dataclass, field
from enum import IntEnum
from pathlib import Path
from typing import Callable

from hapticop.composition.lcsm import State
from hapticop.composition.loader import Loaded
from hapticop.runtime.assembly import Built, build, layout_of, thread_of
from hapticop.runtime.clock import RealtimeClock, VirtualClock
from hapticop.coordination.coordinator import Coordinator
from hapticop.runtime.lifecycle import OK
from hapticop.runtime.logs import Level, LogWriter, default_run_dir
from hapticop.runtime import live, realtime
from hapticop.runtime.control import ControlError, ControlServer, socket_path
from hapticop.validation.patches import PatchError, load_patch, prepare
from hapticop.runtime.deadlines import first_deadline, phases
from hapticop.runtime.region import Region
from hapticop.composition.yamlsource import parse_text, plain
from hapticop.runtime.thread import CyclicThread
from hapticop.composition.units import format_duration

SECOND = 1_000_000_000


class ForcedExit(BaseException):
    """A second Ctrl+C or SIGTERM: leave at once, without waiting for coordination."""


class ExitStatus(IntEnum):
    SUCCESS = 0
    FAILURE = 1
    INTERRUPTED = 130
    TERMINATED = 143


@dataclass
class RunOptions:
    clock: str = "realtime"  # or "virtual"
    duration_ns: int | None = None
    seed: int = 0
    run_dir: Path | None = None
    shutdown_timeout_ns: int = 5 * SECOND
    echo: bool = True  # errors and warnings to the console
    control: str | None = None  # control socket name or path (default: the composition's name)


@dataclass
class _ProcessThread:
    name: str  # the process's name: its thread's, or the shared 'process' name
    process: multiprocessing.Process
    messages: object  # the sending end of a pipe: live changes for its threads
    threads: list[str] = field(default_factory=list)
    reported: bool = False


@dataclass
class Outcome:
    status: ExitStatus
    run_dir: Path
    reasons: list[str] = field(default_factory=list)


class System:
    def __init__(self, loaded: Loaded, source_text: str, file: str, options: RunOptions):
        self.composition = loaded.composition
        if options.duration_ns is None and self.composition.duration is not None:
            options = dataclasses.replace(options, duration_ns=self.composition.duration)
        self.loaded, self.text, self.file, self.options = loaded, source_text, file, options
        self.virtual = options.clock == "virtual"
        self.clock = VirtualClock() if self.virtual else RealtimeClock()
        self.run_dir = options.run_dir or default_run_dir(self.composition.name or Path(file).stem)
        self.writer = LogWriter(self.run_dir, echo=sys.stderr if options.echo else None).start()
        self.log = self.writer.logger("system", Level.INFO, self.clock.now_ns)
        self.layout = layout_of(loaded)
        self.region = Region.create(self.layout)
        self.flag_index = self.layout.flag_index
        self.coordinator = Coordinator(self.composition.coordination, self.region.flags, self.flag_index)
        self.owner_thread = thread_of(self.composition)
        local = [t for t, spec in self.composition.threads.items() if self.virtual or spec.deploy != "process"]
        self.built: Built = build(loaded, self.region, local, self.clock, self.writer, options.seed,
                                  apply_realtime=not self.virtual)
        self.main_name = next(t for t, spec in self.composition.threads.items() if spec.deploy == "main")
        self.main: CyclicThread = self.built.threads[self.main_name]
        self.processes: dict[str, _ProcessThread] = {}
        self._next_watch_ns = 0
        self.os_threads: dict[str, threading.Thread] = {}
        self.virtual_queue: list[tuple[int, int, str]] = []
        self.started = False
        self.reasons: list[str] = []
        self.interrupted: ExitStatus | None = None
        self.shutdown_at: int | None = None
        self.forced = False
        self.default_shutdown = not self._read_by_flag_map("system.shutdown_requested")
        self.exit_by_flag = self._written_by_flag_map("system.exit")
        self.main.supervisor = self.supervise
        self.tree = parse_text(source_text, file).tree
        self.pending: deque[live.PendingPatch] = deque()
        # (at, name, patch, prepared PendingPatch or None, the tree it was prepared on)
        self.scripted = sorted(((p.at, name, p, None, None) for name, p in self.composition.patches.items()),
                               key=lambda item: (item[0], item[1]))
        self.control: ControlServer | None = None
        self.finished = False
        self.operating_ns: int | None = None
        for runner in self.built.runners.values():
            attach = getattr(runner.block, "attach_system", None)
            if attach is not None:
                attach(self)
        if not self.virtual:
            # Processes are created now, before memory is locked and before any loop runs
            # (forking a large locked process stalls the parent); they wait for the mediator.
            groups: dict[str, list[str]] = {}
            for name, spec in self.composition.threads.items():
                if spec.deploy == "process":
                    groups.setdefault(spec.process_name(name), []).append(name)
            for process_name, threads in groups.items():
                self._spawn(process_name, threads)
            realtime.prepare_process([self.composition.threads[t] for t in local], self.log)
        if not self.virtual and self.scripted:
            self._prepare_scripted()
        self.region.system[Region.STARTED_NS] = self.region.system[Region.EPOCH_NS] = self.clock.now_ns()
        self._warn_declaration_only_blocks()

    # -- what the flag maps say ---------------------------------------------------------
    def _read_by_flag_map(self, flag: str) -> bool:
        return any(flag in fm.converting_sources or flag in fm.tracking_sources
                   for fm in self.composition.coordination.flag_maps.values())

    def _written_by_flag_map(self, flag: str) -> bool:
        return any(flag in fm.converting_sinks or flag in fm.tracking_sinks
                   for fm in self.composition.coordination.flag_maps.values())

    def _warn_declaration_only_blocks(self) -> None:
        for name, resolved in self.loaded.activities.items():
            if resolved.interface.outputs and not resolved.block.implements_compute():
                self.log.warning("activity '%s': block '%s' declares its ports but has no computation yet; "
                                 "its outputs stay at zero", name, resolved.spec.block)

    def flag(self, name: str) -> bool:
        return bool(self.region.flags[self.flag_index[name]])

    def set_flag(self, name: str, value: bool = True) -> None:
        self.region.flags[self.flag_index[name]] = 1 if value else 0

    def state(self, owner: str) -> State:
        return State(int(self.region.state[self.layout.owner_index[owner]]))

    # -- the mediator's duties ----------------------------------------------------------
    def start_threads(self) -> bool:
        """Create every thread but the main one (the mediator's resource configuration)."""
        if self.started:
            return True
        self.started = True
        now = self.clock.now_ns()
        for order, (name, spec) in enumerate(self.composition.threads.items()):
            if name == self.main_name:
                continue
            if self.virtual:
                heapq.heappush(self.virtual_queue, (now, order, name))
            elif spec.deploy == "process":
                self.region.go[self.layout.thread_index[name]] = 1
            else:
                thread = self.built.threads[name]
                os_thread = threading.Thread(target=thread.run_realtime, args=(self._first_deadline(name), self._never),
                                             name=f"hapticop-{name}", daemon=True)
                self.os_threads[name] = os_thread
                os_thread.start()
        self.log.info("threads started")
        return True

    @staticmethod
    def _never() -> bool:
        return False

    def _first_deadline(self, thread: str) -> int:
        return first_deadline(int(self.region.system[Region.EPOCH_NS]), self.composition.threads[thread].period,
                              phases(self.composition)[thread], self.clock.now_ns())

    def _spawn(self, name: str, threads: list[str]) -> None:
        from hapticop.runtime.child import process_main

        context = multiprocessing.get_context("spawn")
        receiving, sending = context.Pipe(duplex=False)
        process = context.Process(
            target=process_main,
            args=(plain(self.tree), self.layout.flags[: self.layout.declared_flags], self.region.name, threads,
                  str(self.run_dir), self.options.seed, receiving),
            name=f"hapticop-{name}", daemon=True,
        )
        process.start()
        receiving.close()
        handle = _ProcessThread(name, process, sending, threads)
        for thread in threads:
            self.processes[thread] = handle
            self.log.info("thread '%s' runs in process %d", thread, process.pid)

    def coordinate(self) -> None:
        """One coordination step (the mediator's compute)."""
        self.coordinator.step()

    def send(self, thread: str, message: tuple) -> None:
        """A live change for a thread in another process; that process notices the counter."""
        self.processes[thread].messages.send((thread, message))
        self.region.control[self.layout.thread_index[thread]] += 1

    @staticmethod
    def resolve_block(name: str):
        from hapticop.blocks.registry import resolve

        return resolve(name)

    # -- supervision, every main-thread cycle -------------------------------------------
    def supervise(self) -> None:
        now = self.clock.now_ns()
        started = int(self.region.system[Region.STARTED_NS])
        if self.pending:
            self._apply_pending()
        if self.scripted and now - started >= self.scripted[0][0]:
            self._apply_scripted(self.scripted.pop(0))
        if self.operating_ns is None and not self.virtual:
            self._watch_start(now, started)
        counted_from = started if self.virtual else (self.operating_ns or now)
        if self.options.duration_ns is not None and self.shutdown_at is None and now - counted_from >= self.options.duration_ns:
            self.log.info("duration %s reached", format_duration(self.options.duration_ns))
            self.request_shutdown()
        self._watch_processes()
        if self.shutdown_at is None and self.flag("system.stop"):
            self.log.info("the coordination asked to stop")
            self.request_shutdown()
        if self.exit_by_flag and self.flag("system.exit"):
            self._finish()  # the nets ended the run (after a shutdown request, or on their own)
            return
        if self.shutdown_at is None:
            return
        if self.default_shutdown or self.forced:
            self._walk_down()
        elif now - self.shutdown_at > self.options.shutdown_timeout_ns:
            self.forced = True
            self.reasons.append(f"coordination did not finish the shutdown within "
                                f"{format_duration(self.options.shutdown_timeout_ns)}; forced")
            self.log.error(self.reasons[-1])

    def _watch_start(self, now: int, started: int) -> None:
        """Once every thread has cycled (processes take a while to start), timing restarts there.

        The start-up's slow first cycles say nothing about how the system keeps time, so the
        statistics are cleared, the cycle and CPU counters noted, and a real-time `duration`
        counts from this moment. A thread that never starts does not hold this up past a minute.
        """
        region = self.region
        if not (region.cycles > 0).all() and now - started < 60 * SECOND:
            return
        self.operating_ns = now
        for name in ("latency", "latency_max", "compute", "compute_max", "missed", "e2e", "e2e_max", "sim_ns"):
            getattr(region, name)[...] = 0
        region.cycles_base[:] = region.cycles
        region.cpu_base[:] = region.cpu_ns
        region.system[Region.OPERATING_NS] = now
        self.log.info("every thread runs, %.1f s after start: timing is counted from here", (now - started) / SECOND)

    def request_shutdown(self) -> None:
        if self.shutdown_at is not None:
            return
        self.shutdown_at = self.clock.now_ns()
        if "system.shutdown_requested" in self.flag_index:
            self.set_flag("system.shutdown_requested")

    # -- live changes -------------------------------------------------------------------
    def prepare_patch(self, patch, patch_file: str = "<patch>", base=None) -> "live.PendingPatch":
        """Apply and validate a patch against the running description (any thread), or against
        `base`, a (tree, composition) some earlier pending patch will leave."""
        tree, composition = base or (self.tree, self.composition)
        new_tree, new, plan, diff = prepare(tree, patch, old=composition, patch_file=patch_file,
                                            name=Path(self.file).name)
        resolved = live.check(self, plan, new)
        pending = live.PendingPatch(plan, new, new_tree, resolved, threading.Event())
        pending.diff = diff
        return pending

    def _apply_pending(self) -> None:
        while self.pending:
            pending = self.pending.popleft()
            try:
                live.apply(self, pending)
            except Exception as error:  # noqa: BLE001 - reported to the client, the system runs on
                pending.error = f"{type(error).__name__}: {error}"
                self.log.error("patch not applied: %s", pending.error)
            pending.applied.set()

    def _prepare_scripted(self) -> None:
        """Validate the scripted patches before any loop runs, each on the tree the one before
        leaves: validating takes about a second, which a 1 kHz main loop cannot spare. A patch
        whose base changed meanwhile (a live patch came between) is prepared again when due."""
        tree, composition, prepared = self.tree, self.composition, []
        for at, name, scripted, _, _ in self.scripted:
            pending = None
            try:
                pending = self.prepare_patch(scripted.patch, f"patches.{name}", base=(tree, composition))
            except PatchError:
                pass  # refused when due, with its reason
            prepared.append((at, name, scripted, pending, tree))
            if pending is not None:
                tree, composition = pending.tree, pending.composition
        self.scripted = prepared

    def _apply_scripted(self, item) -> None:
        at, name, scripted, pending, base = item
        try:
            if pending is None or base is not self.tree:
                pending = self.prepare_patch(scripted.patch, patch_file=f"patches.{name}")
            live.apply(self, pending)
            self.log.always("scripted patch '%s' applied at %s", name, format_duration(at))
        except PatchError as error:
            message = f"scripted patch '{name}' refused: {error.diagnostics[0].message}"
            self.reasons.append(message)
            self.log.error(message)

    def _walk_down(self) -> None:
        """The runtime's own shutdown: activities, then threads, then the main thread."""
        others = [n for n in self.loaded.activities if self.owner_thread.get(n) and
                  self.composition.activities[n].block != "mediator"]
        for name in others:
            if self.state(name) is not State.DONE and not self._lost(self.owner_thread[name]):
                self.set_flag(f"{name}.lcsm.request_cleaning")
        if any(self.state(n) is not State.DONE and not self._lost(self.owner_thread[n]) for n in others):
            return
        threads = [t for t in self.composition.threads if t != self.main_name]
        for name in threads:
            if self.state(f"threads.{name}") is not State.DONE and not self._lost(name):
                if self.started:
                    self.set_flag(f"threads.{name}.lcsm.request_cleaning")
                else:  # never started: nothing to clean
                    self.region.state[self.layout.owner_index[f"threads.{name}"]] = State.DONE
        if all(self.state(f"threads.{t}") is State.DONE or self._lost(t) for t in threads):
            self._finish()

    def _finish(self) -> None:
        self.main.lifecycle.request_cleaning()

    def _lost(self, thread: str) -> bool:
        handle = self.processes.get(thread)
        return handle is not None and handle.reported

    WATCH_PROCESSES_NS = 10_000_000  # a lost process is noticed within 10 ms (the streams' ages tell sooner)

    def _watch_processes(self) -> None:
        """Children that ended unasked; looked at every 10 ms, not every cycle: each look costs
        two system calls per child."""
        now = self.clock.now_ns()
        if now < self._next_watch_ns:
            return
        self._next_watch_ns = now + self.WATCH_PROCESSES_NS
        for handle in {id(h): h for h in self.processes.values()}.values():
            if handle.reported or handle.process.is_alive():
                continue
            done = all(self.state(f"threads.{t}") is State.DONE for t in handle.threads)
            if done and handle.process.exitcode == 0:
                continue
            handle.reported = True
            names = ", ".join(f"'{t}'" for t in handle.threads)
            message = (f"thread{'s' if len(handle.threads) > 1 else ''} {names} "
                       f"{'were' if len(handle.threads) > 1 else 'was'} lost: process {handle.process.pid} "
                       f"ended with exit code {handle.process.exitcode}")
            self.reasons.append(message)
            self.log.error(message)
            for thread in handle.threads:
                self.set_flag(f"threads.{thread}.lost")

    # -- running ------------------------------------------------------------------------
    # -- the control channel ------------------------------------------------------------
    def handle(self, request: dict) -> dict:
        """A request on the control socket (its own thread): status, or a patch."""
        op = request.get("op")
        if op == "status":
            return {"ok": True, "status": self.status()}
        if op != "patch":
            return {"ok": False, "error": f"unknown request {op!r}; expected 'status' or 'patch'"}
        try:
            patch = load_patch(request.get("text", ""), request.get("file", "<patch>"))
            pending = self.prepare_patch(patch, request.get("file", "<patch>"))
        except PatchError as error:
            return {"ok": False, "error": "patch refused", "diagnostics": [d.to_json() for d in error.diagnostics]}
        result = {"ok": True, "diff": pending.diff, "changes": pending.plan.describe()}
        if request.get("dry_run"):
            return {**result, "applied": False}
        self.pending.append(pending)
        if not pending.applied.wait(timeout=5.0):
            return {"ok": False, "error": "the main thread did not reach a cycle boundary within 5 s"}
        if pending.error:
            return {"ok": False, "error": f"patch not applied: {pending.error}"}
        return {**result, "applied": True}

    def status(self) -> dict:
        from hapticop.runtime.report import timing

        owners = {owner: {"state": self.state(owner).flag_name, "failed": self._failure(owner)
                          if self.region.failed[i] != OK else None}
                  for owner, i in self.layout.owner_index.items()}
        return {
            "name": self.composition.name or Path(self.file).stem,
            "clock": "virtual" if self.virtual else "realtime",
            "uptime_s": (self.clock.now_ns() - int(self.region.system[Region.STARTED_NS])) / SECOND,
            "threads": {t: {**owners[f"threads.{t}"], "schedule": int(self.region.selected[i])}
                        for t, i in self.layout.thread_index.items()},
            "activities": {a: owners[a] for a in self.layout.activity_index},
            "flags": sorted(name for name, i in self.flag_index.items() if self.region.flags[i]),
            "markings": self.coordinator.markings(),
            "timing": timing(self.region, self.composition),
        }

    def _start_control(self) -> None:
        name = self.composition.name or Path(self.file).stem
        try:
            self.control = ControlServer(socket_path(self.options.control or name), self.handle).start()
            self.log.info("control socket %s", self.control.path)
        except (ControlError, OSError) as error:
            self.log.warning("no control socket, so no live patches: %s", error)

    def run(self) -> Outcome:
        previous = self._install_signals()
        if not self.virtual:
            self._start_control()
        try:
            if self.virtual:
                self._run_virtual()
            else:
                self._run_realtime()
        finally:
            self.finished = True
            self._restore_signals(previous)
            self._stop_everything()
        return Outcome(self._status(), self.run_dir, self.reasons)

    def _run_realtime(self) -> None:
        hold = None
        wanted = self.composition.cpu_dma_latency
        if wanted is not None and any(spec.priority is not None for spec in self.composition.threads.values()):
            hold = realtime.hold_cpu_dma_latency(wanted, self.log)
        try:
            self.main.run_realtime(self._first_deadline(self.main_name), self._never)
        finally:
            if hold is not None:
                hold.close()

    def _run_virtual(self) -> None:
        """Step every started thread at its deadlines, earliest first, ties in file order."""
        order = {name: i for i, name in enumerate(self.composition.threads)}
        queue = self.virtual_queue
        heapq.heappush(queue, (0, order[self.main_name], self.main_name))
        # With a duration, a run that outlives it by far has a shutdown that never ends; without
        # one it runs until the composition ends it (or Ctrl+C), as on the wall clock.
        limit = None
        if self.options.duration_ns is not None:
            limit = self.options.duration_ns + 2 * self.options.shutdown_timeout_ns + 60 * SECOND
        while queue:
            deadline, rank, name = heapq.heappop(queue)
            if limit is not None and deadline > limit:
                self.reasons.append("the virtual run did not end within its time limit")
                break
            self.clock.advance_to(deadline)
            thread = self.built.threads[name]
            thread.cycle()
            if name == self.main_name and thread.done:
                break
            if not thread.done:
                heapq.heappush(queue, (deadline + thread.period, rank, name))

    def _install_signals(self):
        if threading.current_thread() is not threading.main_thread():
            return None

        def handler(signum, _frame):
            if self.interrupted is not None:  # the second one: leave now
                self.region.system[Region.TERMINATE] = 1
                raise ForcedExit(self.interrupted)
            self.interrupted = ExitStatus.INTERRUPTED if signum == signal.SIGINT else ExitStatus.TERMINATED
            self.log.always("%s: shutting down (again to force)", signal.Signals(signum).name)
            self.request_shutdown()

        return {s: signal.signal(s, handler) for s in (signal.SIGINT, signal.SIGTERM)}

    @staticmethod
    def _restore_signals(previous) -> None:
        for signum, handler in (previous or {}).items():
            signal.signal(signum, handler)

    def _stop_everything(self) -> None:
        if self.control is not None:
            self.control.stop()
        self.region.system[Region.TERMINATE] = 1 if any(
            self.state(f"threads.{t}") is not State.DONE for t in self.composition.threads) else 0
        for os_thread in self.os_threads.values():
            os_thread.join(timeout=2)
        for handle in self.processes.values():
            handle.process.join(timeout=2)
            if handle.process.is_alive():
                handle.process.terminate()
                handle.process.join(timeout=2)

    def _status(self) -> ExitStatus:
        failed = [owner for owner, index in self.layout.owner_index.items() if self.region.failed[index] != OK]
        for owner in failed:
            self.reasons.append(f"'{owner}' failed ({self._failure(owner)})")
        if self.reasons:  # forced shutdown, lost thread, refused scripted patch, failed owner...
            return ExitStatus.FAILURE
        if self.interrupted is not None:
            return self.interrupted
        return ExitStatus.SUCCESS

    def _failure(self, owner: str) -> str:
        from hapticop.runtime.lifecycle import FAILURE_TEXT

        return FAILURE_TEXT.get(int(self.region.failed[self.layout.owner_index[owner]]), "failed")

    def close(self) -> None:
        self.writer.stop()
        self.built = None  # drop the views into the region before it is released
        self.main = None
        self.region.close()


@dataclass
class RunResult:
    """What a finished run leaves: its outcome, timing, and the final LCSM states and flags."""

    outcome: Outcome
    timing: dict
    states: dict[str, State]
    flags: set[str]
    markings: dict[str, dict[str, int]]
    virtual: bool


def run_system(loaded: Loaded, text: str, file: str, options: RunOptions,
               on_start: Callable[["System"], None] | None = None) -> RunResult:
    """Build, run and release a system; `on_start` sees it just before it runs."""
    from hapticop.runtime.report import timing, write_timing

    system = System(loaded, text, file, options)
    try:
        if on_start is not None:
            on_start(system)
        outcome = system.run()
        elapsed = None
        if not system.virtual:
            since = int(system.region.system[Region.OPERATING_NS]) or int(system.region.system[Region.STARTED_NS])
            elapsed = system.clock.now_ns() - since
        data = timing(system.region, system.composition, elapsed)
        write_timing(data, system.run_dir)
        states = {owner: system.state(owner) for owner in system.layout.owner_index}
        flags = {name for name, i in system.flag_index.items() if system.region.flags[i]}
        return RunResult(outcome, data, states, flags, system.coordinator.markings(), system.virtual)
    finally:
        system.close()
