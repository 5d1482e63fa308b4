"""From a patch document to a validated new description and a plan of live changes.

A running system is changed by a YAML patch: a JSON Patch (RFC 6902, a list of
operations) or a merge patch (RFC 7396, a mapping). The patch is applied to a copy of
the description, the whole result is checked exactly as `hapticop validate` checks a
file, and the two typed compositions are compared into a `ChangePlan` that says what
the runtime must do at a cycle boundary, or what it cannot do without a restart. Any
problem is a `PatchError` carrying located diagnostics; the running description is never
touched.

Names are mapping keys, so JSON Pointers such as `/activities/haptic/params/k1` stay
valid. Schedule IDs are YAML integers: a pointer segment such as `/threads/main/schedules/1`
addresses the integer key 1 (JSON Pointer segments are always text).
"""

from __future__ import annotations

import copy
import difflib
import io
import re
from collections.abc import Mapping, MutableMapping
from dataclasses import dataclass, field, replace
from typing import Any

import jsonpatch
from jsonpointer import JsonPointer, JsonPointerException
from pydantic import BaseModel
from ruamel.yaml.comments import CommentedMap, CommentedSeq

from hapticop.composition.description import Composition
from hapticop.composition.diagnostics import Diagnostic, Path, Severity
from hapticop.composition.loader import load_tree
from hapticop.validation import Validated, validate_source
from hapticop.validation.reachability import DEFAULT_STATE_LIMIT
from hapticop.composition.yamlsource import Source, SourceError, _reject_aliases_of_containers, _yaml, parse_text

OPERATIONS = ("add", "remove", "replace", "move", "copy", "test")
PATCH_EXPECTED = (
    "a JSON Patch (a list of operations such as '- {op: replace, path: /activities/haptic/params/k1, value: 30.0}') "
    "or a merge patch (a mapping shaped like the part of the description it changes)"
)
RESTART = "restart the system to change it"
_DUMP_WIDTH = 4096  # never fold long lines: diffs then show exactly the lines that changed


class PatchError(Exception):
    """The patch is refused as a whole; `diagnostics` says why, located where possible."""

    def __init__(self, diagnostics: list[Diagnostic], summary: str = ""):
        self.diagnostics = list(diagnostics)
        if not summary:
            errors = len(self.diagnostics)
            summary = (
                self.diagnostics[0].message
                if errors == 1
                else f"{errors} problems: " + "; ".join(d.message for d in self.diagnostics[:3])
                + ("; ..." if errors > 3 else "")
            )
        super().__init__(summary)

    def to_text(self) -> str:
        return "\n".join(d.to_text() for d in self.diagnostics)

    def to_json(self) -> list[dict]:
        return [d.to_json() for d in self.diagnostics]


# --- reading a patch ------------------------------------------------------------------


def load_patch(text: str, file: str = "<patch>") -> list | dict:
    """Parse a patch file: a list is a JSON Patch, a mapping a merge patch.

    Uses the composition reader's YAML settings (no duplicate keys, no recursive anchors,
    size limit) and its located diagnostics. Raises only `PatchError`.
    """
    try:
        return _load_patch(text, file)
    except PatchError:
        raise
    except SourceError as error:
        found = error.diagnostic
        if found.rule == "file-too-large":
            found = replace(found, message=found.message.replace("a composition", "a patch"), hint="")
        raise PatchError([found]) from None
    except Exception as error:  # noqa: BLE001 - the contract is "only PatchError"
        raise PatchError([Diagnostic(rule="patch-syntax", message=f"cannot read the patch: {error}", file=file)]) from None


def _load_patch(text: str, file: str) -> list | dict:
    try:
        patch: Any = parse_text(text, file).tree
    except SourceError as error:
        found = error.diagnostic
        if found.rule == "empty-file":
            raise PatchError(
                [Diagnostic(rule="patch-syntax", message="the patch is empty", expected=PATCH_EXPECTED,
                            file=file, line=1, column=1)]
            ) from None
        if found.rule != "top-level-type":
            raise
        patch = _yaml().load(text)  # the YAML itself was read once already: only its type was wrong
        if not isinstance(patch, CommentedSeq):
            raise PatchError(
                [Diagnostic(rule="patch-syntax", message=found.message.replace("a mapping", "a list or a mapping"),
                            expected=PATCH_EXPECTED, file=file, line=1, column=1)]
            ) from None
        _reject_aliases_of_containers(patch, file)
    check_patch(patch, file)
    return patch


