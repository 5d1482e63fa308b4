"""The standard observer: the composition's `record:`, `--record` and `--view`, behind `runtime.observer.Observer`.

It reserves the recorder's rings (`recording.plan`), starts the recorder (a process of its own on
the wall clock, drained between main cycles under the virtual clock), follows the streams a
patch adds, and stops it when the loops are done. With nothing to record and nothing to show it
starts nothing.
"""

from __future__ import annotations

import copy
import dataclasses
from pathlib import Path
from typing import Any

from hapticop.composition.description import Record
from hapticop.composition.loader import Loaded
from hapticop.observe import cycle_rings
from hapticop.observe.recorder import plan_of, recorded_ring
from hapticop.observe.recorder_process import InlineRecorder, RecorderProcess
from hapticop.recording.live import LiveOptions
from hapticop.recording.plan import recorded_streams
from hapticop.runtime.observer import ObservedRun
from hapticop.runtime.region import Transport


class Observation:
    """`record`: record every stream even if the file does not say so, to this file ('': the
    default); `view`: serve live to Foxglove the recorded streams (the latest slots if none is)."""

    def __init__(self, record: str | None = None, view: LiveOptions | None = None):
        self.record, self.view = record, view
        self.records = False  # to a file
        self.recorder: RecorderProcess | InlineRecorder | None = None
        self.run: ObservedRun | None = None

    def composition(self, tree: Any, loaded: Loaded) -> tuple[Any, Loaded]:
        self.records = self.record is not None or loaded.composition.record is not None
        if self.record is not None and loaded.composition.record is None:  # as if the file said `record: {}`
            tree = copy.copy(tree)
            tree["record"] = {"streams": "all"}
            loaded = dataclasses.replace(loaded, composition=loaded.composition.model_copy(update={"record": Record()}))
        return tree, loaded

    def rings(self, loaded: Loaded) -> dict[str, int]:
        if self.run is not None and not (self.records and self.recorder):  # added live, nothing recording
            return {}
        if self.run is not None:  # added live: streams only (an added activity gets no cycle ring)
            return {name: recorded.capacity for name, recorded in recorded_streams(loaded.composition).items()}
        return {**{name: recorded.capacity for name, recorded in recorded_streams(loaded.composition).items()},
                **cycle_rings.capacities(loaded)}

    def start(self, run: ObservedRun) -> None:
        self.run = run
        layout = run.region.layout
        if not layout.recorded and self.view is None:
            return
        path = None if not self.records else Path(self.record) if self.record else run.run_dir / f"{run.name}.mcap"
        plan = plan_of(run.loaded, layout, run.tree, run.file, path, run.virtual, run.seed, run.run_dir, self.view)
        self.recorder = (InlineRecorder(plan, run.region.memory.buf, run.clock) if run.virtual else
                         RecorderProcess(plan, run.region.name))

    def ready(self) -> list[str]:
        if self.recorder is None:
            return []
        log = self.run.log
        failed = self.recorder.wait_started()
        if failed:
            log.error(failed)
            self.recorder.stop()
            self.recorder = None
            return [failed]
        if self.recorder.view_error:
            log.error(self.recorder.view_error)
            return [self.recorder.view_error]
        if self.recorder.address:
            log.always("live view at %s (Foxglove: open a connection, Foxglove WebSocket)", self.recorder.address)
        return []

    def between_cycles(self) -> None:
        if self.recorder is not None and self.run.virtual:
            self.recorder.between_cycles()

    def stream_added(self, loaded: Loaded, stream: str, ring: Transport) -> None:
        self.recorder.add(recorded_ring(loaded, ring, recorded_streams(loaded.composition)[stream]))

    def event(self, kind: str, payload: dict, time_ns: int) -> None:
        if self.recorder is not None:
            self.recorder.event(kind, payload, time_ns)

    def stop(self) -> tuple[dict | None, str | None]:
        if self.recorder is None:
            return None, None
        recorder, self.recorder = self.recorder, None
        return recorder.stop()
