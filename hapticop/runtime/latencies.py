"""End-to-end latencies: how long data takes from where it enters to where it leaves.

A composition names its paths (`latencies: {handle_to_wheel: {from: falcon.position, to:
ethercat.wheel_commands}}`). Every sample carries one origin stamp per path: the source port
stamps it when it publishes, and each activity passes on the newest origin among its inputs
to everything it writes. When the sink's activity has stepped with an origin it has not
seen before, the time since that origin is counted in the path's histogram, so the figure
includes every hop, queue and cycle phase on the way and the sink's own step.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from hapticop.runtime import tallies
from hapticop.runtime.context import InputPort, OutputPort
from hapticop.runtime.region import Region
from hapticop.runtime.streams import ORIGINS
from hapticop.runtime.tallies import OriginMerge


class OriginRelay:
    """One activity's share: merge its inputs' origins into its outputs, time its sinks.

    The ports' origin stamps are rows of two arrays the relay owns, so the merge is one
    reduction and one broadcast copy per step, however many ports the activity has.
    """

    __slots__ = ("inputs", "outputs", "sinks", "region", "now_ns", "newest", "seen", "_in", "_out", "_merge",
                 "_e2e")

    def __init__(self, inputs: list[InputPort], outputs: list[OutputPort], sinks: list[tuple[InputPort, int]],
                 region: Region, now_ns: Callable[[], int]):
        self.inputs = [port for port in inputs if port.origins is not None]
        self.outputs = [port for port in outputs if port.origins is not None]
        self.sinks = sinks
        self.region, self.now_ns = region, now_ns
        self._in = np.zeros((max(1, len(self.inputs)), ORIGINS), dtype=np.int64)
        self._out = np.zeros((len(self.outputs), ORIGINS), dtype=np.int64)
        for rows, ports in ((self._in, self.inputs), (self._out, self.outputs)):
            for row, port in zip(rows, ports):
                row[:] = port.origins
                port.origins = row  # the port reads and publishes through its row from now on
        self.newest = np.zeros(ORIGINS, dtype=np.int64)
        self.seen = np.zeros(ORIGINS, dtype=np.int64)
        # Compiled, one loop over the few stamps; interpreted, numpy's two calls are the faster
        self._merge = OriginMerge(self._in, self.newest, self._out) if tallies.COMPILED else None
        self._e2e = region.histograms("e2e")

    def before_step(self) -> None:
        if self._merge is not None:
            self._merge.merge()
            return
        np.maximum.reduce(self._in, axis=0, out=self.newest)
        self._out[...] = self.newest

    def after_step(self) -> None:
        if not self.sinks:
            return
        seen, now = self.seen, self.now_ns()
        for port, slot in self.sinks:
            origin = int(port.origins[slot])
            if origin > seen[slot]:
                seen[slot] = origin
                self._e2e.count(slot, now - origin)
