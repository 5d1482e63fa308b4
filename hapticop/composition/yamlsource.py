"""Reading YAML while remembering where every key and value stood in the file.

ruamel.yaml's round-trip loader keeps line and column for each mapping key, value and
sequence item (and keeps comments, so patched files can be written back unchanged in
spirit). `locate` turns a field path from pydantic or from a structural check into the
position a user should look at.
"""

from __future__ import annotations

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


def read_file(path: str | FilePath) -> Source:
    path = FilePath(path)
    try:
        size = path.stat().st_size
        if size > MAX_FILE_BYTES:
            raise SourceError(
                Diagnostic(
                    rule="file-too-large",
                    message=f"the file is {size / 1e6:.1f} MB; a composition may be at most "
                    f"{MAX_FILE_BYTES // 1024} KiB",
                    hint="split large parameter tables into the blocks that use them",
                    file=str(path),
                )
            )
        raw = path.read_bytes()
    except OSError as error:
        raise SourceError(Diagnostic(rule="file-unreadable", message=f"cannot read the file: {error.strerror}",
                                     file=str(path))) from None
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as error:
        raise SourceError(
            Diagnostic(rule="file-encoding", message=f"the file is not UTF-8 text (byte {error.start})", file=str(path))
        ) from None
    return parse_text(text, str(path))


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


def reject_aliases_of_containers(tree: Any, file: str) -> None:
    """Refuse recursive anchors: a mapping that contains itself would hang every check."""
    seen: set[int] = set()

    def walk(node: Any, depth: int, stack: set[int]) -> None:
        if not isinstance(node, (CommentedMap, CommentedSeq)):
            return
        if id(node) in stack:
            line, column = (node.lc.line + 1, node.lc.col + 1) if hasattr(node, "lc") else (0, 0)
            raise SourceError(
                Diagnostic(rule="yaml-recursive", message="a YAML anchor refers to itself", file=file, line=line,
                           column=column)
            )
        if id(node) in seen:
            return
        seen.add(id(node))
        stack.add(id(node))
        children = node.values() if isinstance(node, CommentedMap) else node
        for child in children:
            walk(child, depth + 1, stack)
        stack.discard(id(node))

    walk(tree, 0, set())


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
