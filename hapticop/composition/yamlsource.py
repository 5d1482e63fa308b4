"""Reading YAML while remembering where every key and value stood in the file.

ruamel.yaml's round-trip loader keeps line and column for each mapping key, value and
sequence item (and keeps comments, so patched files can be written back unchanged in
spirit). `locate` turns a field path from pydantic or from a structural check into the
position a user should look at.
"""

from __future__ import annotations

import os
import re
import stat
from dataclasses import dataclass
from pathlib import Path as FilePath
from typing import Any

from ruamel.yaml import YAML
from ruamel.yaml.comments import CommentedMap, CommentedSeq
from ruamel.yaml.constructor import DuplicateKeyError
from ruamel.yaml.error import MarkedYAMLError, YAMLError

from hapticop.composition.diagnostics import Diagnostic, Path

# Composition files are written by people; anything this large is a mistake (or a
# generated file that should be split), and parsing it would stall an editor.
MAX_FILE_BYTES = 1 << 20
_HUGE_INTEGER = re.compile(r"(?<![\w.])[-+]?(\d{4301,})(?![\w.])")  # past Python's int(str) limit


class SourceError(Exception):
    """The file could not be read as a YAML mapping; carries one located diagnostic."""

    def __init__(self, diagnostic: Diagnostic):
        super().__init__(diagnostic.message)
        self.diagnostic = diagnostic


@dataclass
class Source:
    """A parsed YAML document and the name of the file it came from."""

    file: str
    tree: CommentedMap
    text: str = ""  # what was parsed: a process-deployed thread rebuilds the system from it

    def locate(self, path: Path, *, key: bool = False) -> tuple[int, int]:
        return locate(self.tree, path, key=key)

    def place(self, diagnostic: Diagnostic, *, key: bool = False) -> Diagnostic:
        line, column = self.locate(diagnostic.path, key=key)
        return diagnostic.located(self.file, line, column)


def round_trip_yaml() -> YAML:
    """The one YAML reader and writer: round trip (comments, positions), no duplicate keys."""
    yaml = YAML(typ="rt")
    yaml.allow_duplicate_keys = False
    return yaml


def _mark_error(file: str, rule: str, message: str, mark, hint: str = "") -> SourceError:
    line = mark.line + 1 if mark is not None else 0
    column = mark.column + 1 if mark is not None else 0
    return SourceError(Diagnostic(rule=rule, message=message, hint=hint, file=file, line=line, column=column))


def parse_text(text: str, file: str = "<string>") -> Source:
    """Parse YAML text into a located tree, or raise `SourceError` with a clean message."""
    if len(text.encode("utf-8", "surrogatepass")) > MAX_FILE_BYTES:
        raise SourceError(
            Diagnostic(
                rule="file-too-large",
                message=f"the file is {len(text.encode('utf-8', 'surrogatepass')) / 1e6:.1f} MB; "
                f"a composition may be at most {MAX_FILE_BYTES // 1024} KiB",
                hint="split large parameter tables into the blocks that use them",
                file=file,
            )
        )
    try:
        tree = round_trip_yaml().load(text)
    except DuplicateKeyError as error:
        raise _mark_error(
            file,
            "duplicate-key",
            f"duplicate key: {error.problem.strip()}" if error.problem else "duplicate key",
            error.problem_mark,
            hint="each name may appear once in a mapping; the second would silently replace the first",
        ) from None
    except MarkedYAMLError as error:
        reason = " ".join(part for part in (error.context, error.problem) if part) or "malformed YAML"
        raise _mark_error(file, "yaml-syntax", f"malformed YAML: {reason}",
                          error.problem_mark or error.context_mark) from None
    except (YAMLError, RecursionError, ValueError, TypeError) as error:
        # ValueError/TypeError: ruamel rejects some scalars (odd timestamps, huge ints) late.
        if huge := _HUGE_INTEGER.search(text):
            line = text.count("\n", 0, huge.start()) + 1
            column = huge.start() - text.rfind("\n", 0, huge.start())
            raise SourceError(Diagnostic(rule="yaml-syntax", file=file, line=line, column=column,
                                         message=f"an integer of {len(huge.group(1))} digits: no value is that long")
                              ) from None
        raise SourceError(Diagnostic(rule="yaml-syntax", message=f"malformed YAML: {error}", file=file)) from None
    if tree is None:
        raise SourceError(
            Diagnostic(
                rule="empty-file",
                message="the file is empty",
                expected="a mapping with at least 'version', 'threads' and 'activities'",
                file=file,
                line=1,
                column=1,
            )
        )
    if not isinstance(tree, CommentedMap):
        raise SourceError(
            Diagnostic(
                rule="top-level-type",
                message=f"the document is a {_yaml_type(tree)}, not a mapping",
                expected="a mapping with at least 'version', 'threads' and 'activities'",
                file=file,
                line=1,
                column=1,
            )
        )
    reject_aliases_of_containers(tree, file)
    return Source(file=file, tree=tree, text=text)