def check_patch(patch: Any, file: str = "<patch>") -> None:
    """Check the shape of a patch (from a file or embedded in a composition) before applying it."""
    if isinstance(patch, Mapping):
        if "op" in patch and "path" in patch:
            line, column = _item_position(patch, None)
            raise PatchError(
                [Diagnostic(rule="patch-syntax", message="this mapping looks like one JSON Patch operation, "
                            "but a mapping is read as a merge patch", hint="write the operation as a list item: '- op: ...'",
                            file=file, line=line, column=column)]
            )
        return
    if not isinstance(patch, list):
        raise PatchError(
            [Diagnostic(rule="patch-syntax", message=f"a patch is a list or a mapping, not {type(patch).__name__}",
                        expected=PATCH_EXPECTED, file=file)]
        )
    found: list[Diagnostic] = []
    for index, op in enumerate(patch):
        line, column = _item_position(patch, index)

        def problem(message: str, member: str | None = None, expected: str = "") -> None:
            where = (line, column)
            if member is not None and isinstance(op, CommentedMap) and member in op:
                value_line, value_column = op.lc.value(member)
                where = (value_line + 1, value_column + 1)
            found.append(Diagnostic(rule="patch-syntax", message=f"operation {index}: {message}", expected=expected,
                                    path=(index,) if member is None else (index, member),
                                    file=file, line=where[0], column=where[1]))

        if not isinstance(op, Mapping):
            problem("an operation is a mapping with 'op' and 'path'", expected="op: add|remove|replace|move|copy|test")
            continue
        name = op.get("op")
        if name not in OPERATIONS:
            problem(f"unknown op {name!r}" if "op" in op else "missing 'op'", "op" if "op" in op else None,
                    expected=", ".join(OPERATIONS))
            continue
        for member in ("path", "from") if name in ("move", "copy") else ("path",):
            pointer = op.get(member)
            if member not in op:
                problem(f"'{name}' needs a '{member}' member")
            elif not isinstance(pointer, str) or (pointer and not pointer.startswith("/")):
                problem(f"'{member}' {pointer!r} is not a JSON Pointer", member,
                        expected="'' for the whole description, or a path such as /activities/haptic/params/k1")
        if name in ("add", "replace", "test") and "value" not in op:
            problem(f"'{name}' needs a 'value' member")
    if found:
        raise PatchError(found)


def _item_position(container: Any, index: int | None) -> tuple[int, int]:
    try:
        if index is None:
            return container.lc.line + 1, container.lc.col + 1
        line, column = container.lc.item(index)
        return line + 1, column + 1
    except (AttributeError, KeyError, IndexError, TypeError):
        return 0, 0


# --- applying a patch -----------------------------------------------------------------

_DECIMAL = re.compile(r"0|[1-9][0-9]*")


def _key_for(mapping: Any, key: Any) -> Any:
    """The mapping key a text segment means: '1' is the integer 1 among integer keys."""
    if isinstance(mapping, Mapping) and isinstance(key, str) and key not in mapping and _DECIMAL.fullmatch(key):
        number = int(key)
        if number in mapping or (mapping and all(isinstance(k, int) and not isinstance(k, bool) for k in mapping)):
            return number
    return key


class _Pointer(JsonPointer):
    """A JSON Pointer that reaches YAML integer keys (schedule IDs) from text segments."""

    def walk(self, doc: Any, part: Any) -> Any:
        return super().walk(doc, _key_for(doc, part))

    def to_last(self, doc: Any) -> tuple[Any, Any]:
        if not self.parts:
            return doc, None
        for part in self.parts[:-1]:
            doc = self.walk(doc, part)
        return doc, JsonPointer.get_part(doc, _key_for(doc, self.parts[-1]))


