"""The base of every block: declarations first, behaviour in the life-cycle hooks.

A block type is a class. Its class attributes declare the interface the validator checks
(`Params`, `inputs`, `outputs`, `flags_written`, `flags_read`, `rate`); a block whose
port shapes depend on its parameters overrides `interface(params)` instead.

At run time the runtime makes one instance per activity and calls its hooks from the
activity's Life Cycle State Machine, on the activity's thread, in this order:

    create -> configure_resources -> configure_capabilities -> compute (each cycle while
    running) / pausing (each cycle while paused) ... -> clean

A device block may split its cycle like a PLC scan: `compute` reads the device (a status
frame, the slaves' inputs) and publishes what it read, and `flush` writes the device once
every activity of the thread's schedule has computed, with its inputs refreshed, so what the
cycle computed from this cycle's readings leaves in the same cycle instead of the next.

Every hook is optional and succeeds by default. A configuration hook returns `False` to be
called again next cycle (waiting for a device, a flag), anything else to say it is complete;
a hook that raises puts the activity in a reported failed state and the mediator decides
what follows. `compute` is the time-critical step: it reads `self.inputs`, writes
`self.outputs` and publishes them, and must not allocate, block or log synchronously.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import TYPE_CHECKING, ClassVar

from hapticop.blocks.interface import Display, Interface, Need, Params, Port, RateRange
from hapticop.composition.diagnostics import Diagnostic

if TYPE_CHECKING:
    from hapticop.runtime.context import ActivityContext


class NoParams(Params):
    """For blocks that take no parameters."""


class Block:
    """A reusable unit of computation, instantiated as an activity by a composition."""

    Params: ClassVar[type[Params]] = NoParams
    inputs: ClassVar[dict[str, Port]] = {}
    outputs: ClassVar[dict[str, Port]] = {}
    flags_written: ClassVar[dict[str, str]] = {}
    flags_read: ClassVar[dict[str, str]] = {}
    awaits: ClassVar[frozenset[str]] = frozenset()  # read flags the block waits for: someone must write them
    # Read flags a composition may leave unbound (they stay false), so validation does not warn.
    optional_flags: ClassVar[frozenset[str]] = frozenset()
    rate: ClassVar[RateRange | None] = None
    # Parameters a live patch may change with only capability configuration (a calibration, a
    # homing offset); a change to any other parameter takes the activity through resource
    # configuration. Gains and limits belong in `running_params`.
    capability_params: ClassVar[frozenset[str]] = frozenset()
    # A block that only simulates (the hallway world): all its compute counts as simulation.
    simulator: ClassVar[bool] = False
    # Parameters a live patch changes between two cycles without taking the activity out of
    # running (gains, limits, modes): the block reads them each cycle, or rebuilds what depends
    # on them in `retune`.
    running_params: ClassVar[frozenset[str]] = frozenset()
    # Dotted parameters that restate the period of the thread running the block, in seconds (a
    # discretisation step): validation refuses a composition where they disagree.
    period_params: ClassVar[frozenset[str]] = frozenset()
    # Parameters that name another activity this one needs, with what that activity must provide
    # (`{"simulator": "falcon_device"}`); a parameter left None needs nothing.
    needs: ClassVar[dict[str, str]] = {}
    # What this block offers to activities that need it ("falcon_device", "hallway").
    provides: ClassVar[frozenset[str]] = frozenset()
    # Why the block must run alone in a process of its own at normal scheduling (a network session and
    # its threads, which must not share a GIL with the loops), or None; validation keeps it so.
    own_process: ClassVar[str | None] = None

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

    @classmethod
    def declare(cls, params: Params) -> Interface:
        """Everything the block declares for these parameters: its `interface` (which a block may
        override), completed with the activities it needs and what it provides."""
        return dataclasses.replace(cls.interface(params), needs=cls.needs_of(params), provides=cls.provides)

    @classmethod
    def preflight(cls, params: Params, timeout_s: float) -> str | None:
        """What the activity needs from outside the program and cannot find (a device on USB, a
        network interface, a sensor answering at its address), in words; None when all is there.

        Asked of every activity before anything of the run is made, all at once and each on a
        thread of its own, so a run on a machine without its hardware stops at once with one
        message. It may block, at most `timeout_s`; it must leave the device as it found it.
        """
        return None

    @classmethod
    def findings(cls, params: Params, folder: Path | None) -> list[Diagnostic]:
        """What is wrong with these parameters that their model alone cannot say, such as a file they
        name (a scene) read from `folder` (the composition's): each finding's path is under the
        activity's `params`, or it is already located in the file it blames. Asked by validation."""
        return []

    @classmethod
    def promises(cls, params: Params) -> tuple[str, ...]:
        """Files an activity that ran leaves in the run directory when it cleans (its results: a
        recording, metrics, a picture). A run that ends without one of them has lost results, and
        its exit status says so."""
        return ()

    @classmethod
    def displays(cls, params: Params) -> tuple[Display, ...]:
        """What observation may draw from this activity's outputs in Foxglove (the scan, the robot's
        frames, a force arrow), beside the raw streams; drawn only from streams a run records or shows."""
        return ()

    @classmethod
    def needs_of(cls, params: Params) -> tuple[Need, ...]:
        """The activities these parameters name, from the `needs` declaration."""
        found = []
        for param, provides in cls.needs.items():
            name = getattr(params, param, None)
            if name is not None:
                field_info = type(params).model_fields.get(param)
                found.append(Need(param, name, provides, (field_info.description or "") if field_info else ""))
        return tuple(found)

    def __init__(self, context: ActivityContext):
        self.context = context
        self.name = context.name
        self.params = context.params
        self.inputs = context.inputs
        self.outputs = context.outputs
        self.flags = context.flags
        self.clock = context.clock
        self.log = context.log
        self.rng = context.rng
        self.run_dir = context.run_dir

    # -- life-cycle hooks: override only what the block needs ---------------------------
    def create(self) -> bool | None:
        """Allocate the activity's own bookkeeping."""

    def configure_resources(self) -> bool | None:
        """Acquire what the activity needs from others: a socket, a device, a flag."""

    def configure_capabilities(self) -> bool | None:
        """Prepare its own capabilities before serving: homing, calibration."""

    def compute(self) -> None:
        """One cycle of the service, while running. Time-critical."""

    def flush(self) -> None:
        """While running, after the whole schedule computed: write the device (time-critical).
        Overriding it makes the runtime refresh the block's inputs and call it each cycle."""

    def wakeup_fds(self) -> tuple[int, ...]:
        """File descriptors whose incoming data should start a cycle of a `wake: data` thread at
        once (a connected device socket); asked before each wait, so they may change."""
        return ()

    def pausing(self) -> None:
        """One cycle while paused: hold outputs safe, ready to resume at once."""

    def clean(self) -> bool | None:
        """Release everything the other hooks acquired."""

    def retune(self, changed: frozenset[str]) -> None:
        """New `running_params` arrived (already in `self.params`): rebuild what depends on the
        `changed` ones, keeping the state that makes the change bumpless (filter memories,
        integrators). Called on the activity's thread between two of its cycles; it may allocate,
        since it runs once per patch, not once per cycle."""

    @classmethod
    def implements_compute(cls) -> bool:
        return cls.compute is not Block.compute

    @classmethod
    def implements_flush(cls) -> bool:
        return cls.flush is not Block.flush
