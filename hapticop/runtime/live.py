"""Changing a running system: a validated patch's plan, applied at a cycle boundary.

The control thread checks what the plan asks against what this runtime can do without a
restart (`check`), then hands it to the main thread, whose supervisor applies it between
two cycles (`apply`): changed parameters take their activity through resource or
capability configuration, changed schedules take effect from the next cycle, removed
activities are cleaned, added ones start their life cycle in the spare room of the region.
Threads in their own process receive their share over a pipe, noticed through a counter
in the region so that their loop makes no system call to look.
"""

from __future__ import annotations

from dataclasses import dataclass
from threading import Event
from typing import TYPE_CHECKING

from hapticop.composition import flags as flagdefs
from hapticop.composition.description import Composition
from hapticop.composition.diagnostics import Diagnostic
from hapticop.composition.loader import ResolvedActivity
from hapticop.runtime.assembly import make_runner, make_transports, thread_of
from hapticop.validation.changes import ChangePlan
from hapticop.validation.patches import PatchError

if TYPE_CHECKING:
    from hapticop.runtime.system import System

RESTART = "restart the system to change it"


@dataclass
class PendingPatch:
    plan: ChangePlan
    composition: Composition
    tree: object
    resolved: dict[str, ResolvedActivity]
    applied: Event
    error: str = ""


def _refuse(path: tuple, message: str) -> Diagnostic:
    return Diagnostic(rule="patch-unsupported", message=f"{message}; {RESTART}", path=path)


def check(system: "System", plan: ChangePlan, new: Composition) -> dict[str, ResolvedActivity]:
    """Resolve what the plan needs, or raise PatchError for what cannot change live."""
    problems: list[Diagnostic] = []
    resolved: dict[str, ResolvedActivity] = {}
    new_owner = thread_of(new)
    for name in list(plan.params) + list(plan.added_activities):
        spec = new.activities[name]
        old = system.loaded.activities.get(name)
        block = old.block if old else system.resolve_block(spec.block)
        params = block.Params.model_validate(spec.params)
        resolved[name] = ResolvedActivity(name, spec, block, params, block.interface(params))
        if old and resolved[name].interface != old.interface:
            problems.append(_refuse(("activities", name, "params"), f"the new parameters change the ports of '{name}'"))
    for name in plan.added_activities:
        thread = new_owner.get(name)
        if thread and new.threads[thread].deploy == "process":
            problems.append(_refuse(("activities", name), f"'{name}' would run in thread '{thread}', which has its "
                                    "own process; activities are added live only to threads of the main process"))
    for stream in plan.added_streams + plan.removed_streams:
        spec = (new.streams.get(stream) or system.composition.streams[stream])
        ends = [spec.writer] + spec.readers
        for end in ends:
            thread = new_owner.get(end.split(".")[0]) or system.owner_thread.get(end.split(".")[0])
            if thread and new.threads[thread].deploy == "process" and not system.virtual:
                problems.append(_refuse(("streams", stream), f"stream '{stream}' reaches thread '{thread}', which "
                                        "has its own process"))
                break
    if problems:
        raise PatchError(problems)
    return resolved


def apply(system: "System", pending: PendingPatch) -> None:
    """On the main thread, between cycles."""
    plan, new = pending.plan, pending.composition
    old = system.composition
    for name, resolved in pending.resolved.items():
        if name in plan.params:
            _new_params(system, name, resolved)
    for name in plan.removed_activities:
        system.set_flag(f"{name}.lcsm.request_cleaning")
    for name in plan.removed_streams:
        _disconnect(system, old.streams[name])
    system.composition = new
    system.loaded.composition = new
    for name in plan.added_activities:
        _add_activity(system, name, pending.resolved[name], new)
    for name in plan.added_streams:
        _connect(system, name, new)
    for name in plan.changed_streams:
        spec = new.streams[name]
        for reader in spec.readers:
            runner = system.built.runners.get(reader.split(".")[0])
            if runner is not None:
                getattr(runner.block.inputs, reader.split(".")[1]).max_age_ns = spec.max_age or 0
            else:
                system.send(system.owner_thread[reader.split(".")[0]], ("max_age", reader, spec.max_age or 0))
    for thread, schedules in plan.schedules.items():
        if thread in system.built.threads:
            system.built.threads[thread].replace_schedules(schedules)
        else:
            system.send(thread, ("schedules", schedules))
    system.owner_thread = thread_of(new)
    system.tree = pending.tree
    for line in plan.describe():
        system.log.always("patch: %s", line)


def _new_params(system: "System", name: str, resolved: ResolvedActivity) -> None:
    old = system.loaded.activities[name]
    changed = {k for k in type(resolved.params).model_fields if getattr(resolved.params, k) != getattr(old.params, k)}
    if changed <= old.block.running_params:
        request = None  # read every cycle: the next cycle uses them
    elif changed <= old.block.capability_params | old.block.running_params:
        request = "request_capability_configuration"
    else:
        request = "request_resource_configuration"
    runner = system.built.runners.get(name)
    if runner is not None:
        runner.block.params = runner.block.context.params = resolved.params
    else:
        system.send(system.owner_thread[name], ("params", name, resolved.spec.params))
    system.loaded.activities[name] = resolved
    if request is not None:
        system.set_flag(f"{name}.lcsm.{request}")


def _add_activity(system: "System", name: str, resolved: ResolvedActivity, new: Composition) -> None:
    iface = resolved.interface
    flag_names = list(flagdefs.activity_flags(name, iface.flags_written, iface.flags_read))
    system.layout.add_activity(name, flag_names)
    system.loaded.activities[name] = resolved
    runner = make_runner(name, resolved, new, system.region, {}, system.clock, system.writer, system.options.seed)
    system.built.runners[name] = runner
    thread = thread_of(new).get(name)
    if thread is not None:
        system.built.threads[thread].runners[name] = runner


def _connect(system: "System", stream: str, new: Composition) -> None:
    spec = new.streams[stream]
    objects = make_transports(system.loaded, system.region, stream, thread_of(new), allocate=True)
    writer_activity, writer_port = spec.writer.split(".")
    writer = system.built.runners.get(writer_activity)
    if writer is not None:
        getattr(writer.block.outputs, writer_port).transports.extend(objects)
    for index, reader in enumerate(spec.readers):
        activity, port = reader.split(".")
        runner = system.built.runners.get(activity)
        if runner is None:
            continue
        target = getattr(runner.block.inputs, port)
        queue = spec.policy.kind == "queue"
        target.connect(objects[index] if queue else objects[0], queue, spec.max_age or 0)


def _disconnect(system: "System", spec) -> None:
    writer_activity, writer_port = spec.writer.split(".")
    for reader in spec.readers:
        activity, port = reader.split(".")
        runner = system.built.runners.get(activity)
        if runner is not None:
            target = getattr(runner.block.inputs, port)
            stale = target.transport
            target.disconnect()
            writer = system.built.runners.get(writer_activity)
            if writer is not None and stale is not None:
                output = getattr(writer.block.outputs, writer_port)
                output.transports = [t for t in output.transports if t is not stale]
