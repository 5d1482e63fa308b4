# cython: boundscheck=False, wraparound=False, annotation_typing=False
"""The runtime's per-step bookkeeping on small integer arrays, bound once, for the compiled build.

Every activity step counts its compute time in a histogram, and merges its inputs' origin stamps
into its outputs' (end-to-end latencies). Each is a few numpy element or whole-array calls on arrays of
a handful of integers, which cost more than the work: about 2 us per step, all of it overhead, at 1 kHz
on every loop and at every simulated millisecond under the virtual clock. Compiled
(``tallies.pxd``), each is a C loop over arrays bound when the activity is built. Interpreted, this
module gives the same counts, only slower (``np.maximum.reduce`` stays the faster merge there).

Only these arrays are touched, never a stream's slots: the seqlocks between processes keep their
Python reads (``streams.py``), whose order the interpreter does not change.
"""

from __future__ import annotations

import importlib.machinery

COMPILED = __file__.endswith(tuple(importlib.machinery.EXTENSION_SUFFIXES))
"""Whether this module runs compiled."""


class Histograms:
    """Rows of 1 us histograms (``timing.BINS`` bins, the last one holds everything longer) and each
    row's exact maximum in ns, counted one duration at a time without allocating; a 1 kHz loop cannot
    keep a list of its latencies. Nothing is counted once ``closed[0]`` is set: the run is ending
    (``Region.ENDING``), and the shutdown is not the run."""

    def __init__(self, histogram, maximum, closed) -> None:
        if histogram.shape[0] != maximum.shape[0] or histogram.shape[1] < 1 or closed.shape[0] < 1:
            raise ValueError("a histogram row and a maximum for each counted thing, and the flag that closes them")
        self.histogram, self.maximum, self.closed = histogram, maximum, closed
        self.rows, self.bins = histogram.shape[0], histogram.shape[1]

    def count(self, index: int, value_ns: int) -> None:
        """Count one duration in row ``index`` (a negative one as 0, one past the last bin in it)."""
        if index < 0 or index >= self.rows:
            raise IndexError(f"row {index} of {self.rows}")
        if self.closed[0]:
            return
        us = value_ns // 1000
        if us < 0:
            us = 0
        if us >= self.bins:
            us = self.bins - 1
        self.histogram[index, us] += 1
        if value_ns > self.maximum[index]:
            self.maximum[index] = value_ns


class OriginMerge:
    """An activity's origin stamps: ``merge`` takes, per path, the newest stamp among its inputs' rows
    into ``newest`` and every output's row (``OriginRelay.before_step``)."""

    def __init__(self, inputs, newest, outputs) -> None:
        width = newest.shape[0]
        if inputs.shape[0] < 1 or inputs.shape[1] != width or outputs.shape[1] != width:
            raise ValueError("input and output rows as wide as the stamps they merge")
        self.inputs, self.newest, self.outputs = inputs, newest, outputs

    def merge(self) -> None:
        for j in range(self.newest.shape[0]):
            value = self.inputs[0, j]
            for i in range(1, self.inputs.shape[0]):
                if self.inputs[i, j] > value:
                    value = self.inputs[i, j]
            self.newest[j] = value
            for i in range(self.outputs.shape[0]):
                self.outputs[i, j] = value
