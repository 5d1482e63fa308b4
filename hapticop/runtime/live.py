"""Changing a running system: a validated patch's plan, applied at a cycle boundary.

The control thread checks what the plan asks against what this runtime can do without a
restart (`check`), then hands it to the main thread, which applies it between two cycles
(`apply`): changed parameters take their activity through resource or capability
configuration, changed schedules take effect from the next cycle, removed activities are
cleaned, added ones start their life cycle in the spare room of the region. Threads in
their own process receive their share over a pipe, noticed through a counter in the
region so that their loop makes no system call to look. A patch reaches the system only
through `LiveTarget`; the new description replaces the old one whole, last.
"""

from __future__ import annotations

import threading
from collections import deque
from dataclasses import dataclass
from typing import Protocol

from hapticop.composition import flags as flagdefs
from hapticop.composition.description import Composition, Stream
from hapticop.composition.diagnostics import Diagnostic
from hapticop.composition.loader import Loaded, ResolvedActivity
from hapticop.composition.units import format_duration
from hapticop.recording.plan import recorded_streams
from hapticop.runtime import parameter_events
from hapticop.runtime.assembly import thread_of
from hapticop.runtime.described import Description
from hapticop.runtime.logs import Logger
from hapticop.runtime.region import Layout
from hapticop.runtime.streams import RecorderRing, latest_nbytes, queue_nbytes
from hapticop.runtime.thread import ActivityRunner, CyclicThread
from hapticop.validation.changes import ChangePlan
from hapticop.validation.patches import PatchError, prepare

RESTART = "restart the system to change it"


class LiveTarget(Protocol):
    """What a live patch may touch of a running system."""

    description: Description
    virtual: bool
    log: Logger
    layout: Layout  # the region's layout, whose spare room live additions take

    @property
    def runners(self) -> dict[str, ActivityRunner]: ...

    @property
    def threads(self) -> dict[str, CyclicThread]: ...

    def send(self, thread: str, message: tuple) -> None:
        """A change for a thread of another process."""

    def set_flag(self, name: str, value: bool = True) -> None: ...

    def new_runner(self, name: str, resolved: ResolvedActivity, composition: Composition) -> ActivityRunner:
        """An added activity's block, its flags and LCSM given room in the region."""

    def new_transports(self, loaded: Loaded, stream: str, owner: dict[str, str]) -> list:
        """An added stream's buffers, taken from the region's spare room."""


@dataclass
class PendingPatch:
    plan: ChangePlan
    composition: Composition
    tree: object
    resolved: dict[str, ResolvedActivity]
    applied: threading.Event
    diff: str = ""
    error: str = ""


def _refuse(path: tuple, message: str) -> Diagnostic:
    return Diagnostic(rule="patch-unsupported", message=f"{message}; {RESTART}", path=path)


def check(target: LiveTarget, plan: ChangePlan, loaded: Loaded) -> dict[str, ResolvedActivity]:
    """What the plan needs of the patched composition (its activities as validation resolved
    them), or PatchError for what cannot change live."""
    problems: list[Diagnostic] = []
    resolved: dict[str, ResolvedActivity] = {}
    current, new = target.description, loaded.composition
    new_owner = thread_of(new)
    for name in list(plan.params) + list(plan.added_activities):
        resolved[name] = loaded.activities[name]
        old = current.activities.get(name)
        if old and resolved[name].interface != old.interface:
            problems.append(_refuse(("activities", name, "params"), f"the new parameters change the ports of '{name}'"))
    for name in plan.added_activities:
        thread = new_owner.get(name)
        if thread and new.threads[thread].deploy == "process":
            problems.append(_refuse(("activities", name), f"'{name}' would run in thread '{thread}', which has its "
                                    "own process; activities are added live only to threads of the main process"))
    for stream in plan.added_streams + plan.removed_streams:
        spec = (new.streams.get(stream) or current.composition.streams[stream])
        ends = [spec.writer] + spec.readers
        for end in ends:
            thread = new_owner.get(end.split(".")[0]) or current.owner_thread.get(end.split(".")[0])
            if thread and new.threads[thread].deploy == "process" and not target.virtual:
                problems.append(_refuse(("streams", stream), f"stream '{stream}' reaches thread '{thread}', which "
                                        "has its own process"))
                break
    lacking = _room_lacking(target, plan, loaded)
    if lacking:
        problems.append(_refuse(("activities",) if plan.added_activities else ("streams",), lacking))
    if problems:
        raise PatchError(problems)
    return resolved


