"""Small generic blocks for building and testing compositions: a counter and an echo.

They exercise every part of the runtime (ports, streams, flags, life cycle) without any
device, and make good probes in a new composition.
"""

from __future__ import annotations

from typing import Literal

import numpy as np
from pydantic import Field

from hapticop.blocks.base import Block
from hapticop.blocks.interface import Interface, Params, Port


class CounterParams(Params):
    step: int = Field(1, description="added every cycle while running")
    stop_after: int | None = Field(None, ge=1, description="raise 'reached' (and running_complete) at this count")
    fail_at: int | None = Field(None, ge=1, description="raise an error at this count (to test failure handling)")


class Counter(Block):
    """Counts its running cycles and publishes the count."""

    Params = CounterParams
    outputs = {"count": Port("int64", (), "1", "cycles counted so far")}
    flags_written = {"reached": "the count reached stop_after"}
    capability_params = frozenset({"step", "stop_after"})

    def create(self) -> None:
        self.count = 0

    def compute(self) -> bool:
        self.count += self.params.step
        if self.params.fail_at is not None and self.count >= self.params.fail_at:
            raise RuntimeError(f"counter reached fail_at={self.params.fail_at}")
        self.outputs.count.value[...] = self.count
        self.outputs.count.publish()
        if self.params.stop_after is not None and self.count >= self.params.stop_after:
            self.flags["reached"] = True
            return True
        return False


class EchoParams(Params):
    dtype: Literal["int64", "float64", "float32", "uint8"] = Field("int64", description="the samples' element type")
    shape: tuple[int, ...] = Field((), description="the samples' shape (() for a scalar)")
    unit: str = Field("1", description="the samples' unit")


class Echo(Block):
    """Republishes every new input sample; counts what it received."""

    Params = EchoParams
    received = 0  # a count to read from the first moment, also before its thread has created it

    @classmethod
    def interface(cls, params: EchoParams) -> Interface:
        port = Port(params.dtype, params.shape, params.unit)
        return Interface(inputs={"input": port}, outputs={"output": port})

    def create(self) -> None:
        self.received = 0

    def compute(self) -> None:
        source = self.inputs.input
        while source.queue and source.pop() or not source.queue and source.fresh:
            self.received += 1
            np.copyto(self.outputs.output.value, source.value)
            self.outputs.output.publish()
            if not source.queue:
                break
