"""`hapticop compose`: a validated composition turned into a running system.

The main process creates the shared region, builds the threads deployed in it, and runs
the main thread, whose mediator activity owns the coordination: through its context's
`coordination` handle it starts the other threads (`scheduler.py`) and steps the nets
every cycle. Between two main-thread cycles, live patches are applied (`live.py`) and the
supervisor keeps the run bounded (`supervisor.py`); the control socket answers from its
own thread (`service.py`).
"""

from __future__ import annotations

import contextlib
import dataclasses
import json
import os
import signal
import sys
import threading
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from hapticop.composition import flags as flagdefs
from hapticop.composition.description import Composition
from hapticop.composition.lcsm import State
from hapticop.composition.loader import Loaded, ResolvedActivity
from hapticop.coordination.coordinator import Coordinator
from hapticop.rundirs import directory_mode, new_run_directory
from hapticop.runtime import realtime
from hapticop.runtime.assembly import build, layout_of, make_runner, make_transports
from hapticop.runtime.clock import RealtimeClock, VirtualClock
from hapticop.runtime.described import Description
from hapticop.runtime.live import LiveChanges
from hapticop.runtime.logs import Level, LogWriter
from hapticop.runtime.modes import Modes
from hapticop.runtime.observer import ObservedRun, Observer, standard_observer
from hapticop.runtime.pacing import Pacing
from hapticop.runtime.preflight import DevicesMissing, missing_devices
from hapticop.runtime.region import Region
from hapticop.runtime.report import timing, write_timing
from hapticop.runtime.scheduler import Scheduler
from hapticop.runtime.service import ControlService, control_path
from hapticop.runtime.supervisor import SECOND, ExitStatus, Supervisor
from hapticop.runtime.thread import ActivityRunner, CyclicThread
from hapticop.runtime.transport import transport_of
from hapticop.validation import Validated

if TYPE_CHECKING:
    from hapticop.recording.live import LiveOptions

# ExitStatus is part of what a run returns (`Outcome.status`), so it is offered here too.
__all__ = ["ExitStatus", "Outcome", "RunOptions", "RunResult", "System", "run_system"]


@dataclass
class RunOptions:
    clock: str = "realtime"  # or "virtual"
    duration_ns: int | None = None
    seed: int = 0
    run_dir: Path | None = None
    shutdown_timeout_ns: int = 5 * SECOND
    echo: bool = True  # errors and warnings to the console
    control: str | None = None  # control socket name or path (default: the composition's name)
    group_readable: bool = False  # run directories 0750 (files by the caller's umask, 027 from the CLI)
    record: str | None = None  # record every stream even if the file does not say so: to this file ('': the default)
    view: LiveOptions | None = None  # serve live to Foxglove the recorded streams (the latest slots if none is)
    observer: Any = None  # an `Observer` instead of the standard one (which `record` and `view` configure)
    clock_start_ns: int = 0  # the virtual clock's first time (a replay's: a little before the recorded cycles)
    pacing: Pacing | None = None  # under the virtual clock, threads cycled at other times than each period


@dataclass
class Outcome:
    status: ExitStatus
    run_dir: Path
    reasons: list[str] = field(default_factory=list)


@dataclass(frozen=True)
class CoordinationHandle:
    """What the mediator may ask of the runtime: start the other threads, step the nets."""

    start_threads: Callable[[], bool]
    step: Callable[[], bool]


