"""A stream's latest slot read like a recorder ring: what the live view shows when nothing is recorded.

A display needs each stream's newest sample a few dozen times a second, not every sample: the
seqlock slot every `latest` stream already has holds it, and any number of readers may read it
without waiting and without the writer knowing. So a live view without a recording gives the
loops nothing more to do (no ring to push into), and `hapticop view` can watch a system that was
started without thinking of it. A `LatestTap` hands the recorder's drain the newest sample once,
as a one-sample batch, so the recorder's views and outputs serve it unchanged. A stream with
`queue` rings has no slot, and each ring has exactly one reader: it is not tapped.
"""

from __future__ import annotations

import numpy as np

from hapticop.blocks.interface import Port
from hapticop.composition.loader import Loaded
from hapticop.recording.mcapfile import StreamInfo
from hapticop.recording.plan import writer_thread
from hapticop.runtime.streams import LatestSlot


class LatestTap:
    """A latest slot, drained like a ring: its newest sample, once, when it is new."""

    def __init__(self, buffer, port: Port):
        self.slot = LatestSlot(buffer, port)
        self.value = np.zeros(port.shape, port.dtype)
        self.meta = np.zeros(2, np.int64)
        self.newest = 0  # the number of the last sample taken
        self.taken = 0

    @property
    def written(self) -> int:
        return self.slot.count

    @property
    def dropped(self) -> int:
        return 0  # the samples between two looks are not lost: they are in no need of showing

    def drain_into(self, out: np.ndarray) -> int:
        if not self.slot.read_into(self.value, self.meta) or int(self.meta[0]) == self.newest:
            return 0
        self.newest = int(self.meta[0])
        self.taken += 1
        out["seq"][0] = out["count"][0] = self.newest
        out["stamp_ns"][0] = self.meta[1]
        out["payload"][0] = self.value.reshape(-1).view(np.uint8)
        return 1

    def close(self) -> None:
        self.slot.close()


def tapped_streams(loaded: Loaded, layout) -> list[tuple[StreamInfo, int, int]]:
    """Every stream with a latest slot: its description, and where its slot lies (offset, bytes)."""
    composition = loaded.composition
    found = []
    for name, spec in composition.streams.items():
        transports = layout.transports.get(name, [])
        if not transports or transports[0].kind != "latest":
            continue
        activity, port_name = spec.writer.split(".")
        port = loaded.activities[activity].interface.outputs[port_name]
        thread = writer_thread(composition, name)
        rate_hz = 1e9 / composition.threads[thread].period if thread else 0.0
        info = StreamInfo(name, np.dtype(port.dtype).name, tuple(port.shape), port.unit, rate_hz, 1, spec.writer,
                          tuple(spec.readers), spec.doc or port.doc)
        found.append((info, transports[0].offset, transports[0].nbytes))
    return found
