"""`hapticop validate`: every check, on one file, with every finding located.

Order: YAML syntax, then the schema (pydantic models, block parameters), then the
structural checks on the composition graph, then the coordination nets' reachability.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from hapticop.description import Composition
from hapticop.diagnostics import Report
from hapticop.graph import CompositionGraph
from hapticop.loader import Loaded, load_tree
from hapticop.validation import coordination, structure
from hapticop.validation.reachability import DEFAULT_STATE_LIMIT
from hapticop.yamlsource import Source, SourceError, parse_text, read_file


@dataclass
class Validated:
    """The outcome for one file: the report, and the graph when the file could be read."""

    report: Report
    source: Source | None = None
    graph: CompositionGraph | None = None

    @property
    def composition(self) -> Composition | None:
        return self.graph.loaded.composition if self.graph and self.report.ok else None


def validate_source(source: Source, state_limit: int = DEFAULT_STATE_LIMIT) -> Validated:
    report = Report(source.file)
    loaded: Loaded = load_tree(source.tree)
    report.extend(source.place(d, key=d.rule == "unknown-key") for d in loaded.diagnostics)
    cg = CompositionGraph(loaded)
    if loaded.composition is not None:
        for check in structure.CHECKS + coordination.CHECKS:
            found = check(cg, state_limit) if check is coordination.reachability else check(cg)
            report.extend(source.place(d) for d in found)
    return Validated(report, source, cg)


def validate_path(path: str | Path, state_limit: int = DEFAULT_STATE_LIMIT) -> Validated:
    try:
        source = read_file(path)
    except SourceError as error:
        return Validated(Report(str(path), [error.diagnostic]))
    return validate_source(source, state_limit)


def validate_text(text: str, file: str = "<string>", state_limit: int = DEFAULT_STATE_LIMIT) -> Validated:
    try:
        source = parse_text(text, file)
    except SourceError as error:
        return Validated(Report(file, [error.diagnostic]))
    return validate_source(source, state_limit)