class System:
    """Builds the system from a valid composition, runs it, and releases it. Between
    `run`'s start and end, `flag`, `set_flag`, `state` and `request_shutdown` may be
    called from any thread."""

    def __init__(self, validated: Validated, options: RunOptions):
        source, loaded = validated.source, validated.graph.loaded
        self.observer: Observer = options.observer or standard_observer(options.record, options.view)
        tree, loaded = self.observer.composition(source.tree, loaded)
        composition = loaded.composition
        if options.duration_ns is None and composition.duration is not None:
            options = dataclasses.replace(options, duration_ns=composition.duration)
        self.file, self.options = source.file, options
        self.name = composition.name or Path(self.file).stem
        self.virtual = options.clock == "virtual"
        missing = missing_devices(loaded)
        if missing:  # before anything is made: nothing is left behind
            raise DevicesMissing(self.name, missing)
        self.control_path = None if self.virtual else control_path(options.control, self.name)
        self.clock = VirtualClock(options.clock_start_ns) if self.virtual else RealtimeClock()
        if options.run_dir is None:
            self.run_dir = new_run_directory(self.name, group=options.group_readable)
        else:
            self.run_dir = options.run_dir
            self.run_dir.mkdir(mode=directory_mode(options.group_readable), parents=True, exist_ok=True)
        self.writer = LogWriter(self.run_dir, echo=sys.stderr if options.echo else None).start()
        self.log = self.writer.logger("system", Level.INFO, self.clock.now_ns)
        self.region = self.scheduler = self.built = None
        self.finished = False
        self.recording: dict | None = None  # what the observer recorded and lost, once it finished
        try:
            self._build(validated, tree, loaded, composition, options)
        except BaseException:  # Ctrl+C while processes start, a block that cannot be built: nothing stays
            self.close()
            raise

    def _build(self, validated: Validated, tree, loaded: Loaded, composition: Composition,
               options: RunOptions) -> None:
        self.description = Description.of(tree, loaded)
        self.layout = layout_of(loaded, validated.flags, self.observer.rings(loaded))
        self.region = Region.create(self.layout)
        self.log.info("shared memory %s, %d bytes", self.region.name, self.layout.size)
        self.flag_index = self.layout.flag_index
        self.coordinator = Coordinator(composition.coordination, self.region.flags, self.flag_index)
        self.scheduler = Scheduler(composition, self.region, self.clock, self.log)
        self.coordination = CoordinationHandle(self.start_threads, self.coordinator.step)
        local = self.scheduler.local_threads()
        self.built = build(loaded, self.region, local, self.clock, self.writer, options.seed,
                           apply_realtime=not self.virtual, coordination=self.coordination)
        self.main: CyclicThread = self.built.threads[self.scheduler.main_name]
        self.supervisor = Supervisor(self.region, self.scheduler, self.log, duration_ns=options.duration_ns,
                                     shutdown_timeout_ns=options.shutdown_timeout_ns,
                                     finish=self._finish)
        self.live = LiveChanges(self, Path(self.file).name, self.supervisor.reasons)
        self.modes = Modes(self, self.flag_index, self.region.flags,
                           lambda kind, payload: self.observer.event(kind, payload, self.clock.now_ns()))
        flags = list(validated.flags)

        def attach() -> dict:  # what `hapticop view` needs: the region as the children lay it out from the tree
            return {"region": self.region.name, "flags": flags, "tree": json.loads(json.dumps(tree, default=str)),
                    "rings": dict(self.layout.rings), "run_dir": str(self.run_dir), "pid": os.getpid(),
                    "name": self.name}

        self.service = ControlService(self.name, self.live, self.region, self.clock, self.coordinator,
                                      lambda: self.description, self.log, attach,
                                      lambda: dict(self.modes.given))
        self.main.supervisor = self._between_cycles
        self.observer.start(ObservedRun(loaded, tree, self.file, self.name, self.region, self.clock.now_ns,
                                        self.virtual, options.seed, self.run_dir, self.log))
        if not self.virtual:
            realtime.warn_missing(list(composition.threads.values()), composition.cpu_dma_latency, self.log)
            self.scheduler.spawn_processes(tree, self.run_dir, options.seed)
            realtime.prepare_process([composition.threads[t] for t in local], self.log)
            if self.live.scripted:
                self.live.prepare_scripted()
        self.region.system[Region.STARTED_NS] = self.region.system[Region.EPOCH_NS] = self.clock.now_ns()
        self._warn_declaration_only_blocks()

    def _warn_declaration_only_blocks(self) -> None:
        for name, resolved in self.description.activities.items():
            if resolved.interface.outputs and not resolved.block.implements_compute():
                self.log.warning("activity '%s': block '%s' declares its ports but has no computation yet; "
                                 "its outputs stay at zero", name, resolved.spec.block)

    @property
    def composition(self) -> Composition:
        return self.description.composition

    def flag(self, name: str) -> bool:
        return self.region.flag(name)

    def set_flag(self, name: str, value: bool = True) -> None:
        self.region.set_flag(name, value)

    def state(self, owner: str) -> State:
        return self.region.state_of(owner)

    def request_shutdown(self) -> None:
        self.supervisor.request_shutdown()

    def start_threads(self) -> bool:
        """Create every thread but the main one (the mediator's resource configuration)."""
        return self.scheduler.start_threads(self.built.threads)

    def _finish(self) -> None:
        self.main.lifecycle.request_cleaning()

    def _between_cycles(self) -> None:
        """The main thread's duty before each of its cycles: live changes, then supervision."""
        self.live.apply_due(self.clock.now_ns() - int(self.region.system[Region.STARTED_NS]))
        self.modes.apply_due()  # after the patches: a mode's values stay over a patched activity's
        self.observer.between_cycles()
        self.supervisor.check(self.description)

    # -- what a live patch may touch (live.LiveTarget) -----------------------------------
    @property
    def runners(self) -> dict[str, ActivityRunner]:
        return self.built.runners

    @property
    def threads(self) -> dict[str, CyclicThread]:
        return self.built.threads

    def send(self, thread: str, message: tuple) -> None:
        self.scheduler.send(thread, message)

    def new_runner(self, name: str, resolved: ResolvedActivity, composition: Composition) -> ActivityRunner:
        iface = resolved.interface
        self.layout.add_activity(name, list(flagdefs.activity_flags(name, iface.flags_written, iface.flags_read)))
        runner = make_runner(name, resolved, composition, self.region, {}, self.clock, self.writer,
                             self.options.seed, self.coordination)
        self.built.runners[name] = runner
        return runner

    def new_transports(self, loaded: Loaded, stream: str, owner: dict[str, str]) -> list:
        """An added stream's buffers; if the observer wants it, its recorder ring too, which the
        observer follows from now on."""
        rings = self.rings(loaded)
        if stream in rings:
            self.layout.rings[stream] = rings[stream]
        else:
            self.layout.rings.pop(stream, None)
        self.layout.place(transport_of(loaded, stream), self.layout.allocate)
        objects = make_transports(loaded, self.region, stream, owner, one_thread=self.virtual)
        if stream in rings:
            self.observer.stream_added(loaded, stream, self.layout.recorded[stream])
        return objects

    def rings(self, loaded: Loaded) -> dict[str, int]:
        return self.observer.rings(loaded)

    # -- running ------------------------------------------------------------------------
    def run(self) -> Outcome:
        self.supervisor.reasons.extend(self.observer.ready())
        previous = self.supervisor.install_signals()
        if not self.virtual:
            self.service.start(self.control_path)
        try:
            if not self.virtual:
                self.scheduler.run_realtime(self.main)
            elif not self.scheduler.run_virtual(self.built.threads, self._virtual_limit_ns(), self.options.pacing):
                self.supervisor.reasons.append("the virtual run did not end within its time limit")
        finally:
            self.finished = True
            self.supervisor.restore_signals(previous)
            self.live.close("the system is shutting down")  # a patch still waiting is answered, never applied
            self.service.stop()
            self.scheduler.stop()
            self._stop_observer()
        return Outcome(self.supervisor.exit_status(self.description, self.run_dir), self.run_dir,
                       self.supervisor.reasons)

    def _virtual_limit_ns(self) -> int | None:
        limit = self.supervisor.time_limit_ns()
        return None if limit is None else self.options.clock_start_ns + limit

    def _stop_observer(self) -> None:
        """The loops are done: the observer takes the last samples and finishes the file, after the log
        writer has written every line it was given (the recorder takes parameter events from the log)."""
        if not self.writer.flush():
            self.log.error("the log writer did not catch up within 10 s: the recording may lack its last log lines")
        recording, lost = self.observer.stop()
        self.recording = recording or self.recording
        if lost:
            self.supervisor.reasons.append(lost)
            self.log.error(lost)

    def close(self) -> None:
        """Release everything, whether the system ran, was interrupted, or was half built. Another
        Ctrl+C meanwhile is ignored: it would leave the shared memory and the children behind."""
        with _uninterrupted():
            if self.scheduler is not None and not self.finished:
                self.finished = True
                self.scheduler.stop()  # processes started but never run leave before the region goes
            self._stop_observer()  # a run that never ran still leaves a finished file
            self.writer.stop()
            self.built = None  # drop the views into the region before it is released
            self.main = None
            if self.region is not None:
                self.region.close()


