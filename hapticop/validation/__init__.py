"""`hapticop validate`: every check, on one file, with every finding located.

Order: YAML syntax, then the schema (pydantic models, block parameters), then the
structural checks on the composition graph, then the coordination nets' reachability.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from hapticop.composition.description import Composition
from hapticop.composition.diagnostics import Diagnostic, Report
from hapticop.composition.graph import CompositionGraph
from hapticop.composition.loader import Loaded, load_tree
from hapticop.validation import coordination, structure
from hapticop.validation.reachability import DEFAULT_STATE_LIMIT
from hapticop.composition.yamlsource import Source, SourceError, parse_text, read_file
from hapticop.composition.layers import resolve


@dataclass
class Validated:
    """The outcome for one file: the report, and the graph when the file could be read."""

    report: Report
    source: Source | None = None
    graph: CompositionGraph | None = None

    @property
    def composition(self) -> Composition | None:
        return self.graph.loaded.composition if self.graph and self.report.ok else None


def validate_source(source: Source, state_limit: int = DEFAULT_STATE_LIMIT, scripted: bool = True) -> Validated:
    """`scripted=False` skips replaying the file's own scripted patches (used on patched copies)."""
    report = Report(source.file)
    loaded: Loaded = load_tree(source.tree)
    report.extend(source.place(d, key=d.rule == "unknown-key") for d in loaded.diagnostics)
    cg = CompositionGraph(loaded)
    if loaded.composition is not None:
        for check in structure.CHECKS + coordination.CHECKS:
            found = check(cg, state_limit) if check is coordination.reachability else check(cg)
            report.extend(source.place(d) for d in found)
        if scripted and report.ok and loaded.composition.patches:
            report.extend(source.place(d) for d in _scripted_patches(source, loaded, state_limit))
    return Validated(report, source, cg)


def _scripted_patches(source: Source, loaded: Loaded, state_limit: int):
    """Replay the scripted patches in time order: each must apply, validate and be live-able."""
    from hapticop.runtime.patching import PatchError, prepare

    tree, composition = source.tree, loaded.composition
    for name, scripted in sorted(composition.patches.items(), key=lambda item: (item[1].at, item[0])):
        try:
            tree, composition, _, _ = prepare(tree, scripted.patch, old=composition, patch_file=f"patches.{name}",
                                              state_limit=state_limit)
        except PatchError as error:
            first = error.diagnostics[0]
            detail = f"{first.dotted_path}: {first.message}" if first.path else first.message
            yield Diagnostic(rule="scripted-patch", message=f"patch '{name}' would be refused: {detail}",
                             path=("patches", name, "patch"))
            return


def validate_path(path: str | Path, state_limit: int = DEFAULT_STATE_LIMIT) -> Validated:
    try:
        source = resolve(read_file(path))
    except SourceError as error:
        return Validated(Report(str(path), [error.diagnostic]))
    return validate_source(source, state_limit)


def validate_text(text: str, file: str = "<string>", state_limit: int = DEFAULT_STATE_LIMIT) -> Validated:
    try:
        source = resolve(parse_text(text, file))
    except SourceError as error:
        return Validated(Report(file, [error.diagnostic]))
    return validate_source(source, state_limit)