def apply_patch(tree: Mapping, patch: list | Mapping, *, file: str = "<patch>") -> CommentedMap:
    """Apply `patch` to a deep copy of `tree`; `tree` is never modified.

    A list is applied as RFC 6902 JSON Patch, one operation after another; a mapping as
    RFC 7396 merge patch (null deletes a key; mappings merge; anything else replaces).
    Comments stay where they were, and a plain list or mapping that replaces a flow-style
    one (`[a, b]`) is written in flow style too. `file` names the patch in diagnostics.
    """
    check_patch(patch, file)
    work: Any = copy.deepcopy(tree)
    if isinstance(patch, Mapping):
        work = _merge(work, patch)
    else:
        for index, op in enumerate(patch):
            op = copy.deepcopy(dict(op))
            try:
                pointer = _Pointer(op["path"])
                before = pointer.resolve(work, None) if op["op"] in ("replace", "add") else None
                work = jsonpatch.JsonPatch([op], pointer_cls=_Pointer).apply(work, in_place=True)
                if _flow(before) and op["path"]:
                    parent, key = pointer.to_last(work)
                    if op["op"] == "replace" or isinstance(parent, Mapping):
                        parent[key] = _restyle(before, parent[key])
            except Exception as error:  # noqa: BLE001 - jsonpatch and jsonpointer raise several kinds
                line, column = _item_position(patch, index)
                raise PatchError(
                    [Diagnostic(rule="patch-apply", message=f"operation {index} ({op['op']} {op['path']!r}) failed: "
                                f"{_reason(error, op, work)}", path=_pointer_path(op["path"]),
                                hint="the patch is refused as a whole; nothing was changed"
                                if not isinstance(error, jsonpatch.JsonPatchTestFailed)
                                else "the description is not what the patch expects; it may have been patched since",
                                file=file, line=line, column=column)]
                ) from None
    if not isinstance(work, Mapping):
        raise PatchError(
            [Diagnostic(rule="patch-apply", message=f"the patch replaces the whole description with a "
                        f"{type(work).__name__}, not a mapping", file=file)]
        )
    return work if isinstance(work, CommentedMap) else _reread(work, "<patched>")


def _merge(target: Any, patch: Any) -> Any:
    """RFC 7396 MergePatch, changing `target` in place where it is a mapping."""
    if not isinstance(patch, Mapping):
        return _restyle(target, copy.deepcopy(patch))
    if not isinstance(target, MutableMapping):
        target = _restyle(target, CommentedMap())
    for name, value in patch.items():
        key = _key_for(target, name)
        if value is None:
            target.pop(key, None)
            continue
        current = target.get(key)
        merged = _merge(current, value)
        if merged is not current:
            target[key] = merged
    return target


def _flow(node: Any) -> bool:
    return isinstance(node, (CommentedMap, CommentedSeq)) and bool(node.fa.flow_style())


def _restyle(old: Any, new: Any) -> Any:
    """A plain list or dict replacing a flow-style one becomes flow-style too."""
    if not _flow(old) or isinstance(new, (CommentedMap, CommentedSeq)):
        return new
    if isinstance(new, list):
        styled: Any = CommentedSeq(new)
    elif isinstance(new, dict):
        styled = CommentedMap(new)
    else:
        return new
    styled.fa.set_flow_style()
    return styled


def _reason(error: Exception, op: Mapping, doc: Any) -> str:
    if isinstance(error, jsonpatch.JsonPatchTestFailed):
        try:
            actual = _Pointer(op["path"]).resolve(doc)
        except JsonPointerException:
            return str(error)
        return f"the value is {_show(_plain(actual))}, not {_show(_plain(op.get('value')))}"
    text = str(error) or type(error).__name__
    text = re.sub(r"^(member '.*?' not found) in .*$", r"\1", text, flags=re.S)  # not the whole sub-document
    if isinstance(error, (KeyError, IndexError, TypeError)):
        text = f"{type(error).__name__}: {text}"
    return text


