"""A composition that extends another: `extends: hallway.yaml`, then only what differs.

The rest of the file is an RFC 7396 merge patch on the base (mappings merge, `null` deletes,
anything else replaces), so a variant such as the bench names its extra threads and changed
parameters and nothing else, and follows the base when the base changes. Bases may extend
bases. Every finding is still placed in the file that wrote the blamed value: the layer that
holds the deepest part of its path.
"""

from __future__ import annotations

import copy
from dataclasses import dataclass, field
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
        return diagnostic.located(owner.file, line, column)


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
