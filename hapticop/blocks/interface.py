"""What a block promises to the composition: its ports, flags, parameters and rates.

Blocks know nothing of each other. Each one declares typed ports (dtype, shape, unit),
the flags it writes and reads, the parameter model it accepts and the cycle rates it can
run at; the composition wires them, and the validator checks the wiring against these
declarations before anything runs.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import ClassVar

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, model_validator
from pydantic_core import PydanticCustomError


@dataclass(frozen=True)
class Port:
    """One typed slot of a block's activity state: what flows through a stream.

    `dtype` is a numpy dtype name, `shape` the array shape (`()` for a scalar) and `unit`
    an SI unit symbol (`m`, `N`, `m/s`, `rad`, `A`; `1` for dimensionless). An input that
    is not `required` may stay unconnected; the block then sees its initial value.

    `range` (low, high) bounds every element of a port that carries a command: a sample with an
    element outside it, or not finite, is refused where it is read (`hapticop.blocks.bounds`) and by
    the bridge that receives it from another host; it is not executed and not passed on.
    """

    dtype: str
    shape: tuple[int, ...] = ()
    unit: str = "1"
    doc: str = ""
    required: bool = True
    range: tuple[float, float] | None = None

    def __post_init__(self) -> None:
        np.dtype(self.dtype)  # fail at import time on a typo, not during validation
        if self.range is not None and not self.range[0] <= self.range[1]:
            raise ValueError(f"port range {self.range}: low above high")

    def describe(self) -> str:
        return f"{self.dtype}{list(self.shape)} [{self.unit}]"

    @property
    def nbytes(self) -> int:
        return int(np.dtype(self.dtype).itemsize * int(np.prod(self.shape, dtype=np.int64)))


@dataclass(frozen=True)
class RateRange:
    """The cycle rates, in Hz, at which a block's computation is valid."""

    min_hz: float
    max_hz: float
    why: str = ""

    def admits(self, period_ns: int) -> bool:
        hz = 1e9 / period_ns
        slack = 1e-6 * hz  # periods are whole nanoseconds: 15 Hz is 66666667 ns
        return self.min_hz - slack <= hz <= self.max_hz + slack

    def describe(self) -> str:
        if self.min_hz == self.max_hz:
            return f"{self.min_hz:g} Hz"
        return f"{self.min_hz:g} to {self.max_hz:g} Hz"


@dataclass(frozen=True)
class Display:
    """A picture a viewer such as Foxglove can draw from some of this block's outputs: `kind` names
    it (`laser_scan`, `frames`, `force_arrow`), `ports` gives each of its roles the block's output
    port that plays it, `options` the figures it needs that only the block knows (a mount, a
    heading). Observation builds it from the recorded streams of those ports, whatever they are called."""

    kind: str
    ports: dict[str, str]
    options: dict[str, float | tuple[float, ...]] = field(default_factory=dict)


@dataclass(frozen=True)
class Need:
    """Another activity this one works with outside the streams, named by one of its parameters.

    A device block whose `driver` is a simulator needs the activity that simulates the device
    (it talks to it over a link, in the device's own bytes); a simulated device needs the world
    it lives in. Validation checks that the named activity is declared and that its block
    `provides` what is needed, and `hapticop graph` draws the relation.
    """

    param: str  # the parameter that names the other activity (where a finding points)
    activity: str  # its value: the other activity's name
    provides: str  # what the other activity's block must provide, e.g. "falcon_device"
    why: str = ""


@dataclass(frozen=True)
class Interface:
    """A block's declarations once its parameters are known (shapes may depend on them)."""

    inputs: dict[str, Port] = field(default_factory=dict)
    outputs: dict[str, Port] = field(default_factory=dict)
    flags_written: dict[str, str] = field(default_factory=dict)
    flags_read: dict[str, str] = field(default_factory=dict)
    rate: RateRange | None = None
    needs: tuple[Need, ...] = ()
    provides: frozenset[str] = frozenset()
    # Inputs that are alternatives (the same thing in two forms, e.g. a raw scan or one rendered beside
    # the loop): exactly one of each group is connected. Validation says so, located.
    one_of: tuple[tuple[str, ...], ...] = ()
    # Parameters that configure one input alone (None: its default): set while that input is unconnected
    # they would do nothing (the value that counts is declared elsewhere), which validation refuses, located.
    input_params: dict[str, str] = field(default_factory=dict)


class Params(BaseModel):
    """Base of every block's parameter model: unknown keys are mistakes, not extensions, and
    every number is finite unless its field allows NaN or infinity itself."""

    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)


class DeviceParams(Params):
    """A device block's parameters: the `driver` that reaches the device (each block declares its
    own, the real one first and its default) and, with driver 'sim', the activity simulating it.

    The simulator is named, never implied, so a composition for real hardware differs from the
    simulated one only by its simulation activities and its `driver:` fields.
    """

    simulated_by: ClassVar[str] = "a simulator"  # the built-in block that simulates it, for messages
    simulator: str | None = Field(None, description="with driver 'sim': the activity that simulates the device")

    @model_validator(mode="after")
    def _simulator_goes_with_sim(self) -> DeviceParams:
        driver = getattr(self, "driver", None)
        if driver == "sim" and self.simulator is None:
            raise PydanticCustomError(
                "sim_needs_simulator", "driver 'sim' needs 'simulator': the activity that simulates the device "
                "({block})", {"block": self.simulated_by})
        if driver != "sim" and self.simulator is not None:
            raise PydanticCustomError(
                "simulator_without_sim", "'simulator' goes with driver 'sim' only (the driver is '{driver}')",
                {"driver": driver})
        return self