def _pointer_path(pointer: str) -> Path:
    try:
        return tuple(int(p) if _DECIMAL.fullmatch(p) else p for p in JsonPointer(pointer).parts)
    except (JsonPointerException, TypeError, AttributeError):
        return ()


def _dump(tree: Any) -> str:
    yaml = _yaml()
    yaml.width = _DUMP_WIDTH
    buffer = io.StringIO()
    yaml.dump(tree, buffer)
    return buffer.getvalue()


def _reread(tree: Any, file: str) -> CommentedMap:
    """The tree as read back from its own dump: positions then match what `diff_text` shows."""
    try:
        return parse_text(_dump(tree), file).tree
    except SourceError as error:
        raise PatchError([Diagnostic(rule="patch-apply", message=f"the patched description cannot be "
                                     f"written as YAML: {error.diagnostic.message}")]) from None
    except Exception as error:  # noqa: BLE001 - e.g. a value ruamel cannot represent
        raise PatchError([Diagnostic(rule="patch-apply", message=f"the patched description cannot be "
                                     f"written as YAML: {error}")]) from None


# --- validating and showing the result ------------------------------------------------


def validate_patched(new_tree: CommentedMap, file: str = "<patched>", state_limit: int = DEFAULT_STATE_LIMIT) -> Validated:
    """Run every check of `hapticop validate` on the patched description.

    The checks run on the tree read back from its YAML dump, so every diagnostic's line
    and column are those of the patched document as `diff_text` and a dump show it (the
    patched tree itself mixes positions from the old file and the patch). Errors raise
    `PatchError` with the validator's own diagnostics (rule ids and messages unchanged);
    warnings stay in the returned report.
    """
    validated = validate_source(Source(file, _reread(new_tree, file)), state_limit, scripted=False)
    if not validated.report.ok:
        errors = [d for d in validated.report.sorted() if d.severity is Severity.ERROR]
        raise PatchError(errors, f"the patched description is invalid ({len(errors)} "
                         f"error{'s' if len(errors) != 1 else ''}): {errors[0].message}")
    return validated


def diff_text(old_tree: Any, new_tree: Any, name: str = "composition.yaml") -> str:
    """A unified diff of the two descriptions as YAML (comments kept); empty when equal."""
    return "".join(
        difflib.unified_diff(
            _dump(old_tree).splitlines(keepends=True),
            _dump(new_tree).splitlines(keepends=True),
            fromfile=f"a/{name}",
            tofile=f"b/{name}",
        )
    )


# --- what the runtime must do ---------------------------------------------------------


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
            "params": _plain(self.params),
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
    ("activity", "block"): "the block of a running activity cannot change live; add an activity with a new name instead",
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
            plan.params[name] = _plain(after.params)
            say(f"activity '{name}': parameters {_param_changes(before.params, after.params)}")

    plan.added_streams = _added(old.streams, new.streams)
    plan.removed_streams = _added(new.streams, old.streams)
    for name in plan.added_streams:
        stream = new.streams[name]
        say(f"stream '{name}' added ({stream.writer} -> {', '.join(stream.readers)})")
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


def _unsupported_fields(plan: ChangePlan, kind: str, path: Path, before: BaseModel, after: BaseModel, live: set[str]) -> None:
    for name, info in type(before).model_fields.items():
        if name in live:
            continue
        if _semantic(getattr(before, name)) != _semantic(getattr(after, name)):
            reason = _REASONS.get((kind, name), f"the {name} of a running {kind} cannot change live")
            plan.unsupported.append((path + (info.alias or name,), reason))


