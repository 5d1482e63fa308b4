"""Changing a running system: a validated patch's plan, applied at a cycle boundary.

The control thread checks what the plan asks against what this runtime can do without a
restart (`check`) and decides, per activity, whether new parameters are retuned in place or
take it through configuration again (`Effect`), so that a dry run can say so. It then hands the
patch to the main thread, which applies it between two cycles (`apply`): changed schedules take
effect from the next cycle, removed activities are cleaned, added ones start their life cycle
in the spare room of the region. Threads in their own process receive their share over a pipe,
noticed through a counter in the region so that their loop makes no system call to look.

A patch means what its reply says (docs/running.md, "Live patches"):
- it is applied whole or not at all: what can fail (building an added activity) is done
  before anything running changes, and undone if it fails;
- it lands only on the description it was prepared on (compare-and-swap on the description's
  tree): one prepared before another change landed is prepared again, never applied over that
  change, so no change undoes another;
- a patch whose client gave up, or one still waiting at shutdown, is cancelled under the lock
  the main thread takes it with: it was either applied and is reported so, or it never is.
A patch reaches the system only through `LiveTarget`; the new description replaces the old one
whole, last.
"""

from __future__ import annotations

import threading
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Protocol

from hapticop.composition import flags as flagdefs
from hapticop.composition.description import Composition, Stream
from hapticop.composition.diagnostics import Diagnostic
from hapticop.composition.loader import Loaded, ResolvedActivity
from hapticop.composition.units import format_duration
from hapticop.runtime import parameter_events
from hapticop.runtime.assembly import thread_of
from hapticop.runtime.described import Description
from hapticop.runtime.logs import Logger
from hapticop.runtime.region import Layout
from hapticop.runtime.streams import RecorderRing
from hapticop.runtime.thread import ActivityRunner, CyclicThread
from hapticop.runtime.transport import connect_reader, transport_of
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

    def rings(self, loaded: Loaded) -> dict[str, int]:
        """The recorder rings the run's observer would give these streams (capacity per stream)."""


class StaleBase(Exception):
    """The running description is no longer the one the patch was prepared on."""


@dataclass(frozen=True)
class Effect:
    """What new parameters do to a running activity, decided when the patch is prepared."""

    changed: frozenset[str]
    request: str | None  # None: retuned in place; else the LCSM request that re-configures it

    def describe(self, name: str) -> str:
        fields = ", ".join(sorted(self.changed)) or "no field"
        if self.request is None:
            return f"activity '{name}': retuned in place ({fields})"
        stage = "capability" if self.request == "request_capability_configuration" else "resource"
        return f"activity '{name}': reconfigured: stops and restarts {name} ({stage} configuration, for {fields})"


def effects(base: Description, plan: ChangePlan, resolved: dict[str, ResolvedActivity]) -> dict[str, Effect]:
    """Per activity whose parameters change: retuned while it runs, or re-configured (which stops it)."""
    found = {}
    for name in plan.params:
        was, now = base.activities[name], resolved[name]
        changed = frozenset(k for k in type(now.params).model_fields
                            if getattr(now.params, k) != getattr(was.params, k))
        block = was.block
        if changed <= block.running_params:
            request = None
        elif changed <= block.capability_params | block.running_params:
            request = "request_capability_configuration"
        else:
            request = "request_resource_configuration"
        found[name] = Effect(changed, request)
    return found


WAITING, APPLYING, APPLIED, FAILED, CANCELLED, STALE = "waiting", "applying", "applied", "failed", "cancelled", "stale"


