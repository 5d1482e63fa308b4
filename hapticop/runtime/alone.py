"""One activity alone: its block on the runtime's own runner and life cycle, in a region of its own.

The block harness and a replay drive a block as a run does (inputs refreshed, the LCSM stepped
with its requests and failures, the flush, parameters handed over between steps) through the
same `ActivityRunner`, never by calling its hooks themselves, so what they judge is what a run
does. The activity is on no thread and reads no stream: the caller connects its input ports to
transports it writes, adds transports to its outputs, and advances the clock.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from hapticop.blocks.base import Block
from hapticop.composition import flags as flagdefs
from hapticop.composition.lcsm import State
from hapticop.runtime.assembly import make_context
from hapticop.runtime.context import ActivityContext
from hapticop.runtime.logs import Logger
from hapticop.runtime.region import Layout, Region
from hapticop.runtime.thread import ActivityRunner


class _Private:
    """The region's memory, private to this process: nobody else attaches to one activity alone."""

    def __init__(self, size: int) -> None:
        self.buf = memoryview(bytearray(size))
        self.name = ""

    def close(self) -> None:
        return None


@dataclass
class Alone:
    """The runner, its region and what its block sees."""

    runner: ActivityRunner
    region: Region
    context: ActivityContext

    @property
    def block(self) -> Block:
        return self.runner.block

    @property
    def state(self) -> State:
        return self.runner.state

    def failure(self) -> BaseException | None:
        """The error a hook raised in the last step, taken (the runner only logs it)."""
        error, self.runner.lifecycle.error = self.runner.lifecycle.error, None
        return error

    def close(self) -> None:
        self.region.close()


def alone(name: str, block_type: type[Block], params, clock, run_dir: Path, rng: np.random.Generator,
          log: Logger, runtime_log: Logger, *, period_ns: int = 0, start_on_request: bool = False) -> Alone:
    """The block built on its own runner; `log` is what the block says, `runtime_log` what its life
    cycle says (state changes, failures). Its context is built as a run builds one
    (`assembly.make_context`), over a one-activity layout."""
    interface = block_type.declare(params)
    layout = Layout.alone(name, list(flagdefs.activity_flags(name, interface.flags_written, interface.flags_read)))
    region = Region(layout, _Private(layout.size), owner=False)  # type: ignore[arg-type]
    region.state[:] = State.CREATION
    context, cycle = make_context(name, interface, params, region, clock, log, rng, run_dir, period_ns)
    block = block_type(context)
    return Alone(ActivityRunner(name, block, region, start_on_request, runtime_log, cycle=cycle), region, context)