def read_text(path: str | FilePath, what: str = "a composition") -> str:
    """The text of a regular file of at most `MAX_FILE_BYTES`, strictly UTF-8, or `SourceError`.

    The type is checked before and after opening, and the file is opened without blocking,
    so a FIFO, a device or a directory is refused instead of hanging or filling memory.
    """
    file = str(path)

    def refuse(rule: str, message: str, hint: str = "") -> SourceError:
        return SourceError(Diagnostic(rule=rule, message=message, hint=hint, file=file))

    def too_large(size: int) -> SourceError:
        return refuse("file-too-large", f"the file is {size / 1e6:.1f} MB; {what} may be at most "
                      f"{MAX_FILE_BYTES // 1024} KiB", "split large parameter tables into the blocks that use them")

    try:
        mode = os.stat(file).st_mode
        if not stat.S_ISREG(mode):
            raise refuse("file-unreadable", f"cannot read the file: {_kind(mode)}, not a regular file")
        descriptor = os.open(file, os.O_RDONLY | os.O_NONBLOCK | os.O_NOCTTY)
        with os.fdopen(descriptor, "rb") as handle:
            status = os.fstat(handle.fileno())
            if not stat.S_ISREG(status.st_mode):  # replaced between the two looks
                raise refuse("file-unreadable", f"cannot read the file: {_kind(status.st_mode)}, not a regular file")
            if status.st_size > MAX_FILE_BYTES:
                raise too_large(status.st_size)
            raw = handle.read(MAX_FILE_BYTES + 1)
    except OSError as error:
        raise refuse("file-unreadable", f"cannot read the file: {error.strerror or error}") from None
    except ValueError as error:  # a NUL byte in the name
        raise refuse("file-unreadable", f"cannot read the file: {error}") from None
    if len(raw) > MAX_FILE_BYTES:
        raise too_large(len(raw))
    try:
        return raw.decode("utf-8")
    except UnicodeDecodeError as error:
        raise refuse("file-encoding", f"the file is not UTF-8 text (byte {error.start})") from None


def _kind(mode: int) -> str:
    for test, name in ((stat.S_ISDIR, "a directory"), (stat.S_ISFIFO, "a FIFO"), (stat.S_ISCHR, "a character device"),
                       (stat.S_ISBLK, "a block device"), (stat.S_ISSOCK, "a socket")):
        if test(mode):
            return f"it is {name}"
    return "it is a special file"


def read_file(path: str | FilePath) -> Source:
    return parse_text(read_text(path), str(path))


def _yaml_type(value: Any) -> str:
    if isinstance(value, list):
        return "list"
    if isinstance(value, str):
        return "string"
    if isinstance(value, bool):
        return "boolean"
    if isinstance(value, (int, float)):
        return "number"
    return type(value).__name__


