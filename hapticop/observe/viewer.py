"""`hapticop view SYSTEM`: the live view of a system already running, from a process of its own.

The running system's control socket tells where its shared region is and the tree its children
lay the region out from (`attach`); this process maps the region read-only in spirit and reads
what any reader may read without taking it from anyone: each stream's latest slot (a stream
with queue rings is skipped: a ring has exactly one reader), the loops' timing counters and the
run's log files, through the recorder's own drain, views and live output (`taps`), at the
display rate, at normal scheduling: what `compose --view` does when nothing is recorded. Nothing
of the running system changes.
"""

from __future__ import annotations

import os
import time
from collections.abc import Callable
from dataclasses import dataclass
from multiprocessing import resource_tracker, shared_memory
from pathlib import Path

from hapticop.composition.loader import load_tree
from hapticop.observe.event_channels import EventPlan
from hapticop.observe.recorder import RecordedRing, Recorder, RecorderPlan, rings_of, sources_of
from hapticop.observe.taps import tapped_streams
from hapticop.observe.timing_channels import TimingPlan
from hapticop.recording.live import LiveOptions
from hapticop.recording.scene import views_for
from hapticop.runtime.assembly import layout_of


@dataclass
class Attachment:
    """What the control socket's `attach` answers."""

    region: str
    flags: list[str]
    tree: dict
    rings: dict[str, int]  # the recorder rings the run reserved, to lay the region out as it did
    run_dir: str
    pid: int
    name: str


def view(attachment: Attachment, options: LiveOptions, announce: Callable[[str], None] = print,
         should_stop: Callable[[], bool] = lambda: False) -> dict:
    """Serve the running system live until it ends or `should_stop()`; the summary."""
    loaded = load_tree(attachment.tree)
    layout = layout_of(loaded, attachment.flags, attachment.rings)
    memory = shared_memory.SharedMemory(name=attachment.region, create=False)
    resource_tracker.unregister(memory._name, "shared_memory")  # noqa: SLF001 - the system's to unlink, never ours
    rings = [RecordedRing(info, offset, nbytes, 1, "latest") for info, offset, nbytes in tapped_streams(loaded, layout)]
    plan = RecorderPlan(None, rings, "CLOCK_MONOTONIC", views=views_for(loaded, [r.info.name for r in rings]),
                        live=options, timing=TimingPlan.of(loaded.composition, layout),
                        run_dir=Path(attachment.run_dir), name=attachment.name, events=EventPlan.of(layout))
    taps = rings_of(plan, memory.buf)
    sources = recorder = None
    try:
        sources = sources_of(plan, memory.buf)
        recorder = Recorder(plan, taps, time.monotonic_ns, sources)
        announce(f"{attachment.name}: live view at {recorder.address} ({len(taps)} streams)")
        while not should_stop() and _alive(attachment.pid):
            recorder.drain()
            time.sleep(plan.drain_ns / 1e9)
        return recorder.finish()
    finally:
        recorder = sources = None  # their views into the region go first
        for tap in taps.values():
            tap.close()
        taps = None
        memory.close()


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True
