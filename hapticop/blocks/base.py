"""The base of every block: declarations first, behaviour in the life-cycle hooks.

A block type is a class. Its class attributes declare the interface the validator checks
(`Params`, `inputs`, `outputs`, `flags_written`, `flags_read`, `rate`); a block whose
port shapes depend on its parameters overrides `interface(params)` instead.
"""

from __future__ import annotations

from typing import ClassVar

from hapticop.blocks.interface import Interface, Params, Port, RateRange


class NoParams(Params):
    """For blocks that take no parameters."""


class Block:
    """A reusable unit of computation, instantiated as an activity by a composition."""

    Params: ClassVar[type[Params]] = NoParams
    inputs: ClassVar[dict[str, Port]] = {}
    outputs: ClassVar[dict[str, Port]] = {}
    flags_written: ClassVar[dict[str, str]] = {}
    flags_read: ClassVar[dict[str, str]] = {}
    rate: ClassVar[RateRange | None] = None

    @classmethod
    def interface(cls, params: Params) -> Interface:
        """The ports, flags and rate of this block for the given parameters."""
        return Interface(
            inputs=dict(cls.inputs),
            outputs=dict(cls.outputs),
            flags_written=dict(cls.flags_written),
            flags_read=dict(cls.flags_read),
            rate=cls.rate,
        )
