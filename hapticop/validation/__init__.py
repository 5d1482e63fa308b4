"""`hapticop validate`: every check, on one file, with every finding located.

Order: YAML syntax, then the schema (pydantic models, block parameters), then the
structural checks on the composition graph, then the coordination nets' reachability,
then the file's scripted patches replayed.
"""

from __future__ import annotations

from pathlib import Path

from hapticop.blocks.registry import search_beside
from hapticop.composition.diagnostics import Report
from hapticop.composition.layers import resolve
from hapticop.composition.yamlsource import Source, SourceError, parse_text, read_file
from hapticop.validation.core import Validated, check_source
from hapticop.validation.reachability import DEFAULT_STATE_LIMIT
from hapticop.validation.scripted import scripted_patches

__all__ = ["Validated", "validate_path", "validate_source", "validate_text"]


def validate_source(source: Source, state_limit: int = DEFAULT_STATE_LIMIT, scripted: bool = True) -> Validated:
    """`scripted=False` skips replaying the file's own scripted patches."""
    validated = check_source(source, state_limit)
    loaded = validated.graph.loaded
    if scripted and validated.report.ok and loaded.composition.patches:
        validated.report.extend(source.place(d) for d in scripted_patches(source, loaded, state_limit))
    return validated


def validate_path(path: str | Path, state_limit: int = DEFAULT_STATE_LIMIT) -> Validated:
    try:
        source = resolve(read_file(path))
    except SourceError as error:
        return Validated(Report(str(path), [error.diagnostic]))
    search_beside(path)  # its own blocks may sit beside it
    return validate_source(source, state_limit)


def validate_text(text: str, file: str = "<string>", state_limit: int = DEFAULT_STATE_LIMIT) -> Validated:
    try:
        source = resolve(parse_text(text, file))
    except SourceError as error:
        return Validated(Report(file, [error.diagnostic]))
    return validate_source(source, state_limit)
