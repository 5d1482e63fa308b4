"""For block authors' tests and benchmarks: a block alone in a harness, and small calls measured.

`BlockHarness` runs one block without a composition, the way dora's mock node does: its ports
are real ports fed and read by the test, its clock is virtual, its life-cycle hooks are called
as its activity's state machine would call them. The measuring functions report microseconds
per call and what a call leaves allocated (bench/ reports figures; tests check allocations only).
"""

from __future__ import annotations

import contextlib
import queue
import time
import tracemalloc
from collections.abc import Callable
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import numpy as np

from hapticop.blocks.base import Block
from hapticop.blocks.registry import resolve
from hapticop.runtime.clock import VirtualClock
from hapticop.runtime.context import ActivityContext, FlagView, InputPort, OutputPort
from hapticop.runtime.logs import Level, Logger
from hapticop.runtime.streams import LatestSlot, latest_nbytes


class HookDidNotComplete(AssertionError):
    pass


class BlockHarness:
    """One block, its ports and flags, stepped by hand on a virtual clock.

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
        self._sources: dict[str, LatestSlot] = {}
        inputs = {}
        for port_name, spec in self.interface.inputs.items():
            inputs[port_name] = InputPort(port_name, spec, self.clock.now_ns)
            self._sources[port_name] = LatestSlot(bytearray(latest_nbytes(spec)), spec, synchronised=False)
            inputs[port_name].connect(self._sources[port_name], queue=False,
                                      max_age_ns=(max_age_ns or {}).get(port_name, 0))
        outputs = {port_name: OutputPort(port_name, spec, self.clock.now_ns)
                   for port_name, spec in self.interface.outputs.items()}
        flag_names = list(self.interface.flags_written) + list(self.interface.flags_read)
        self.flag_values = np.zeros(max(len(flag_names), 1), dtype=np.uint8)
        flags = FlagView(self.flag_values, {f"{name}.{flag}": i for i, flag in enumerate(flag_names)}, name, flag_names)
        self._log_queue: queue.SimpleQueue = queue.SimpleQueue()
        log = Logger(name, Level.DEBUG, self._log_queue, self.clock.now_ns)
        self.context = ActivityContext(name, self.params, SimpleNamespace(**inputs), SimpleNamespace(**outputs), flags,
                                       self.clock, log, np.random.default_rng(seed), Path(run_dir))
        self.block = self.block_type(self.context)
        self.inputs, self.outputs, self.flags = self.context.inputs, self.context.outputs, flags

    def feed(self, port: str, value) -> None:
        """Write a sample to input `port`, as the stream that feeds it would (seen at the next step)."""
        self._sources[port].write(np.asarray(value), self.clock.now_ns())

    def configure(self, max_cycles: int = 100_000) -> None:
        """create, then each configuration hook until it completes, one period apart, with the
        inputs refreshed before each call as the runtime does."""
        for hook in (self.block.create, self.block.configure_resources, self.block.configure_capabilities):
            for _ in range(max_cycles):
                self._refresh()
                if hook() is not False:
                    break
                self.advance()
            else:
                raise HookDidNotComplete(f"{hook.__name__} did not complete in {max_cycles} cycles")

    def step(self, cycles: int = 1) -> None:
        """Cycles while running: inputs refreshed, compute, then flush (with inputs refreshed again)."""
        flushes = self.block_type.implements_flush()
        for _ in range(cycles):
            self._refresh()
            self.block.compute()
            if flushes:
                self._refresh()
                self.block.flush()
            self.advance()

    def retune(self, params: dict[str, Any]) -> frozenset[str]:
        """A live patch of running parameters as the runtime delivers it between two cycles: the
        top-level keys of `params` replace the block's, then `retune` hears which ones changed."""
        merged = self.block_type.Params.model_validate({**self.params.model_dump(), **params})
        changed = frozenset(k for k in type(merged).model_fields if getattr(merged, k) != getattr(self.params, k))
        if not changed <= self.block_type.running_params:
            raise ValueError(f"{sorted(changed - self.block_type.running_params)} are not running parameters: "
                             "a live patch would re-configure the block instead")
        self.params = self.block.params = self.context.params = merged
        self.block.retune(changed)
        return changed

    def clean(self) -> None:
        self.block.clean()

    def advance(self, ns: int | None = None) -> None:
        self.clock.advance_to(self.clock.now_ns() + (self.period_ns if ns is None else ns))

    def log_lines(self) -> list[str]:
        """What the block logged since the last call, formatted."""
        lines = []
        while not self._log_queue.empty():
            _, _, level, message, args = self._log_queue.get()
            lines.append(f"{Level(level).name.lower()}: {message % args if args else message}")
        return lines

    def _refresh(self) -> None:
        for port in vars(self.inputs).values():
            port.refresh()



def allocation_stats(fn: Callable[[], object], calls: int = 1000, warmup: int = 10) -> tuple[int, int]:
    """(bytes still allocated after `calls` calls, peak bytes during them), by tracemalloc."""
    for _ in range(warmup):
        fn()
    tracemalloc.start()
    try:
        before, _ = tracemalloc.get_traced_memory()
        tracemalloc.reset_peak()
        for _ in range(calls):
            fn()
        after, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    return after - before, peak - before


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
        before = tracemalloc.take_snapshot()
        run()
        after = tracemalloc.take_snapshot()
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
