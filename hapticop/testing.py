"""For block authors' tests and benchmarks: a block alone in a harness, and small calls measured.

`BlockHarness` runs one block without a composition, the way dora's mock node does: its ports
are real ports fed and read by the test, its clock is virtual, and its hooks are called by the
runtime's own runner and life-cycle state machine, over a region laid out for it alone, with the
context a run would build (`runtime.assembly.make_context`), as in a run. The measuring
functions report microseconds per call and what a call leaves allocated (bench/ reports figures;
tests check allocations only).
"""

from __future__ import annotations

import contextlib
import queue
import time
import tracemalloc
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from hapticop.blocks.base import Block
from hapticop.blocks.registry import resolve
from hapticop.composition import flags as flagdefs
from hapticop.composition.lcsm import State
from hapticop.runtime.assembly import make_context
from hapticop.runtime.clock import VirtualClock
from hapticop.runtime.logs import Level, Logger
from hapticop.runtime.region import Layout, Region
from hapticop.runtime.streams import LatestSlot, latest_nbytes
from hapticop.runtime.thread import ActivityRunner


class _Private:
    """The region's memory, private to this process: nobody else attaches to one block alone."""

    def __init__(self, size: int) -> None:
        self.buf = memoryview(bytearray(size))
        self.name = ""

    def close(self) -> None:
        return None


class HookDidNotComplete(AssertionError):
    pass


_HOOK_OF = {State.CREATION: "create", State.RESOURCE_CONFIGURATION: "configure_resources",
            State.CAPABILITY_CONFIGURATION: "configure_capabilities"}


class BlockHarness:
    """One block, its ports and flags, on the runtime's own runner, stepped by hand on a virtual clock.

    >>> harness = BlockHarness("echo", {"dtype": "float64", "shape": [3]})
    >>> harness.configure()
    >>> harness.feed("input", [1.0, 2.0, 3.0]); harness.step()
    >>> harness.outputs.output.value
    """

    def __init__(self, block: type[Block] | str, params: dict[str, Any] | None = None, *, name: str = "block",
                 period_ns: int = 1_000_000, run_dir: Path | str = ".", seed: int = 0,
                 max_age_ns: dict[str, int] | None = None):
        """`max_age_ns` gives inputs a stream's max_age: a sample older than that reads as not valid."""
        self.block_type = resolve(block) if isinstance(block, str) else block
        self.params = self.block_type.Params.model_validate(params or {})
        self.interface = self.block_type.declare(self.params)
        self.clock = VirtualClock()
        self.period_ns = period_ns
        self._log_queue: queue.SimpleQueue = queue.SimpleQueue()
        log = Logger(name, Level.DEBUG, self._log_queue, self.clock.now_ns)
        runtime_log = Logger(name, Level.WARNING, self._log_queue, self.clock.now_ns)  # failures, not state changes
        interface = self.interface
        layout = Layout.alone(name, list(flagdefs.activity_flags(name, interface.flags_written, interface.flags_read)))
        self.region = Region(layout, _Private(layout.size), owner=False)  # type: ignore[arg-type]
        self.region.state[:] = State.CREATION
        self.context, cycle = make_context(name, interface, self.params, self.region, self.clock, log,
                                           np.random.default_rng(seed), Path(run_dir), period_ns)
        self.block = self.block_type(self.context)
        self.runner = ActivityRunner(name, self.block, self.region, False, runtime_log, cycle=cycle)
        self._sources: dict[str, LatestSlot] = {}
        for port_name, port in vars(self.context.inputs).items():
            self._sources[port_name] = LatestSlot(bytearray(latest_nbytes(port.spec)), port.spec, synchronised=False)
            port.connect(self._sources[port_name], queue=False, max_age_ns=(max_age_ns or {}).get(port_name, 0))
        self.flag_values = self.region.flags
        self.inputs, self.outputs, self.flags = self.context.inputs, self.context.outputs, self.context.flags

    def feed(self, port: str, value) -> None:
        """Write a sample to input `port`, as the stream that feeds it would (seen at the next step)."""
        self._sources[port].write(np.asarray(value), self.clock.now_ns())

    def configure(self, max_cycles: int = 100_000) -> None:
        """Cycles, one period apart, until the life cycle runs the block: creation, then each
        configuration hook again each cycle until it completes, as its activity's LCSM does."""
        tries = 0
        while self.runner.state is not State.RUNNING:
            state = self.runner.state
            if state not in _HOOK_OF:
                raise HookDidNotComplete(f"the block is {state.flag_name}, not configuring")
            self._cycle()
            tries = 0 if self.runner.state is not state else tries + 1
            if tries >= max_cycles:
                raise HookDidNotComplete(f"{_HOOK_OF[state]} did not complete in {max_cycles} cycles")

    def step(self, cycles: int = 1) -> None:
        """Cycles while running: inputs refreshed, compute, then flush (with inputs refreshed again)."""
        for _ in range(cycles):
            self._cycle()

    def retune(self, params: dict[str, Any]) -> frozenset[str]:
        """A live patch of running parameters as the runtime delivers it: the top-level keys of
        `params` replace the block's, and the block takes them (`retune` hears which ones changed)
        at its next step."""
        merged = self.block_type.Params.model_validate({**self.params.model_dump(), **params})
        changed = frozenset(k for k in type(merged).model_fields if getattr(merged, k) != getattr(self.params, k))
        if not changed <= self.block_type.running_params:
            raise ValueError(f"{sorted(changed - self.block_type.running_params)} are not running parameters: "
                             "a live patch would re-configure the block instead")
        self.params = merged
        self.runner.retune(merged, changed)
        return changed

    def clean(self) -> None:
        """The life cycle's cleaning, as a shutdown asks for it."""
        self.runner.lifecycle.request_cleaning()
        self._cycle()

    def advance(self, ns: int | None = None) -> None:
        self.clock.advance_to(self.clock.now_ns() + (self.period_ns if ns is None else ns))

    def log_lines(self) -> list[str]:
        """What the block logged since the last call, formatted."""
        lines = []
        while not self._log_queue.empty():
            _, _, level, message, args = self._log_queue.get()
            lines.append(f"{Level(level).name.lower()}: {message % args if args else message}")
        return lines

    def _cycle(self) -> None:
        """One cycle of the runner, then the clock a period on; a hook that raised raises here."""
        runner = self.runner
        runner.step()
        if runner.flushes:
            runner.flush()
        error, runner.lifecycle.error = runner.lifecycle.error, None  # the runner only logs it
        if error is not None:
            raise error
        self.advance()


