"""The entry point of a thread deployed in its own process.

The child rebuilds the composition from the plain tree it is handed, attaches to the parent's shared region
by name, builds only its own thread, and runs its loop. Ctrl+C is the parent's to handle:
the child ignores SIGINT and leaves when its thread is done or the region says terminate.
"""

from __future__ import annotations

import signal
import sys
import time
from pathlib import Path

from hapticop.loader import load_tree
from hapticop.runtime.assembly import build, layout_of
from hapticop.runtime.clock import RealtimeClock
from hapticop.runtime import realtime
from hapticop.runtime.logs import Level, LogWriter
from hapticop.runtime.deadlines import first_deadline, phases
from hapticop.runtime.region import Region


def process_main(tree: dict, flags: list[str], region_name: str, thread: str, run_dir: str, seed: int,
                 messages) -> None:
    """The parent hands over the validated tree as plain data and the flag list, so this process
    neither parses YAML nor builds the graph again: it starts in a fraction of the time."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    loaded = load_tree(tree)
    region = Region.attach(layout_of(loaded, flags), region_name)
    clock = RealtimeClock()
    writer = LogWriter(Path(run_dir), echo=sys.stderr).start()
    built = build(loaded, region, [thread], clock, writer, seed, apply_realtime=True)
    realtime.prepare_process([loaded.composition.threads[thread]], writer.logger("system", Level.INFO, clock.now_ns))
    index = region.layout.thread_index[thread]
    loop = built.threads[thread]
    loop.supervisor = _LiveChanges(loop, built, loaded, region, index, messages)
    try:
        while not region.go[index] and not region.system[Region.TERMINATE]:
            time.sleep(0.001)  # created early; runs once the mediator starts the thread
        spec = loaded.composition.threads[thread]
        start = first_deadline(int(region.system[Region.EPOCH_NS]), spec.period, phases(loaded.composition)[thread],
                               clock.now_ns())
        built.threads[thread].run_realtime(start, lambda: False)
    finally:
        writer.stop()
        del built
        region.close()


class _LiveChanges:
    """Applies the parent's live changes between two cycles of this process's thread."""

    def __init__(self, loop, built, loaded, region: Region, index: int, messages):
        self.loop, self.built, self.loaded, self.region, self.index, self.messages = \
            loop, built, loaded, region, index, messages
        self.seen = 0

    def __call__(self) -> None:
        if self.region.control[self.index] == self.seen:
            return  # the common case: one memory read
        self.seen = int(self.region.control[self.index])
        while self.messages.poll():
            kind, *args = self.messages.recv()
            if kind == "params":
                name, params = args
                runner = self.built.runners[name]
                runner.block.params = runner.block.context.params = type(runner.block.params).model_validate(params)
            elif kind == "schedules":
                self.loop.replace_schedules({int(k): v for k, v in args[0].items()})
            elif kind == "max_age":
                reader, max_age = args
                activity, port = reader.split(".")
                getattr(self.built.runners[activity].block.inputs, port).max_age_ns = max_age