@dataclass
class PendingPatch:
    """A prepared patch on its way to the main thread, and what became of it (`outcome`, then `done`)."""

    plan: ChangePlan
    composition: Composition
    tree: object
    resolved: dict[str, ResolvedActivity]
    base: Description  # the description it was prepared on: it applies to that one only
    effects: dict[str, Effect]
    diff: str = ""
    error: str = ""
    outcome: str = WAITING
    done: threading.Event = field(default_factory=threading.Event, repr=False)
    _lock: threading.Lock = field(default_factory=threading.Lock, repr=False)

    def changes(self) -> list[str]:
        """The plan's lines, and each parameter change said as retuned in place or reconfigured."""
        return self.plan.describe() + [effect.describe(name) for name, effect in self.effects.items()]

    def take(self) -> bool:
        """The main thread's claim; False when the patch was cancelled meanwhile (it is then skipped)."""
        with self._lock:
            if self.outcome != WAITING:
                return False
            self.outcome = APPLYING
            return True

    def cancel(self, why: str) -> bool:
        """Withdraw a patch the main thread has not taken; False when it has (then wait for `done`)."""
        with self._lock:
            if self.outcome != WAITING:
                return False
            self.outcome, self.error = CANCELLED, why
        self.done.set()
        return True

    def finish(self, outcome: str, error: str = "") -> None:
        with self._lock:
            self.outcome, self.error = outcome, error
        self.done.set()


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
    recorded = target.rings(loaded)  # a recorded run's added streams get a recorder ring each
    for name in plan.added_streams:
        transport = transport_of(loaded, name)
        buffers.extend(nbytes for nbytes, _ in transport.buffers())
        if name in recorded:
            rings.append(transport.ring_nbytes(recorded[name]))
    lacking = target.layout.room_for(flags, buffers + rings)
    if lacking and rings and target.layout.room_for(flags, buffers) is None:
        lacking += ": the recorder's rings of the new streams would not fit ('record.depth' sets their length)"
    return lacking


def apply(target: LiveTarget, pending: PendingPatch) -> None:
    """On the main thread, between cycles: all of the patch, or (raising) none of it."""
    plan = pending.plan
    old = target.description
    if old.tree is not pending.base.tree:
        raise StaleBase("the system changed since the patch was prepared")
    new = old.patched(pending.tree, pending.composition, pending.resolved)
    lacking = _room_lacking(target, plan, new.loaded)  # patches prepared together may not all fit
    if lacking:
        raise PatchError([_refuse(("activities",) if plan.added_activities else ("streams",), lacking)])
    runners = _build_added(target, plan, pending, new)  # what may fail, before anything running changes
    for name, effect in pending.effects.items():
        retuned = effect.changed if effect.request is None else frozenset()  # a re-configuration rebuilds it all
        retune(target, old, name, pending.resolved[name].params, retuned)
        if effect.request is not None:
            target.set_flag(f"{name}.lcsm.{effect.request}")
    for name in plan.removed_activities:
        target.set_flag(f"{name}.lcsm.request_cleaning")
    for name in plan.removed_streams:
        _disconnect(target, name, old.composition.streams[name])
    for name, runner in runners.items():
        thread = new.owner_thread.get(name)
        if thread is not None:
            target.threads[thread].add_runner(name, runner)
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
    for line in pending.changes():
        target.log.always("patch: %s", line)