def _room_lacking(target: LiveTarget, plan: ChangePlan, loaded: Loaded) -> str | None:
    """What the region's spare room lacks for the plan's additions, given those already made."""
    flags = {}
    for name in plan.added_activities:
        iface = loaded.activities[name].interface
        flags[name] = list(flagdefs.activity_flags(name, iface.flags_written, iface.flags_read))
    buffers, rings = [], []
    recorded = recorded_streams(loaded.composition)  # a recorded run's added streams get a recorder ring each
    for name in plan.added_streams:
        spec = loaded.composition.streams[name]
        writer_activity, writer_port = spec.writer.split(".")
        port = loaded.activities[writer_activity].interface.outputs[writer_port]
        if spec.policy.kind == "latest":
            buffers.append(latest_nbytes(port))
        else:
            buffers.extend(queue_nbytes(port, spec.policy.capacity) for _ in spec.readers)
        if name in recorded:
            rings.append(queue_nbytes(port, recorded[name].capacity))
    lacking = target.layout.room_for(flags, buffers + rings)
    if lacking and rings and target.layout.room_for(flags, buffers) is None:
        lacking += ": the recorder's rings of the new streams would not fit ('record.depth' sets their length)"
    return lacking


def apply(target: LiveTarget, pending: PendingPatch) -> None:
    """On the main thread, between cycles."""
    plan = pending.plan
    old = target.description
    new = old.patched(pending.tree, pending.composition, pending.resolved)
    lacking = _room_lacking(target, plan, new.loaded)  # patches prepared together may not all fit
    if lacking:
        raise PatchError([_refuse(("activities",) if plan.added_activities else ("streams",), lacking)])
    for name, resolved in pending.resolved.items():
        if name in plan.params:
            _new_params(target, old, name, resolved)
    for name in plan.removed_activities:
        target.set_flag(f"{name}.lcsm.request_cleaning")
    for name in plan.removed_streams:
        _disconnect(target, name, old.composition.streams[name])
    for name in plan.added_activities:
        runner = target.new_runner(name, pending.resolved[name], new.composition)
        thread = new.owner_thread.get(name)
        if thread is not None:
            target.threads[thread].runners[name] = runner
    for name in plan.added_streams:
        _connect(target, name, new)
    for name in plan.changed_streams:
        spec = new.composition.streams[name]
        for reader in spec.readers:
            runner = target.runners.get(reader.split(".")[0])
            if runner is not None:
                getattr(runner.block.inputs, reader.split(".")[1]).max_age_ns = spec.max_age or 0
            else:
                target.send(old.owner_thread[reader.split(".")[0]], ("max_age", reader, spec.max_age or 0))
    for thread, schedules in plan.schedules.items():
        if thread in target.threads:
            target.threads[thread].replace_schedules(schedules)
        else:
            target.send(thread, ("schedules", schedules))
    target.description = new
    for line in plan.describe():
        target.log.always("patch: %s", line)


def _new_params(target: LiveTarget, old: Description, name: str, resolved: ResolvedActivity) -> None:
    """Running parameters reach the block between two of its cycles; others re-configure it."""
    was = old.activities[name]
    changed = frozenset(k for k in type(resolved.params).model_fields
                        if getattr(resolved.params, k) != getattr(was.params, k))
    if changed <= was.block.running_params:
        request = None
    elif changed <= was.block.capability_params | was.block.running_params:
        request = "request_capability_configuration"
    else:
        request = "request_resource_configuration"
    retune(target, old, name, resolved.params, changed if request is None else frozenset())
    if request is not None:  # a re-configuration rebuilds it all
        target.set_flag(f"{name}.lcsm.{request}")


def retune(target: LiveTarget, description: Description, name: str, params, changed: frozenset[str]) -> None:
    """Give an activity new parameters, wherever it runs; it takes them before its next step and
    retunes what depends on the `changed` ones."""
    parameter_events.landed(target.log, name, params, changed)
    runner = target.runners.get(name)
    if runner is not None:
        runner.retune(params, changed)
    else:
        target.send(description.owner_thread[name], ("params", name, params.model_dump(mode="json"), sorted(changed)))


