"""A port's declared range checked on a sample, leaving nothing allocated: where a command is read or arrives.

A command port declares `range` (`hapticop.blocks.interface.Port`): every element must be finite
and inside it. A port without a range is taken as it is: a scan's ranges say "no return" with an
infinity, which is data, not a fault. The reader that executes the command (the governor, the
platform controller) and the bridge that receives it from another host check each new sample here,
refuse a bad one (it is not executed, not passed on) and follow the next good one. Refusals are
counted, and said once per burst: the first bad sample of a burst is logged, and the burst's length
when a good one follows.
"""

from __future__ import annotations

import logging

import numpy as np

from hapticop.blocks.interface import Port

SHORT = 16
"""A vector up to this long is checked element by element as Python floats: for a twist or a force that
is several times faster than three ufunc calls and a reduction, whose fixed cost is per call."""


class Bounds:
    """The check of one port's samples (finite and inside its declared range), with its counts."""

    def __init__(self, port: Port, what: str) -> None:
        self.what = what  # for the log: the port or stream it guards
        self.range = port.range
        self._short = len(port.shape) == 1 and port.shape[0] <= SHORT
        self._ok = np.zeros(port.shape, dtype=bool)
        self._also = np.zeros(port.shape, dtype=bool)
        self.refused = 0  # every sample refused so far
        self.burst = 0  # refused since the last good one

    @property
    def checks(self) -> bool:
        """Whether anything is checked at all (a port without a range is taken as it is)."""
        return self.range is not None

    def admits(self, value: np.ndarray) -> bool:
        """True for a sample to follow; False (counted) for one to refuse. NaN fails every comparison."""
        if self.range is None:
            return True
        low, high = self.range
        if self._short:
            for element in value.tolist():
                if not low <= element <= high:
                    break
            else:
                return True
        else:
            ok = self._ok
            np.greater_equal(value, low, out=ok)
            np.less_equal(value, high, out=self._also)
            np.logical_and(ok, self._also, out=ok)
            if ok.all():
                return True
        self.refused += 1
        self.burst += 1
        return False

    def said(self, log: logging.Logger | logging.LoggerAdapter, good: bool) -> None:
        """Log a burst of refusals once: at its first sample, and its length when a good sample ends it."""
        if not good and self.burst == 1:
            log.warning("%s: a sample not finite or outside %s refused (not executed, not passed on)",
                        self.what, "its range [{:g}, {:g}]".format(*self.range))
        elif good and self.burst:
            log.info("%s: following again after %d refused sample(s)", self.what, self.burst)
            self.burst = 0


class Refusals:
    """What a receiver refused of one stream, by reason, said once per burst (the first refusal with its
    reason; the burst's length when a good one ends it). Off the 1 kHz loops: a reason is a string."""

    def __init__(self) -> None:
        self.by_reason: dict[str, int] = {}
        self.total = 0
        self.burst = 0

    def count(self, why: str) -> None:
        self.by_reason[why] = self.by_reason.get(why, 0) + 1
        self.total += 1
        self.burst += 1

    def said(self, log, what: str, why: str | None) -> None:
        if why is not None and self.burst == 1:
            log.warning("%s: refused a sample (%s); refusals are counted in 'refused' until a good one", what, why)
        elif why is None and self.burst:
            log.info("%s: a good one again after %d refused", what, self.burst)
            self.burst = 0