def _build_added(target: LiveTarget, plan: ChangePlan, pending: PendingPatch,
                 new: Description) -> dict[str, ActivityRunner]:
    """The added activities' blocks, built but not yet scheduled. If one cannot be built, those built
    before it are dropped, their room in the region is given back, and the error propagates."""
    mark = target.layout.mark()
    runners: dict[str, ActivityRunner] = {}
    try:
        for name in plan.added_activities:
            runners[name] = target.new_runner(name, pending.resolved[name], new.composition)
    except BaseException:
        for name in plan.added_activities:
            target.runners.pop(name, None)
        target.layout.rollback(mark)
        raise
    return runners


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
        connect_reader(spec, getattr(runner.block.inputs, port), objects, index)


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

    ATTEMPTS = 3  # a live patch prepared again at most this often when other changes keep landing first

    def __init__(self, target: LiveTarget, name: str, reasons: list[str]):
        self.target, self.name, self.reasons = target, name, reasons  # name: the file's, for diffs
        self.pending: deque[PendingPatch] = deque()
        self.closed: str | None = None  # why no patch is taken any more (the system is shutting down)
        self._closing = threading.Lock()
        # (at, name, patch, prepared PendingPatch or None)
        patches = target.description.composition.patches
        self.scripted = sorted(((p.at, name, p, None) for name, p in patches.items()),
                               key=lambda item: (item[0], item[1]))

    def prepare(self, patch, patch_file: str = "<patch>", base: Description | None = None) -> PendingPatch:
        """Apply and validate a patch against the running description (any thread), or against
        `base`, the description some earlier pending patch will leave."""
        base = base or self.target.description
        prepared = prepare(base.tree, patch, old=base.composition, patch_file=patch_file, name=self.name)
        resolved = check(self.target, prepared.plan, prepared.loaded)
        return PendingPatch(prepared.plan, prepared.composition, prepared.tree, resolved, base,
                            effects(base, prepared.plan, resolved), prepared.diff)

    def ask(self, patch, patch_file: str, present: Callable[[], bool], timeout_s: float,
            settle_s: float = 30.0) -> PendingPatch:
        """A client's patch, prepared, handed to the main thread and waited for (the control thread).

        Its `outcome` is the truth: applied, failed, or cancelled (its client left, the main thread did
        not reach a cycle boundary within `timeout_s`, or the system is shutting down), in which case it
        never takes effect. One that the main thread took is waited for up to `settle_s` more. When
        another change landed first, it is prepared again on the description as it is now."""
        deadline = time.monotonic() + timeout_s
        pending = self.prepare(patch, patch_file)
        for _ in range(self.ATTEMPTS):
            self._hand_over(pending, present)
            self._await(pending, present, deadline, settle_s)
            if pending.outcome != STALE:
                return pending
            pending = self.prepare(patch, patch_file)
        pending.cancel(f"other changes landed first {self.ATTEMPTS} times; ask again")
        return pending

    def _hand_over(self, pending: PendingPatch, present: Callable[[], bool]) -> None:
        with self._closing:
            if self.closed:
                pending.cancel(self.closed)
            elif not present():
                pending.cancel("its client left before it was applied")
            else:
                self.pending.append(pending)

    @staticmethod
    def _await(pending: PendingPatch, present: Callable[[], bool], deadline: float, settle_s: float) -> None:
        while not pending.done.wait(0.05):
            if not present():
                why = "its client left before it was applied"
            elif time.monotonic() >= deadline:
                why = "the main thread did not reach a cycle boundary in time"
            else:
                continue
            if not pending.cancel(why):  # the main thread took it: it finishes, so wait for what happened
                pending.done.wait(settle_s)
            return

    def close(self, why: str) -> None:
        """No more patches: every one still waiting is cancelled with `why` (at shutdown)."""
        with self._closing:
            self.closed = why
            while self.pending:
                self.pending.popleft().cancel(why)

    def prepare_scripted(self) -> None:
        """Validate the scripted patches before any loop runs, each on the description the one before
        leaves: validating takes about a second, which a 1 kHz main loop cannot spare. A patch whose
        base changed meanwhile (a live patch came between) is prepared again when due."""
        base, prepared = self.target.description, []
        for at, name, scripted, _ in self.scripted:
            pending = None
            try:
                pending = self.prepare(scripted.patch, f"patches.{name}", base=base)
            except PatchError:
                pass  # refused when due, with its reason
            prepared.append((at, name, scripted, pending))
            if pending is not None:
                base = base.patched(pending.tree, pending.composition, pending.resolved)
        self.scripted = prepared

    def apply_due(self, since_start_ns: int) -> None:
        """Between two main-thread cycles: the patches asked meanwhile, then a scripted one if due."""
        while self.pending:
            pending = self.pending.popleft()
            if not pending.take():
                continue  # cancelled: its client was told it was not applied
            try:
                apply(self.target, pending)
            except StaleBase as error:
                pending.finish(STALE, str(error))
            except Exception as error:  # noqa: BLE001 - reported to the client, the system runs on
                message = f"{type(error).__name__}: {error}"
                self.target.log.error("patch not applied: %s", message)
                pending.finish(FAILED, message)
            else:
                pending.finish(APPLIED)
        if self.scripted and since_start_ns >= self.scripted[0][0]:
            self._apply_scripted(self.scripted.pop(0))

    def _apply_scripted(self, item) -> None:
        at, name, scripted, pending = item
        log = self.target.log
        try:
            if pending is None or pending.base.tree is not self.target.description.tree:
                pending = self.prepare(scripted.patch, patch_file=f"patches.{name}")
            apply(self.target, pending)
            log.always("scripted patch '%s' applied at %s", name, format_duration(at))
        except PatchError as error:
            message = f"scripted patch '{name}' refused: {error.diagnostics[0].message}"
            self.reasons.append(message)
            log.error(message)
        except Exception as error:  # noqa: BLE001 - a block that cannot be built: none of the patch, run on
            message = f"scripted patch '{name}' not applied: {type(error).__name__}: {error}"
            self.reasons.append(message)
            log.error(message)