# Allocations that are not the measured call's: another thread's machinery (pytest-xdist's execnet
# thread, for one, receives and sends while a worker's test runs) and the measuring itself (the
# snapshots, and this module's loop counter).
NOT_THE_CALL = tuple(tracemalloc.Filter(False, pattern) for pattern in (
    "*/execnet/*", "*/threading.py", "*/queue.py", "*/selectors.py", tracemalloc.__file__, "<frozen abc>", __file__))


CLEAN = (256, 1024)  # bytes kept and at peak below which no test of the suite sees an allocation


def allocation_stats(fn: Callable[[], object], calls: int = 1000, warmup: int = 10,
                     attempts: int = 3) -> tuple[int, int]:
    """(bytes still allocated after `calls` calls, peak bytes during them), by tracemalloc; what other
    threads' machinery and the measuring allocated is left out of the first.

    The peak cannot leave other threads out (tracemalloc keeps one for the process), so a measure
    that is not clean is taken again, up to `attempts` times, and the least of each is returned: an
    allocation of the call's own shows every time, another thread's now and then."""
    for _ in range(warmup):
        fn()
    kept = peak = None
    for _ in range(attempts):
        k, p = _allocated(fn, calls)
        kept, peak = (k, p) if kept is None else (min(kept, k), min(peak, p))
        if kept < CLEAN[0] and peak < CLEAN[1]:
            break
    return kept, peak


def _allocated(fn: Callable[[], object], calls: int) -> tuple[int, int]:
    tracemalloc.start()
    try:
        before = tracemalloc.take_snapshot().filter_traces(NOT_THE_CALL)
        start, _ = tracemalloc.get_traced_memory()
        tracemalloc.reset_peak()
        for _ in range(calls):
            fn()
        _, peak = tracemalloc.get_traced_memory()
        after = tracemalloc.take_snapshot().filter_traces(NOT_THE_CALL)
    finally:
        tracemalloc.stop()
    return sum(stat.size_diff for stat in after.compare_to(before, "filename")), peak - start


def time_per_call(fn: Callable[[], object], calls: int = 5000) -> tuple[float, float]:
    """(median, p99) microseconds per call, after a warm-up."""
    for _ in range(200):
        fn()
    samples = np.empty(calls)
    clock = time.perf_counter_ns
    for i in range(calls):
        started = clock()
        fn()
        samples[i] = clock() - started
    return float(np.median(samples)) / 1e3, float(np.percentile(samples, 99)) / 1e3


def grown_bytes(run: Callable[[], object]) -> int:
    """Bytes one call of `run` left allocated, summed over the files where allocation grew
    (tracemalloc snapshots before and after; warm up before calling this)."""
    tracemalloc.start()
    try:
        before = tracemalloc.take_snapshot().filter_traces(NOT_THE_CALL)
        run()
        after = tracemalloc.take_snapshot().filter_traces(NOT_THE_CALL)
    finally:
        tracemalloc.stop()
    return sum(stat.size_diff for stat in after.compare_to(before, "filename") if stat.size_diff > 0)


@contextlib.contextmanager
def stepped_system(validated, run_dir: Path):
    """A valid composition built on the virtual clock, for a caller that steps its threads itself
    (`thread.cycle()`); yields the system and its threads, not yet started. However the caller ends,
    the blocks are cleaned (links closed, worlds withdrawn: the process goes on) and the region freed."""
    from hapticop.runtime.system import RunOptions, System

    system = System(validated, RunOptions(clock="virtual", run_dir=run_dir, echo=False))
    threads = dict(system.built.threads)
    try:
        yield system, threads
    finally:
        for thread in threads.values():
            for runner in thread.runners.values():
                runner.block.clean()
        system.writer.stop()
        system.built = system.main = None
        system.region.close()
