"""What a patch changes in a running system: two valid compositions compared into a plan.

The plan lists what the runtime does at a cycle boundary (new parameters, schedules,
activities and streams added or removed, a stream's `max_age`) and what it cannot do
without a restart, with the reason.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

from pydantic import BaseModel

from hapticop.composition.description import Composition
from hapticop.composition.diagnostics import Path
from hapticop.composition.units import format_duration

RESTART = "restart the system to change it"


@dataclass
class ChangePlan:
    """What differs between the running composition and the patched one."""

    params: dict[str, dict] = field(default_factory=dict)  # activity -> its new params (all of them)
    schedules: dict[str, dict[int, list[str]]] = field(default_factory=dict)  # thread -> its new schedules
    added_activities: list[str] = field(default_factory=list)
    removed_activities: list[str] = field(default_factory=list)
    added_streams: list[str] = field(default_factory=list)
    removed_streams: list[str] = field(default_factory=list)
    changed_streams: list[str] = field(default_factory=list)
    unsupported: list[tuple[Path, str]] = field(default_factory=list)  # (path, why it cannot change live)
    details: list[str] = field(default_factory=list, repr=False)  # filled by plan_changes for describe()

    @property
    def empty(self) -> bool:
        return not (self.params or self.schedules or self.added_activities or self.removed_activities
                    or self.added_streams or self.removed_streams or self.changed_streams or self.unsupported)

    def describe(self) -> list[str]:
        """One human-readable line per change; unsupported changes last."""
        lines = list(self.details)
        lines += [f"{_dotted(path)}: {reason}; {RESTART}" for path, reason in self.unsupported]
        return lines

    def to_json(self) -> dict:
        return {
            "params": plain_value(self.params),
            "schedules": {t: {str(i): list(a) for i, a in s.items()} for t, s in self.schedules.items()},
            "added_activities": list(self.added_activities),
            "removed_activities": list(self.removed_activities),
            "added_streams": list(self.added_streams),
            "removed_streams": list(self.removed_streams),
            "changed_streams": list(self.changed_streams),
            "unsupported": [{"path": _dotted(p), "reason": r} for p, r in self.unsupported],
            "describe": self.describe(),
        }


# Fields a running thread, activity or stream can change live; any other changed field
# (including fields added to the models later) is reported as unsupported.
_LIVE_THREAD_FIELDS = {"schedules", "doc"}
_LIVE_ACTIVITY_FIELDS = {"params", "doc"}
_LIVE_STREAM_FIELDS = {"max_age", "doc"}
_REASONS = {
    ("thread", "period"): "the period of a running thread cannot change live",
    ("thread", "priority"): "the priority of a running thread cannot change live",
    ("thread", "cpus"): "the CPU affinity of a running thread cannot change live",
    ("thread", "deploy"): "where a thread is deployed cannot change live",
    ("thread", "start"): "the start policy of a thread only matters at start",
    ("activity", "block"): "the block of a running activity cannot change live; "
                           "add an activity with a new name instead",
    ("activity", "start"): "the start policy of an activity only matters at start",
    ("stream", "writer"): "the endpoints of a running stream cannot change live; add a stream with a new name instead",
    ("stream", "readers"): "the endpoints of a running stream cannot change live; add a stream with a new name instead",
    ("stream", "policy"): "the connection policy of a running stream cannot change live",
}


def plan_changes(old: Composition, new: Composition) -> ChangePlan:
    """Compare two valid compositions; what the runtime cannot do live goes to `unsupported`."""
    plan = ChangePlan()
    say = plan.details.append

    if old.name != new.name:
        plan.unsupported.append((("name",), "the system's name fixes its control socket"))
    if old.record != new.record:
        plan.unsupported.append((("record",), "what a run records is fixed when it starts (its rings are in the "
                                 "shared region)"))

    for name in _added(old.threads, new.threads):
        plan.unsupported.append((("threads", name), "threads cannot be added to a running system"))
    for name in _added(new.threads, old.threads):
        plan.unsupported.append((("threads", name), "threads cannot be removed from a running system"))
    for name in _common(old.threads, new.threads):
        before, after = old.threads[name], new.threads[name]
        _unsupported_fields(plan, "thread", ("threads", name), before, after, _LIVE_THREAD_FIELDS)
        if before.schedules != after.schedules:
            plan.schedules[name] = {i: list(a) for i, a in after.schedules.items()}
            for schedule in sorted(set(before.schedules) | set(after.schedules)):
                was, now = before.schedules.get(schedule), after.schedules.get(schedule)
                if was != now:
                    say(f"thread '{name}': schedule {schedule} {_schedule(was, 'none')} -> {_schedule(now, 'removed')}")

    plan.added_activities = _added(old.activities, new.activities)
    plan.removed_activities = _added(new.activities, old.activities)
    for name in plan.added_activities:
        say(f"activity '{name}' added (block {new.activities[name].block})")
    for name in plan.removed_activities:
        say(f"activity '{name}' removed")
    for name in _common(old.activities, new.activities):
        before, after = old.activities[name], new.activities[name]
        _unsupported_fields(plan, "activity", ("activities", name), before, after, _LIVE_ACTIVITY_FIELDS)
        if _semantic(before.params) != _semantic(after.params) or _types(before.params) != _types(after.params):
            plan.params[name] = plain_value(after.params)
            say(f"activity '{name}': parameters {_param_changes(before.params, after.params)}")

    plan.added_streams = _added(old.streams, new.streams)
    plan.removed_streams = _added(new.streams, old.streams)
    for name in plan.added_streams:
        stream = new.streams[name]
        say(f"stream '{name}' added ({stream.writer} -> {', '.join(stream.readers) or 'nobody: watched only'})")
    for name in plan.removed_streams:
        say(f"stream '{name}' removed")
    for name in _common(old.streams, new.streams):
        before, after = old.streams[name], new.streams[name]
        if _semantic(before) == _semantic(after):
            continue
        plan.changed_streams.append(name)
        _unsupported_fields(plan, "stream", ("streams", name), before, after, _LIVE_STREAM_FIELDS)
        if before.max_age != after.max_age:
            say(f"stream '{name}': max_age {_duration(before.max_age)} -> {_duration(after.max_age)}")

    for name in sorted(set(old.modes) | set(new.modes)):
        if _semantic(old.modes.get(name)) != _semantic(new.modes.get(name)):
            what = "added" if name not in old.modes else "removed" if name not in new.modes else "changed"
            say(f"mode '{name}' {what}")  # taken up between two cycles (runtime/modes.py)

    _coordination_changes(plan, old, new)
    return plan


def _coordination_changes(plan: ChangePlan, old: Composition, new: Composition) -> None:
    reason = "the coordination (nets, flag maps, flags) cannot change live"
    before, after = old.coordination, new.coordination
    for name in _added(before.flags, after.flags):
        plan.unsupported.append((("coordination", "flags", name), f"a flag was added; {reason}"))
    for name in _added(after.flags, before.flags):
        plan.unsupported.append((("coordination", "flags", name), f"a flag was removed; {reason}"))
    for collection in ("nets", "flag_maps"):
        was, now = getattr(before, collection), getattr(after, collection)
        for name in sorted(set(was) | set(now), key=lambda n: (n not in now, n)):
            if _semantic(was.get(name)) != _semantic(now.get(name)):
                what = "added" if name not in was else "removed" if name not in now else "changed"
                plan.unsupported.append((("coordination", collection, name), f"{collection[:-1].replace('_', ' ')} "
                                         f"'{name}' {what}; {reason}"))


def _unsupported_fields(plan: ChangePlan, kind: str, path: Path, before: BaseModel, after: BaseModel,
                        live: set[str]) -> None:
    for name, info in type(before).model_fields.items():
        if name in live:
            continue
        if _semantic(getattr(before, name)) != _semantic(getattr(after, name)):
            reason = _REASONS.get((kind, name), f"the {name} of a running {kind} cannot change live")
            plan.unsupported.append((path + (info.alias or name,), reason))


def _added(before: Mapping, after: Mapping) -> list[str]:
    return [name for name in after if name not in before]


def _common(before: Mapping, after: Mapping) -> list[str]:
    return [name for name in after if name in before]


def _semantic(value: Any) -> Any:
    """Plain data for comparison, without 'doc' fields (they change nothing at run time)."""
    if isinstance(value, BaseModel):
        return {name: _semantic(getattr(value, name)) for name in type(value).model_fields if name != "doc"}
    if isinstance(value, Mapping):
        return {plain_value(k): _semantic(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_semantic(v) for v in value]
    return plain_value(value)


def _types(value: Any) -> Any:
    """The shape of a params tree with scalar types: so `true` -> `1` counts as a change."""
    if isinstance(value, Mapping):
        return {str(k): _types(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_types(v) for v in value]
    return type(plain_value(value)).__name__


def plain_value(value: Any) -> Any:
    """ruamel's round-trip types (CommentedMap, ScalarFloat...) as plain Python values."""
    if isinstance(value, Mapping):
        return {plain_value(k): plain_value(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [plain_value(v) for v in value]
    if isinstance(value, bool) or value is None:
        return value
    if isinstance(value, int):
        return bool(value) if type(value).__name__ == "ScalarBoolean" else int(value)
    if isinstance(value, float):
        return float(value)
    if isinstance(value, str):
        return str(value)
    return value


def show(value: Any) -> str:
    if value is None:
        return "null"
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, Mapping):
        return "{" + ", ".join(f"{k}: {show(v)}" for k, v in value.items()) + "}"
    if isinstance(value, list):
        return "[" + ", ".join(show(v) for v in value) + "]"
    return str(value)


def _flatten(params: Mapping, prefix: str = "") -> dict[str, Any]:
    flat: dict[str, Any] = {}
    for key, value in params.items():
        name = f"{prefix}{key}"
        if isinstance(value, Mapping) and value:
            flat.update(_flatten(value, name + "."))
        else:
            flat[name] = plain_value(value)
    return flat


_UNSET = object()


def _param_changes(before: Mapping, after: Mapping) -> str:
    was, now = _flatten(before), _flatten(after)
    changes = []
    for key in list(was) + [k for k in now if k not in was]:
        old_value, new_value = was.get(key, _UNSET), now.get(key, _UNSET)
        if old_value == new_value and type(old_value) is type(new_value):
            continue
        shown_old = "(default)" if old_value is _UNSET else show(old_value)
        shown_new = "(default)" if new_value is _UNSET else show(new_value)
        changes.append(f"{key} {shown_old} -> {shown_new}")
    return ", ".join(changes) or "rewritten"


def _schedule(activities: list[str] | None, missing: str) -> str:
    return f"({missing})" if activities is None else "[" + ", ".join(activities) + "]"


def _duration(ns: int | None) -> str:
    return "none" if ns is None else format_duration(ns)


def _dotted(path: Path) -> str:
    return ".".join(str(part) for part in path) or "<document>"
