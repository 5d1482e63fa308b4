"""From a patch document to a validated new description and a plan of live changes.

A running system is changed by a YAML patch: a JSON Patch (RFC 6902, a list of
operations) or a merge patch (RFC 7396, a mapping). The patch is applied to a copy of
the description, the whole result is checked exactly as `hapticop validate` checks a
file, and the two typed compositions are compared into a `ChangePlan` (`changes`) that
says what the runtime must do at a cycle boundary, or what it cannot do without a
restart. Any problem is a `PatchError` carrying located diagnostics; the running
description is never touched.

Names are mapping keys, so JSON Pointers such as `/activities/haptic/params/k1` stay
valid. Schedule IDs are YAML integers: a pointer segment such as `/threads/main/schedules/1`
addresses the integer key 1 (JSON Pointer segments are always text).
"""

from __future__ import annotations

import copy
import re
from collections.abc import Iterator, Mapping
from dataclasses import dataclass, replace
from typing import Any

import jsonpatch
from jsonpointer import JsonPointer, JsonPointerException
from ruamel.yaml.comments import CommentedMap, CommentedSeq

from hapticop.composition.description import Composition
from hapticop.composition.diagnostics import Diagnostic, Path, Severity
from hapticop.composition.documents import diff, dump, is_flow, key_for, merge, restyle
from hapticop.composition.loader import Loaded, load_tree
from hapticop.composition.yamlsource import (
    Source,
    SourceError,
    parse_text,
    reject_aliases_of_containers,
    round_trip_yaml,
)
from hapticop.validation.changes import RESTART, ChangePlan, plain_value, plan_changes, show
from hapticop.validation.core import Validated, check_source
from hapticop.validation.reachability import DEFAULT_STATE_LIMIT

OPERATIONS = ("add", "remove", "replace", "move", "copy", "test")
PATCH_EXPECTED = (
    "a JSON Patch (a list of operations such as '- {op: replace, path: /activities/haptic/params/k1, value: 30.0}') "
    "or a merge patch (a mapping shaped like the part of the description it changes)"
)
_DECIMAL = re.compile(r"0|[1-9][0-9]*")


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
        raise PatchError([Diagnostic(rule="patch-syntax", message=f"cannot read the patch: {error}",
                                     file=file)]) from None


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
        patch = round_trip_yaml().load(text)  # the YAML itself was read once already: only its type was wrong
        if not isinstance(patch, CommentedSeq):
            raise PatchError(
                [Diagnostic(rule="patch-syntax", message=found.message.replace("a mapping", "a list or a mapping"),
                            expected=PATCH_EXPECTED, file=file, line=1, column=1)]
            ) from None
        reject_aliases_of_containers(patch, file)
    check_patch(patch, file)
    return patch



