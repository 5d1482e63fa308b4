"""Each activity's cycles, recorded as the stream `cycles/ACTIVITY`: what a replay lines its inputs up by.

A wall-clock run misses cycles when it overruns, and its threads publish while others compute,
so the stamps alone cannot say which input sample a cycle saw. In a recorded run every step of
an activity writes one row: the LCSM state it stepped from, which of the parameter sets handed
to it the block held (`parameter_events`), its LCSM requests and its own flags as they were
before the step, and the number of the sample each input held after the step (a
queue's: the last popped) and, for a block that flushes, after the flush. The row's stamp is the
step's time (`context.CycleClock`), which its input ports judge `valid` and `age_ns()` by.
Writing it is a few copies between preallocated arrays, pushed into a recorder ring like any
stream's sample: nothing allocates on the cycle path.
"""

from __future__ import annotations

import json

import numpy as np

from hapticop.blocks.interface import Interface, Port
from hapticop.composition import lcsm

PREFIX = "cycles/"


def stream_of(activity: str) -> str:
    """The recorded stream of an activity's cycles."""
    return PREFIX + activity


def columns(interface: Interface, flushes: bool) -> list[str]:
    """What each element of a row is, in order (the stream's `doc` says it, as JSON)."""
    flags = list(interface.flags_written) + list(interface.flags_read)
    return (["state", "parameters"] + [f"request.{r}" for r in lcsm.REQUEST_FLAGS] + [f"flag.{f}" for f in flags]
            + [f"step.{p}" for p in interface.inputs] + ([f"flush.{p}" for p in interface.inputs] if flushes else []))


def port_of(interface: Interface, flushes: bool) -> Port:
    names = columns(interface, flushes)
    return Port("int64", (len(names),), "1", json.dumps(names))


class CycleLog:
    """One activity's row, filled as its runner steps and pushed when the cycle is done."""

    def __init__(self, activity: str, interface: Interface, flushes: bool, ring, flags: np.ndarray,
                 states: np.ndarray, owner_index: int, flag_index: dict[str, int], inputs: list, cycle,
                 parameters: np.ndarray) -> None:
        self.ring, self.flags, self.cycle = ring, flags, cycle
        self.row = np.zeros(len(columns(interface, flushes)), np.int64)
        names = [f"{activity}.lcsm.{r}" for r in lcsm.REQUEST_FLAGS] + [
            f"{activity}.{f}" for f in list(interface.flags_written) + list(interface.flags_read)]
        self.flag_indices = np.array([flag_index[n] for n in names], np.intp)
        self.flag_values = np.zeros(len(names), np.uint8)
        self.flag_row = self.row[2:2 + len(names)]
        self.state = states[owner_index:owner_index + 1]
        self.state_row = self.row[0:1]
        self.parameters, self.parameters_row = parameters, self.row[1:2]
        first = 2 + len(names)
        n = len(inputs)
        self.step_pairs = [(self.row[first + i:first + i + 1], port.meta[0:1]) for i, port in enumerate(inputs)]
        self.flush_pairs = ([(self.row[first + n + i:first + n + i + 1], port.meta[0:1])
                             for i, port in enumerate(inputs)] if flushes else [])
        self.stamp = 0

    def before(self) -> None:
        """The state, requests and flags the step starts from, and its time."""
        self.stamp = self.cycle.now
        np.copyto(self.state_row, self.state)
        np.take(self.flags, self.flag_indices, out=self.flag_values)
        np.copyto(self.flag_row, self.flag_values)

    def stepped(self) -> None:
        np.copyto(self.parameters_row, self.parameters)  # taken at the step's start, before its hook
        for row, meta in self.step_pairs:
            np.copyto(row, meta)

    def flushed(self) -> None:
        for row, meta in self.flush_pairs:
            np.copyto(row, meta)

    def push(self) -> None:
        self.ring.push(self.row, self.stamp)
