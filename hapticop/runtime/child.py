"""The entry point of a thread deployed in its own process.

The child rebuilds the composition from its text, attaches to the parent's shared region
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
from hapticop.runtime.region import Region
from hapticop.yamlsource import parse_text


def process_main(text: str, file: str, region_name: str, thread: str, run_dir: str, seed: int) -> None:
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    loaded = load_tree(parse_text(text, file).tree)
    region = Region.attach(layout_of(loaded), region_name)
    clock = RealtimeClock()
    writer = LogWriter(Path(run_dir), echo=sys.stderr).start()
    built = build(loaded, region, [thread], clock, writer, seed, apply_realtime=True)
    realtime.prepare_process([loaded.composition.threads[thread]], writer.logger("system", Level.INFO, clock.now_ns))
    index = region.layout.thread_index[thread]
    try:
        while not region.go[index] and not region.system[Region.TERMINATE]:
            time.sleep(0.001)  # created early; runs once the mediator starts the thread
        built.threads[thread].run_realtime(clock.now_ns() + 1_000_000, lambda: False)
    finally:
        writer.stop()
        del built
        region.close()