@contextlib.contextmanager
def _uninterrupted():
    """SIGINT and SIGTERM ignored for a bounded piece of cleaning (on the main thread only)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = {s: signal.signal(s, signal.SIG_IGN) for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        yield
    finally:
        for signum, handler in previous.items():
            signal.signal(signum, handler)


@dataclass
class RunResult:
    """What a finished run leaves: its outcome, timing, and the final LCSM states and flags."""

    outcome: Outcome
    timing: dict
    states: dict[str, State]
    flags: set[str]
    markings: dict[str, dict[str, int]]
    virtual: bool
    recording: dict | None = None  # the recorder's summary: the file, and per stream written, recorded, dropped


def run_system(validated: Validated, options: RunOptions,
               on_start: Callable[[System], None] | None = None) -> RunResult:
    """Build, run and release a system from a valid composition; `on_start` sees it just before it runs."""
    system = System(validated, options)
    try:
        if on_start is not None:
            on_start(system)
        outcome = system.run()
        elapsed = None
        ending = system.supervisor.ending
        if not system.virtual:
            since = int(system.region.system[Region.OPERATING_NS]) or int(system.region.system[Region.STARTED_NS])
            elapsed = (ending.at_ns if ending is not None else system.clock.now_ns()) - since
        data = timing(system.region, system.composition, elapsed, ending)
        write_timing(data, system.run_dir)
        states = {owner: system.state(owner) for owner in system.layout.owner_index}
        flags = {name for name, i in system.flag_index.items() if system.region.flags[i]}
        return RunResult(outcome, data, states, flags, system.coordinator.markings(), system.virtual,
                         system.recording)
    finally:
        system.close()