# Aliases let a few hundred bytes name billions of values ("billion laughs"): every reader
# after the parser (pydantic, units, JSON Patch, deep copies) walks the tree expanded, so the
# expanded size and the nesting are bounded here, once, for every document the project reads.
MAX_EXPANDED_NODES = 200_000
MAX_NESTING = 64


def reject_aliases_of_containers(tree: Any, file: str) -> None:
    """Refuse recursive anchors, alias expansion past `MAX_EXPANDED_NODES` and deep nesting.

    Each shared node is visited once and its expanded size remembered, so the check itself
    costs the size of the file, not of its expansion.
    """
    sizes: dict[int, int] = {}

    def refuse(node: Any, rule: str, message: str, hint: str = "") -> SourceError:
        line, column = (node.lc.line + 1, node.lc.col + 1) if hasattr(node, "lc") else (0, 0)
        return SourceError(Diagnostic(rule=rule, message=message, hint=hint, file=file, line=line, column=column))

    def size(node: Any, depth: int, stack: set[int]) -> int:
        if not isinstance(node, (CommentedMap, CommentedSeq)):
            return 1
        if id(node) in stack:
            raise refuse(node, "yaml-recursive", "a YAML anchor refers to itself")
        if depth > MAX_NESTING:
            raise refuse(node, "yaml-too-deep", f"the document nests deeper than {MAX_NESTING} levels")
        if id(node) in sizes:
            return sizes[id(node)]
        stack.add(id(node))
        children = [*node.keys(), *node.values()] if isinstance(node, CommentedMap) else node
        total = 1 + sum(size(child, depth + 1, stack) for child in children)
        stack.discard(id(node))
        if total > MAX_EXPANDED_NODES:
            raise refuse(node, "yaml-too-large", f"YAML aliases expand this document past {MAX_EXPANDED_NODES} "
                         "values", hint="an alias may repeat a value, not multiply the document")
        sizes[id(node)] = total
        return total

    size(tree, 0, set())


def locate(tree: Any, path: Path, *, key: bool = False) -> tuple[int, int]:
    """Line and column (1-based) of the value at `path`, or of its key when `key` is set.

    Path segments that do not exist in the tree (pydantic's union tags, or a missing field)
    are skipped, so the answer is the deepest part of the path that does exist.
    """
    node = tree
    position = (1, 1)
    parts = list(path)
    for index, part in enumerate(parts):
        last = index == len(parts) - 1
        if isinstance(node, CommentedMap):
            name = find_key(node, part)
            if name is MISSING:
                continue
            value = node[name]
            if key and last or value is None or isinstance(value, (CommentedMap, CommentedSeq)):
                # A nested block starts on the line after its key, and an empty value has no
                # position of its own: point at the key then.
                line, column = node.lc.key(name)
            else:
                line, column = node.lc.value(name)
            position = (line + 1, column + 1)
            node = node[name]
        elif isinstance(node, CommentedSeq) and isinstance(part, int) and 0 <= part < len(node):
            line, column = node.lc.item(part)
            position = (line + 1, column + 1)
            node = node[part]
    return position


MISSING = object()
"""What `find_key` answers for a key the mapping does not hold."""


def find_key(mapping: CommentedMap, part: Any) -> Any:
    """The key of `mapping` that a path segment means, or `MISSING`."""
    if part in mapping:
        return part
    # YAML integer keys (schedule IDs) arrive from pydantic as ints or as their text.
    for candidate in mapping:
        if str(candidate) == str(part):
            return candidate
    return MISSING


def plain(node: Any) -> Any:
    """The tree as plain dicts, lists and scalars: cheap to pickle and to load without ruamel."""
    if isinstance(node, dict):
        return {key: plain(value) for key, value in node.items()}
    if isinstance(node, list):
        return [plain(value) for value in node]
    if isinstance(node, str):
        return str(node)
    if isinstance(node, bool) or node is None:
        return node
    if isinstance(node, int):
        return int(node)
    if isinstance(node, float):
        return float(node)
    return node