def prepare(
    tree: Mapping,
    patch: list | Mapping,
    *,
    old: Composition | None = None,
    file: str = "<patched>",
    patch_file: str = "<patch>",
    name: str = "composition.yaml",
    state_limit: int = DEFAULT_STATE_LIMIT,
) -> tuple[CommentedMap, Composition, ChangePlan, str]:
    """Apply, validate and plan: (new tree, new composition, plan, diff), or `PatchError`.

    `old` is the running composition (read from `tree` when not given). A plan with
    changes the runtime cannot make live is refused with one 'patch-unsupported'
    diagnostic per change, located in the patched document.
    """
    new_tree = apply_patch(tree, patch, file=patch_file)
    validated = validate_patched(new_tree, file, state_limit)
    new = validated.composition
    if old is None:
        old = load_tree(tree).composition
        if old is None:
            raise PatchError([Diagnostic(rule="patch-invalid", message="the current description is not valid; "
                                         "validate it before patching", file=file)])
    plan = plan_changes(old, new)
    if plan.unsupported:
        source = validated.source
        found = []
        for path, reason in plan.unsupported:
            line, column = source.locate(path, key=True)
            found.append(Diagnostic(rule="patch-unsupported", message=f"{reason}; {RESTART}", path=path,
                                    hint="a running system changes only activity parameters, schedules, "
                                    "activities, streams and stream max_age live",
                                    file=file, line=line, column=column))
        raise PatchError(found)
    return new_tree, new, plan, diff_text(tree, new_tree, name)


# --- small helpers ----------------------------------------------------------------------


def _added(before: Mapping, after: Mapping) -> list[str]:
    return [name for name in after if name not in before]


def _common(before: Mapping, after: Mapping) -> list[str]:
    return [name for name in after if name in before]


def _semantic(value: Any) -> Any:
    """Plain data for comparison, without 'doc' fields (they change nothing at run time)."""
    if isinstance(value, BaseModel):
        return {name: _semantic(getattr(value, name)) for name in type(value).model_fields if name != "doc"}
    if isinstance(value, Mapping):
        return {_plain(k): _semantic(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_semantic(v) for v in value]
    return _plain(value)


def _types(value: Any) -> Any:
    """The shape of a params tree with scalar types: so `true` -> `1` counts as a change."""
    if isinstance(value, Mapping):
        return {str(k): _types(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_types(v) for v in value]
    return type(_plain(value)).__name__


def _plain(value: Any) -> Any:
    """ruamel's round-trip types (CommentedMap, ScalarFloat...) as plain Python values."""
    if isinstance(value, Mapping):
        return {_plain(k): _plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    if isinstance(value, bool) or value is None:
        return value
    if isinstance(value, int):
        return bool(value) if type(value).__name__ == "ScalarBoolean" else int(value)
    if isinstance(value, float):
        return float(value)
    if isinstance(value, str):
        return str(value)
    return value


def _show(value: Any) -> str:
    if value is None:
        return "null"
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, Mapping):
        return "{" + ", ".join(f"{k}: {_show(v)}" for k, v in value.items()) + "}"
    if isinstance(value, list):
        return "[" + ", ".join(_show(v) for v in value) + "]"
    return str(value)


def _flatten(params: Mapping, prefix: str = "") -> dict[str, Any]:
    flat: dict[str, Any] = {}
    for key, value in params.items():
        name = f"{prefix}{key}"
        if isinstance(value, Mapping) and value:
            flat.update(_flatten(value, name + "."))
        else:
            flat[name] = _plain(value)
    return flat


_UNSET = object()


def _param_changes(before: Mapping, after: Mapping) -> str:
    was, now = _flatten(before), _flatten(after)
    changes = []
    for key in list(was) + [k for k in now if k not in was]:
        old_value, new_value = was.get(key, _UNSET), now.get(key, _UNSET)
        if old_value == new_value and type(old_value) is type(new_value):
            continue
        shown_old = "(default)" if old_value is _UNSET else _show(old_value)
        shown_new = "(default)" if new_value is _UNSET else _show(new_value)
        changes.append(f"{key} {shown_old} -> {shown_new}")
    return ", ".join(changes) or "rewritten"


def _schedule(activities: list[str] | None, missing: str) -> str:
    return f"({missing})" if activities is None else "[" + ", ".join(activities) + "]"


def _duration(ns: int | None) -> str:
    from hapticop.composition.units import format_duration

    return "none" if ns is None else format_duration(ns)


def _dotted(path: Path) -> str:
    return ".".join(str(part) for part in path) or "<document>"
