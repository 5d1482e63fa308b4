"""A time-triggered thread: each cycle it steps its own LCSM, then its selected schedule.

The same `CyclicThread` runs as a thread of the main process, as the only loop of its own
process, or stepped by the virtual-clock scheduler: only the loop that calls `cycle()`
differs. In real time the loop sleeps to absolute deadlines, records each wake-up latency
(until the run starts ending) and counts every missed deadline (a cycle that overruns skips,
and counts, the periods it covered).
"""

from __future__ import annotations

import os
import select
import threading
import time
from collections.abc import Callable

import numpy as np

from hapticop.blocks.base import Block
from hapticop.composition.description import Thread
from hapticop.composition.lcsm import State
from hapticop.runtime import realtime
from hapticop.runtime.context import CycleClock
from hapticop.runtime.cycle_log import CycleLog
from hapticop.runtime.latencies import OriginRelay
from hapticop.runtime.lifecycle import Hooks, Lifecycle
from hapticop.runtime.logs import Logger
from hapticop.runtime.region import Region


class ActivityRunner:
    """One activity on its thread: the block, its LCSM and its ports."""

    def __init__(self, name: str, block: Block, region: Region, start_on_request: bool, log: Logger,
                 relay: OriginRelay | None = None, cycle: CycleClock | None = None):
        self.name, self.block, self.region, self.log = name, block, region, log
        self.cycle = cycle if cycle is not None else CycleClock()  # the step's time its input ports judge by
        self.now_ns = block.context.clock.now_ns
        self.relay = relay
        self.simulator = block.simulator
        # A simulator's time counts as simulation. On the wall clock that is its thread's CPU time
        # (other threads preempt it); on the virtual clock, where every loop runs in this thread one
        # after the other, its step's duration, without two system calls per step.
        self.simulator_cpu = self.simulator and not block.context.clock.virtual
        self.flushes = block.implements_flush()
        self.took = 0  # this cycle's compute time so far (compute, then flush)
        self.computing = False  # this cycle ran the block's compute (a life-cycle hook is no compute)
        self.retuned: tuple[object, frozenset[str]] | None = None  # new running parameters, not yet taken
        self.cycle_log: CycleLog | None = None  # a recorded run's row per cycle (`cycle_log`)
        # Which of the parameter sets handed to it (counted from 1) the block holds: 0 for its first
        # ones; what a recording's parameter events are matched to (`parameter_events`).
        self.parameters = np.zeros(1, np.int64)
        self._handed = 0
        self._retuning = threading.Lock()
        layout = region.layout
        self.index = layout.activity_index[name]
        self.compute_counts = region.histograms("compute")
        self.inputs = [port for port in vars(block.inputs).values()]
        self.lifecycle = Lifecycle(
            region.flags, region.state, region.failed, layout.owner_index[name], layout.flag_index, name,
            Hooks(block.create, block.configure_resources, block.configure_capabilities, block.compute,
                  block.pausing, block.clean),
            start_on_request, log, region.reached,
        )

    @property
    def state(self) -> State:
        return self.lifecycle.state

    def retune(self, params: object, changed: frozenset[str]) -> None:
        """Hand the block new parameters; it takes them before its next step, on its own thread.
        Parameters given twice before that step arrive as one change of both sets of names."""
        with self._retuning:
            if self.retuned is not None:
                changed = changed | self.retuned[1]
            self.retuned = (params, changed)
            self._handed += 1

    def _take_parameters(self) -> None:
        with self._retuning:  # the main thread may hand over more meanwhile
            params, changed = self.retuned  # type: ignore[misc]
            self.retuned = None
            self.parameters[0] = self._handed
        block = self.block
        block.params = block.context.params = params
        if changed and self.lifecycle.configured:  # one still configuring builds from the new ones
            try:
                block.retune(changed)
            except Exception as error:  # noqa: BLE001 - a block's bug is its failure, not the thread's
                self.lifecycle.fail_running(error)

    def step(self) -> None:
        self.cycle.now = self.now_ns()
        if self.retuned is not None:
            self._take_parameters()
        changed = False
        for port in self.inputs:
            if port.refresh() or port.queue:  # a queue's origins change as the block pops it
                changed = True
        relay = self.relay
        if relay is not None and changed:  # the origins merged last step still stand otherwise
            relay.before_step()
        cycle_log = self.cycle_log
        if cycle_log is not None:
            cycle_log.before()
        cpu = time.thread_time_ns() if self.simulator_cpu else 0
        started = time.perf_counter_ns()
        self.computing = self.lifecycle.step()
        took = self.took = time.perf_counter_ns() - started
        if cycle_log is not None:
            cycle_log.stepped()
        if self.simulator:
            self.region.sim_ns[self.index] += time.thread_time_ns() - cpu if self.simulator_cpu else took
        if not self.flushes:
            self._finish()

    def flush(self) -> None:
        """The write phase: fresh inputs (what this cycle computed), then the block's flush."""
        for port in self.inputs:
            port.refresh()
        started = time.perf_counter_ns()
        self.lifecycle.flush(self.block.flush)
        self.took += time.perf_counter_ns() - started
        if self.cycle_log is not None:
            self.cycle_log.flushed()
        self._finish()

    def _finish(self) -> None:
        """Count the cycle's compute time (not a configuring or cleaning hook's: a world plotting its
        run as it cleans is no 1.5 s compute), and the end-to-end latencies ending here."""
        if self.computing:
            self.compute_counts.count(self.index, self.took)
        if self.relay is not None:
            self.relay.after_step()
        if self.cycle_log is not None:
            self.cycle_log.push()


