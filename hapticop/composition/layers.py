"""A composition that extends another: `extends: hallway.yaml`, then only what differs.

The rest of the file is an RFC 7396 merge patch on the base (mappings merge, `null` deletes,
anything else replaces), so a variant such as the bench names its extra threads and changed
parameters and nothing else, and follows the base when the base changes. Bases may extend
bases. Every finding is still placed in the file that wrote the blamed value: the layer that
holds the deepest part of its path.
"""

from __future__ import annotations

import copy
from dataclasses import dataclass, field, replace
from pathlib import Path as FilePath

from ruamel.yaml.comments import CommentedMap

from hapticop.composition.diagnostics import Diagnostic, Path
from hapticop.composition.documents import dump, merge
from hapticop.composition.yamlsource import MISSING, Source, SourceError, find_key, locate, read_file

MAX_DEPTH = 8


@dataclass
class LayeredSource(Source):
    """The merged document, with the layers it came from (the extending file first)."""

    layers: list[Source] = field(default_factory=list)

    def place(self, diagnostic: Diagnostic, *, key: bool = False) -> Diagnostic:
        owner = max(self.layers, key=lambda layer: _depth(layer.tree, diagnostic.path))  # first wins ties
        line, column = locate(owner.tree, diagnostic.path, key=key)
        above = self.layers[:self.layers.index(owner)]
        change = next((found for layer in above if (found := _change_named(layer, diagnostic.message))), None)
        if change is None:
            return diagnostic.located(owner.file, line, column)
        # A base's line is blamed for what a file above it changed (an activity deleted or replaced):
        # point at the change, and say where the blamed value itself is written.
        layer, path = change
        where = f"what it blames is written at {owner.file}:{line}:{column}; this line changes '{path[-1]}'"
        hint = f"{diagnostic.hint}; {where}" if diagnostic.hint else where
        return replace(diagnostic, hint=hint).located(layer.file, *locate(layer.tree, path, key=True))


ENTRIES = (("threads",), ("activities",), ("streams",), ("modes",), ("coordination", "nets"),
           ("coordination", "flag_maps"))


def _change_named(layer: Source, message: str) -> tuple[Source, Path] | None:
    """The entry (a thread, an activity...) this layer writes that the message names, if any."""
    for collection in ENTRIES:
        entries = layer.tree
        for part in collection:
            entries = entries.get(part) if isinstance(entries, CommentedMap) else None
        for name in entries if isinstance(entries, CommentedMap) else ():
            if f"'{name}'" in message or f"'{name}." in message:
                return layer, (*collection, name)
    return None


def _depth(tree: CommentedMap, path: Path) -> int:
    node, depth = tree, 0
    for part in path:
        if isinstance(node, CommentedMap):
            name = find_key(node, part)
            if name is MISSING:
                break
            node, depth = node[name], depth + 1
        elif isinstance(node, list) and isinstance(part, int) and 0 <= part < len(node):
            node, depth = node[part], depth + 1
        else:
            break
    return depth


def resolve(source: Source, seen: tuple[str, ...] = ()) -> Source:
    """`source` itself, or, if it extends a base, the base with it merged on top."""
    if "extends" not in source.tree:
        return source
    base_name = source.tree["extends"]
    line, column = locate(source.tree, ("extends",))
    if not isinstance(base_name, str) or not base_name.strip():
        raise SourceError(Diagnostic("extends", "'extends' names the file this one builds on", ("extends",),
                                     expected="a path such as 'hallway.yaml'", file=source.file, line=line,
                                     column=column))

    def unreadable(reason: str) -> SourceError:
        shown = base_name.replace("\0", "\\0")  # a NUL byte printed raw would cut the line
        return SourceError(Diagnostic("extends", f"cannot read '{shown}', which this file extends: {reason}",
                                      ("extends",), file=source.file, line=line, column=column))

    try:
        base_path = (FilePath(source.file).parent / base_name).resolve()
    except (OSError, RuntimeError, ValueError) as error:  # a symlink loop, a NUL byte in the name
        raise unreadable(getattr(error, "strerror", None) or str(error)) from None
    if str(base_path) in seen or len(seen) >= MAX_DEPTH:
        raise SourceError(Diagnostic("extends", f"'{base_name}' extends itself (through {len(seen)} files)",
                                     ("extends",), file=source.file, line=line, column=column))
    try:
        base = resolve(read_file(base_path), seen + (str(base_path),))
    except SourceError as error:
        if error.diagnostic.rule == "file-unreadable":
            raise unreadable(error.diagnostic.message.removeprefix("cannot read the file: ")) from None
        raise
    overlay = CommentedMap((k, v) for k, v in source.tree.items() if k != "extends")
    merged = merge(copy.deepcopy(base.tree), overlay)
    layers = [source] + (base.layers if isinstance(base, LayeredSource) else [base])
    return LayeredSource(file=source.file, tree=merged, text=dump(merged), layers=layers)