def check_patch(patch: Any, file: str = "<patch>") -> None:
    """Check the shape of a patch (from a file or embedded in a composition) before applying it."""
    if isinstance(patch, Mapping):
        if "op" in patch and "path" in patch:
            line, column = _item_position(patch, None)
            raise PatchError(
                [Diagnostic(rule="patch-syntax", message="this mapping looks like one JSON Patch operation, "
                            "but a mapping is read as a merge patch",
                            hint="write the operation as a list item: '- op: ...'",
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


class _Pointer(JsonPointer):
    """A JSON Pointer that reaches YAML integer keys (schedule IDs) from text segments."""

    def walk(self, doc: Any, part: Any) -> Any:
        return super().walk(doc, key_for(doc, part))

    def to_last(self, doc: Any) -> tuple[Any, Any]:
        if not self.parts:
            return doc, None
        for part in self.parts[:-1]:
            doc = self.walk(doc, part)
        return doc, JsonPointer.get_part(doc, key_for(doc, self.parts[-1]))


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
        work = merge(work, patch)
    else:
        for index, op in enumerate(patch):
            op = copy.deepcopy(dict(op))
            try:
                pointer = _Pointer(op["path"])
                before = pointer.resolve(work, None) if op["op"] in ("replace", "add") else None
                work = jsonpatch.JsonPatch([op], pointer_cls=_Pointer).apply(work, in_place=True)
                if is_flow(before) and op["path"]:
                    parent, key = pointer.to_last(work)
                    if op["op"] == "replace" or isinstance(parent, Mapping):
                        parent[key] = restyle(before, parent[key])
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


def _reason(error: Exception, op: Mapping, doc: Any) -> str:
    if isinstance(error, jsonpatch.JsonPatchTestFailed):
        try:
            actual = _Pointer(op["path"]).resolve(doc)
        except JsonPointerException:
            return str(error)
        return f"the value is {show(plain_value(actual))}, not {show(plain_value(op.get('value')))}"
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


def _pointer_path(pointer: str) -> Path:
    try:
        return tuple(int(p) if _DECIMAL.fullmatch(p) else p for p in JsonPointer(pointer).parts)
    except (JsonPointerException, TypeError, AttributeError):
        return ()


def _reread(tree: Any, file: str) -> CommentedMap:
    """The tree as read back from its own dump: positions then match what `documents.diff` shows."""
    try:
        return parse_text(dump(tree), file).tree
    except SourceError as error:
        raise PatchError([Diagnostic(rule="patch-apply", message=f"the patched description cannot be "
                                     f"written as YAML: {error.diagnostic.message}")]) from None
    except Exception as error:  # noqa: BLE001 - e.g. a value ruamel cannot represent
        raise PatchError([Diagnostic(rule="patch-apply", message=f"the patched description cannot be "
                                     f"written as YAML: {error}")]) from None


# --- validating the result and planning the change -------------------------------------


def validate_patched(new_tree: CommentedMap, file: str = "<patched>",
                     state_limit: int = DEFAULT_STATE_LIMIT) -> Validated:
    """Run every check of `hapticop validate` on the patched description.

    The checks run on the tree read back from its YAML dump, so every diagnostic's line
    and column are those of the patched document as `documents.diff` and a dump show it (the
    patched tree itself mixes positions from the old file and the patch). Errors raise
    `PatchError` with the validator's own diagnostics (rule ids and messages unchanged);
    warnings stay in the returned report.
    """
    validated = check_source(Source(file, _reread(new_tree, file)), state_limit)
    if not validated.report.ok:
        errors = [d for d in validated.report.sorted() if d.severity is Severity.ERROR]
        raise PatchError(errors, f"the patched description is invalid ({len(errors)} "
                         f"error{'s' if len(errors) != 1 else ''}): {errors[0].message}")
    return validated


@dataclass(frozen=True)
class Prepared:
    """A patch applied, validated and planned; unpacks as (tree, composition, plan, diff)."""

    tree: CommentedMap
    loaded: Loaded  # the patched composition, its activities resolved by validation
    plan: ChangePlan
    diff: str

    @property
    def composition(self) -> Composition:
        return self.loaded.composition

    def __iter__(self) -> Iterator[Any]:
        return iter((self.tree, self.composition, self.plan, self.diff))


def prepare(
    tree: Mapping,
    patch: list | Mapping,
    *,
    old: Composition | None = None,
    file: str = "<patched>",
    patch_file: str = "<patch>",
    name: str = "composition.yaml",
    state_limit: int = DEFAULT_STATE_LIMIT,
) -> Prepared:
    """Apply, validate and plan, or raise `PatchError`.

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
        source, expansion = validated.source, validated.graph.loaded.expansion
        found = []
        for path, reason in plan.unsupported:  # a written-out net is located at the declaration that wrote it
            line, column = source.locate(expansion.origin_of(path) or path, key=True)
            found.append(Diagnostic(rule="patch-unsupported", message=f"{reason}; {RESTART}", path=path,
                                    hint="a running system changes only activity parameters, schedules, "
                                    "activities, streams and stream max_age live",
                                    file=file, line=line, column=column))
        raise PatchError(found)
    return Prepared(new_tree, validated.graph.loaded, plan, diff(tree, new_tree, name))
