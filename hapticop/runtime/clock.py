"""Two clocks with one interface: the wall clock, and simulated time for deterministic runs.

The real-time clock sleeps to absolute deadlines with `clock_nanosleep(CLOCK_MONOTONIC,
TIMER_ABSTIME)`, so a late wake-up never shifts the following deadlines. The virtual clock
is advanced by the scheduler that steps every thread in a fixed order; nothing sleeps.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import errno
import time

CLOCK_MONOTONIC = 1
TIMER_ABSTIME = 1


class _Timespec(ctypes.Structure):
    _fields_ = [("tv_sec", ctypes.c_long), ("tv_nsec", ctypes.c_long)]


def _load_nanosleep():
    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6", use_errno=True)
        function = libc.clock_nanosleep
    except (OSError, AttributeError):
        return None
    function.argtypes = [ctypes.c_int, ctypes.c_int, ctypes.POINTER(_Timespec), ctypes.POINTER(_Timespec)]
    function.restype = ctypes.c_int
    return function


class RealtimeClock:
    """CLOCK_MONOTONIC in nanoseconds, with absolute sleeps."""

    virtual = False

    def __init__(self) -> None:
        self._nanosleep = _load_nanosleep()
        self._request = _Timespec()  # reused: sleeping allocates nothing
        self._request_ref = ctypes.byref(self._request)

    @staticmethod
    def now_ns() -> int:
        return time.monotonic_ns()

    def sleep_until(self, deadline_ns: int) -> None:
        if self._nanosleep is None:
            remaining = deadline_ns - time.monotonic_ns()
            if remaining > 0:
                time.sleep(remaining / 1e9)
            return
        self._request.tv_sec, self._request.tv_nsec = divmod(deadline_ns, 1_000_000_000)
        while self._nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, self._request_ref, None) == errno.EINTR:
            pass  # a signal (Ctrl+C) woke us: the deadline is absolute, so just sleep again


    @staticmethod
    def spin_until(deadline_ns: int) -> None:
        """Busy-wait the last stretch: no scheduler wake-up latency, at the price of a busy core."""
        now = time.monotonic_ns
        while now() < deadline_ns:
            pass


class VirtualClock:
    """Simulated time: set by the scheduler, read by everyone."""

    virtual = True

    def __init__(self, start_ns: int = 0) -> None:
        self._now = start_ns

    def now_ns(self) -> int:
        return self._now

    def advance_to(self, t_ns: int) -> None:
        if t_ns < self._now:
            raise ValueError("virtual time never goes backwards")
        self._now = t_ns

    def sleep_until(self, deadline_ns: int) -> None:
        self.advance_to(max(deadline_ns, self._now))

    spin_until = sleep_until