def _connect(target: LiveTarget, stream: str, new: Description) -> None:
    spec = new.composition.streams[stream]
    objects = target.new_transports(new.loaded, stream, new.owner_thread)
    writer_activity, writer_port = spec.writer.split(".")
    writer = target.runners.get(writer_activity)
    if writer is not None:
        getattr(writer.block.outputs, writer_port).transports.extend(objects)
    for index, reader in enumerate(spec.readers):
        activity, port = reader.split(".")
        runner = target.runners.get(activity)
        if runner is None:
            continue
        queue = spec.policy.kind == "queue"
        getattr(runner.block.inputs, port).connect(objects[index] if queue else objects[0], queue, spec.max_age or 0)


def _disconnect(target: LiveTarget, name: str, spec: Stream) -> None:
    writer_activity, writer_port = spec.writer.split(".")
    writer = target.runners.get(writer_activity)
    if writer is not None:  # its record ends with it: the writer stops pushing into the recorder's ring
        output = getattr(writer.block.outputs, writer_port)
        output.transports = [t for t in output.transports if not (isinstance(t, RecorderRing) and t.stream == name)]
    for reader in spec.readers:
        activity, port = reader.split(".")
        runner = target.runners.get(activity)
        if runner is not None:
            port_in = getattr(runner.block.inputs, port)
            stale = port_in.transport
            port_in.disconnect()
            writer = target.runners.get(writer_activity)
            if writer is not None and stale is not None:
                output = getattr(writer.block.outputs, writer_port)
                output.transports = [t for t in output.transports if t is not stale]


class LiveChanges:
    """The patches of one running system: asked over the control socket, or scripted in its file."""

    def __init__(self, target: LiveTarget, name: str, reasons: list[str]):
        self.target, self.name, self.reasons = target, name, reasons  # name: the file's, for diffs
        self.pending: deque[PendingPatch] = deque()
        # (at, name, patch, prepared PendingPatch or None, the tree it was prepared on)
        patches = target.description.composition.patches
        self.scripted = sorted(((p.at, name, p, None, None) for name, p in patches.items()),
                               key=lambda item: (item[0], item[1]))

    def prepare(self, patch, patch_file: str = "<patch>", base=None) -> PendingPatch:
        """Apply and validate a patch against the running description (any thread), or against
        `base`, a (tree, composition) some earlier pending patch will leave."""
        current = self.target.description
        tree, composition = base or (current.tree, current.composition)
        prepared = prepare(tree, patch, old=composition, patch_file=patch_file, name=self.name)
        resolved = check(self.target, prepared.plan, prepared.loaded)
        return PendingPatch(prepared.plan, prepared.composition, prepared.tree, resolved, threading.Event(),
                            prepared.diff)

    def prepare_scripted(self) -> None:
        """Validate the scripted patches before any loop runs, each on the tree the one before
        leaves: validating takes about a second, which a 1 kHz main loop cannot spare. A patch
        whose base changed meanwhile (a live patch came between) is prepared again when due."""
        current = self.target.description
        tree, composition, prepared = current.tree, current.composition, []
        for at, name, scripted, _, _ in self.scripted:
            pending = None
            try:
                pending = self.prepare(scripted.patch, f"patches.{name}", base=(tree, composition))
            except PatchError:
                pass  # refused when due, with its reason
            prepared.append((at, name, scripted, pending, tree))
            if pending is not None:
                tree, composition = pending.tree, pending.composition
        self.scripted = prepared

    def apply_due(self, since_start_ns: int) -> None:
        """Between two main-thread cycles: the patches asked meanwhile, then a scripted one if due."""
        while self.pending:
            pending = self.pending.popleft()
            try:
                apply(self.target, pending)
            except Exception as error:  # noqa: BLE001 - reported to the client, the system runs on
                pending.error = f"{type(error).__name__}: {error}"
                self.target.log.error("patch not applied: %s", pending.error)
            pending.applied.set()
        if self.scripted and since_start_ns >= self.scripted[0][0]:
            self._apply_scripted(self.scripted.pop(0))

    def _apply_scripted(self, item) -> None:
        at, name, scripted, pending, base = item
        log = self.target.log
        try:
            if pending is None or base is not self.target.description.tree:
                pending = self.prepare(scripted.patch, patch_file=f"patches.{name}")
            apply(self.target, pending)
            log.always("scripted patch '%s' applied at %s", name, format_duration(at))
        except PatchError as error:
            message = f"scripted patch '{name}' refused: {error.diagnostics[0].message}"
            self.reasons.append(message)
            log.error(message)
