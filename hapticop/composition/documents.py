"""Descriptions as YAML documents: merged (RFC 7396), written out, and compared line by line.

`extends:` layers and live patches both change a description as a document before it is
read into models; these are the operations they share. Comments and flow style survive.
"""

from __future__ import annotations

import copy
import difflib
import io
import re
from collections.abc import Mapping, MutableMapping
from typing import Any

from ruamel.yaml.comments import CommentedMap, CommentedSeq

from hapticop.composition.yamlsource import round_trip_yaml

DUMP_WIDTH = 4096  # never fold long lines: diffs then show exactly the lines that changed
_DECIMAL = re.compile(r"0|[1-9][0-9]*")


def key_for(mapping: Any, key: Any) -> Any:
    """The mapping key a text segment means: '1' is the integer 1 among integer keys."""
    if isinstance(mapping, Mapping) and isinstance(key, str) and key not in mapping and _DECIMAL.fullmatch(key):
        number = int(key)
        if number in mapping or (mapping and all(isinstance(k, int) and not isinstance(k, bool) for k in mapping)):
            return number
    return key


def merge(target: Any, patch: Any) -> Any:
    """RFC 7396 MergePatch, changing `target` in place where it is a mapping."""
    if not isinstance(patch, Mapping):
        return restyle(target, copy.deepcopy(patch))
    if not isinstance(target, MutableMapping):
        target = restyle(target, CommentedMap())
    for name, value in patch.items():
        key = key_for(target, name)
        if value is None:
            target.pop(key, None)
            continue
        current = target.get(key)
        merged = merge(current, value)
        if merged is not current:
            target[key] = merged
    return target


def is_flow(node: Any) -> bool:
    """Written inline (`[a, b]`, `{k: v}`) in its file."""
    return isinstance(node, (CommentedMap, CommentedSeq)) and bool(node.fa.flow_style())


def restyle(old: Any, new: Any) -> Any:
    """A plain list or dict replacing a flow-style one becomes flow-style too."""
    if not is_flow(old) or isinstance(new, (CommentedMap, CommentedSeq)):
        return new
    if isinstance(new, list):
        styled: Any = CommentedSeq(new)
    elif isinstance(new, dict):
        styled = CommentedMap(new)
    else:
        return new
    styled.fa.set_flow_style()
    return styled


def dump(tree: Any) -> str:
    """The document as YAML text, comments kept, long lines never folded."""
    yaml = round_trip_yaml()
    yaml.width = DUMP_WIDTH
    buffer = io.StringIO()
    yaml.dump(tree, buffer)
    return buffer.getvalue()


def diff(old_tree: Any, new_tree: Any, name: str = "composition.yaml") -> str:
    """A unified diff of the two descriptions as YAML (comments kept); empty when equal."""
    return "".join(
        difflib.unified_diff(
            dump(old_tree).splitlines(keepends=True),
            dump(new_tree).splitlines(keepends=True),
            fromfile=f"a/{name}",
            tofile=f"b/{name}",
        )
    )
