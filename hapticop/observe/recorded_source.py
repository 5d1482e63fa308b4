"""`recorded_source`: a recording's samples published again, each in the cycle that saw it in the run.

A replay rewrites the composition (`observe.rewrite`): the activities that fed the replayed one
give way to this block, which publishes on each output port the samples of one recorded stream.
Which samples are due is read from the replayed activity's recorded cycles (`runtime.cycle_log`):
in the cycle stepped at a recorded cycle's time, every sample up to the number that cycle's input
held after its step is published before the replayed activity steps, and, for one that flushes,
up to the number it held after its flush in this block's own flush. Each sample keeps its recorded
stamp, and since every sample is published in order the stream numbers them as the run did.

It publishes in whichever hook its life cycle calls (each returns at once, so it is configured in
the cycles the replayed activity is), and needs the virtual clock to stand at the recorded times.
It lives with observation, not with the blocks: it reads a recording.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
from pydantic import Field

from hapticop.blocks.base import Block
from hapticop.blocks.interface import Interface, Params, Port
from hapticop.recording.reading import series_of


class RecordedStream(Params):
    stream: str = Field(description="the recorded stream this port carries")
    dtype: str = Field(description="its samples' element type, as recorded")
    shape: tuple[int, ...] = Field((), description="its samples' shape, as recorded")
    unit: str = Field("1", description="its samples' unit (the reader's)")
    paced_by: str | None = Field(None, description="the replayed input whose recorded cycles say which samples are "
                                 "due when (none: the port publishes nothing; it connects the input of an activity "
                                 "only configured beside the replayed one)")


class RecordedSourceParams(Params):
    recording: str = Field(description="the MCAP recording the samples are read from")
    cycles: str = Field(description="the recorded cycles that say which samples are due when "
                                    "(`cycles/ACTIVITY`; their columns `step.PORT` and `flush.PORT`)")
    outputs: dict[str, RecordedStream] = Field(
        default_factory=dict, description="per output port: the recorded stream it publishes (the port is named "
                                          "after the replayed activity's input it feeds)")
    compared: dict[str, RecordedStream] = Field(
        default_factory=dict, description="per input port: a replayed output it reads back, only so that the "
                                          "output's stream has a reader (the replay records it and judges that)")


class _Feed:
    """One port's recorded samples, published in order up to a number."""

    def __init__(self, port, values: np.ndarray, stamps: np.ndarray, step: int, flush: int | None):
        self.port, self.values, self.stamps = port, values, stamps
        self.step, self.flush = step, flush  # the cycle rows' columns
        self.next = 0  # samples published: the next one's number is this plus one

    def up_to(self, number: int) -> None:
        end = min(int(number), len(self.values))
        port = self.port
        for i in range(self.next, end):
            port.value[...] = self.values[i]
            port.stamp_ns = int(self.stamps[i])
            port.publish()
        self.next = max(self.next, end)


class RecordedSource(Block):
    """Publishes a recording's samples at the cycles that saw them in the run (a replay's input)."""

    Params = RecordedSourceParams

    @classmethod
    def interface(cls, params: RecordedSourceParams) -> Interface:
        return Interface(
            inputs={port: Port(s.dtype, tuple(s.shape), s.unit, f"the replayed '{s.stream}', read back")
                    for port, s in params.compared.items()},
            outputs={port: Port(s.dtype, tuple(s.shape), s.unit, f"the recorded stream '{s.stream}'")
                     for port, s in params.outputs.items()})

    def create(self) -> bool:
        params = self.params
        paced = {port: s for port, s in params.outputs.items() if s.paced_by is not None}
        read = series_of(Path(params.recording), [params.cycles] + [s.stream for s in paced.values()])
        cycles = read[params.cycles]
        columns = {name: i for i, name in enumerate(json.loads(cycles.info.doc or "[]"))}
        self.times, self.rows = cycles.publish_ns, cycles.values
        self.row = 0  # the first cycle row not yet past
        self.feeds = [_Feed(getattr(self.outputs, port), read[s.stream].values, read[s.stream].publish_ns,
                            columns[f"step.{s.paced_by}"], columns.get(f"flush.{s.paced_by}"))
                      for port, s in paced.items()]
        self._emit("step")
        return True

    def configure_resources(self) -> bool:
        self._emit("step")
        return True

    def configure_capabilities(self) -> bool:
        self._emit("step")
        return True

    def compute(self) -> None:
        self._emit("step")

    def pausing(self) -> None:
        self._emit("step")

    def flush(self) -> None:
        self._emit("flush")

    def _emit(self, phase: str) -> None:
        """What the recorded cycle at this time had seen by its step (or flush), published."""
        now, times = self.context.clock.now_ns(), self.times
        i = self.row
        while i < len(times) and times[i] < now:
            i += 1
        self.row = i
        if i == len(times) or times[i] != now:
            return  # no recorded cycle now: the replayed activity is not stepped either
        row = self.rows[i]
        for feed in self.feeds:
            column = feed.step if phase == "step" else feed.flush
            if column is not None:
                feed.up_to(row[column])