class CyclicThread:
    """The event loop of one thread of the composition."""

    def __init__(self, name: str, spec: Thread, region: Region, runners: dict[str, ActivityRunner],
                 clock, log: Logger, apply_realtime: bool):
        self.name, self.spec, self.region, self.clock, self.log = name, spec, region, clock, log
        self.runners = runners
        self.apply_realtime = apply_realtime
        layout = region.layout
        self.index = layout.thread_index[name]
        self.period = spec.period
        self.schedules = {sid: [runners[a] for a in members if a in runners] for sid, members in spec.schedules.items()}
        prefix = f"threads.{name}"
        self.select_flags = [(sid, layout.flag_index[f"{prefix}.select_schedule.{sid}"]) for sid in spec.schedules]
        self.schedule_flags = {sid: layout.flag_index[f"{prefix}.schedule.{sid}"] for sid in spec.schedules}
        self.deadline_missed_flag = layout.flag_index[f"{prefix}.deadline_missed"]
        self.lifecycle = Lifecycle(
            region.flags, region.state, region.failed, layout.owner_index[prefix], layout.flag_index, prefix,
            Hooks(self._create, self._configure_resources, self._configure_capabilities, self._run_schedule,
                  self._pause, self._clean),
            spec.start == "on_request", log, region.reached,
        )
        self.selected = -1
        self._plan: tuple[dict[int, list[ActivityRunner]], dict[int, list[ActivityRunner]]] = ({}, {})
        self._all: list[ActivityRunner] = []
        self._place()
        self._select(0)
        self.supervisor: Callable[[], None] | None = None  # the main thread's supervisor runs first

    # -- the thread's own life cycle ------------------------------------------------------
    def _create(self) -> bool:
        return True

    def _configure_resources(self) -> bool:
        if self.apply_realtime:
            realtime.apply(self.spec, self.log)
        return True

    def _configure_capabilities(self) -> bool:
        return True

    def _pause(self) -> None:
        self._housekeeping(self._all)

    def _run_schedule(self) -> None:
        flags = self.region.flags
        for sid, index in self.select_flags:
            if flags[index]:
                flags[index] = 0
                self._select(sid)
        schedules, outsides = self._plan  # one read: a live patch may replace both meanwhile
        selected = self.selected
        active = schedules[selected]
        for runner in active:
            runner.step()
        for runner in active:
            if runner.flushes:
                runner.flush()
        outside = outsides[selected]
        if outside:
            self._housekeeping(outside)

    @staticmethod
    def _housekeeping(outside: list[ActivityRunner]) -> None:
        """Activities outside the selected schedule still honour a request to clean."""
        for runner in outside:
            if runner.lifecycle.cleaning_requested() or runner.state is State.CLEANING:
                runner.step()

    def _place(self) -> None:
        """Which runners each schedule leaves out (their housekeeping), made once per change of the
        schedules or the runners rather than looked for every cycle."""
        runners = list(self.runners.values())
        schedules = self.schedules
        self._plan = (schedules, {sid: [r for r in runners if r not in members] for sid, members in schedules.items()})
        self._all = runners

    def add_runner(self, name: str, runner: ActivityRunner) -> None:
        """A live patch added an activity to this thread: scheduled by the patch's new schedules."""
        self.runners[name] = runner
        self._place()

    def _clean(self) -> bool:
        """Walk every activity of this thread to done, then the thread is done."""
        finished = True
        for runner in self.runners.values():
            if runner.state is not State.DONE:
                runner.lifecycle.request_cleaning()
                runner.step()
                finished = finished and runner.state is State.DONE
        return finished

    def _select(self, sid: int) -> None:
        if sid == self.selected:
            return
        for other, index in self.schedule_flags.items():
            self.region.flags[index] = 1 if other == sid else 0
        if self.selected >= 0:
            self.log.info("schedule %d -> %d", self.selected, sid)
        self.selected = sid
        self.region.selected[self.index] = sid

    def replace_schedules(self, schedules: dict[int, list[str]]) -> None:
        """A live patch changed the schedules: takes effect from the next cycle."""
        self.schedules = {sid: [self.runners[a] for a in members if a in self.runners]
                          for sid, members in schedules.items()}
        self._place()
        if self.selected not in self.schedules:
            self._select(0)

    @property
    def done(self) -> bool:
        return self.lifecycle.state is State.DONE

    # -- one cycle, and the real-time loop ------------------------------------------------
    def cycle(self) -> None:
        if self.supervisor is not None:
            self.supervisor()
        self.region.heartbeat[self.index] = self.clock.now_ns()
        self.region.cycles[self.index] += 1
        self.lifecycle.step()

    def run_realtime(self, first_deadline_ns: int, should_stop: Callable[[], bool]) -> None:
        region, index, period = self.region, self.index, self.period
        system = region.system
        latencies, busy = region.histograms("latency"), region.histograms("busy")
        deadline = first_deadline_ns
        clock = self.clock
        spin = self.spec.busy_wait
        on_data = self.spec.wake == "data"
        if self.apply_realtime:
            realtime.plain()  # until its resource configuration, not its creator's real time
        while not system[Region.TERMINATE] and not should_stop():
            if on_data and self._wait_for_data(deadline):
                self.cycle()  # data woke us before the deadline: an extra cycle, off the grid
                region.cpu_ns[index] = time.thread_time_ns()
                if self.done:
                    break
                continue
            if spin:
                clock.sleep_until(deadline - spin)
                clock.spin_until(deadline)
            else:
                clock.sleep_until(deadline)
            woke = clock.now_ns()
            latencies.count(index, woke - deadline)
            self.cycle()
            finished = clock.now_ns()
            busy.count(index, finished - woke)
            region.cpu_ns[index] = time.thread_time_ns()
            if self.done:
                break
            deadline += period
            if finished > deadline:  # overran: skip and count the periods already gone
                missed = (finished - deadline) // period + 1
                region.missed[index] += missed
                region.flags[self.deadline_missed_flag] = 1
                deadline += missed * period
        self.log.info("loop ended after %d cycles (pid %d)", int(region.cycles[index]), os.getpid())

    def _wait_for_data(self, deadline_ns: int) -> bool:
        """Wait until a wake-up descriptor of the running schedule is readable (True) or the
        deadline is near (False: the caller sleeps the rest)."""
        fds = [fd for runner in self.schedules[self.selected] if runner.state is State.RUNNING
               for fd in runner.block.wakeup_fds()]
        timeout = (deadline_ns - self.clock.now_ns()) / 1e9
        if not fds or timeout <= 0:
            return False
        try:
            readable, _, _ = select.select(fds, (), (), timeout)
        except (OSError, ValueError):  # a socket closed under us: its block notices in its cycle
            return False
        return bool(readable)
