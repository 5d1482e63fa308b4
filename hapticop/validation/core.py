"""Every check of one source, without replaying its scripted patches (they need this to run)."""

from __future__ import annotations

from dataclasses import dataclass, replace

from hapticop.composition.description import Composition
from hapticop.composition.diagnostics import Diagnostic, Report
from hapticop.composition.graph import CompositionGraph
from hapticop.composition.loader import Loaded, load_tree
from hapticop.composition.yamlsource import Source
from hapticop.validation import coordination, modes, structure
from hapticop.validation.reachability import DEFAULT_STATE_LIMIT


@dataclass
class Validated:
    """The outcome for one file: the report, and the graph when the file could be read.

    A valid one is what the runtime starts from: its source tree and graph are not read or
    built again."""

    report: Report
    source: Source | None = None
    graph: CompositionGraph | None = None

    @property
    def composition(self) -> Composition | None:
        return self.graph.loaded.composition if self.graph and self.report.ok else None

    @property
    def flags(self) -> list[str]:
        """Every flag of the composition, in the graph's order (the region's layout)."""
        return [node[1] for node, _ in self.graph.nodes_of("flag")]


def check_source(source: Source, state_limit: int = DEFAULT_STATE_LIMIT) -> Validated:
    """Schema, then the structural checks on the graph, then coordination and reachability."""
    report = Report(source.file)
    loaded: Loaded = load_tree(source.tree)
    report.extend(source.place(d, key=d.rule == "unknown-key") for d in loaded.diagnostics)
    cg = CompositionGraph(loaded)
    if loaded.composition is not None:
        for check in structure.CHECKS + coordination.CHECKS + modes.CHECKS:
            found = check(cg, state_limit) if check is coordination.reachability else check(cg)
            report.extend(placed(source, loaded, d) for d in found)
    return Validated(report, source, cg)


def placed(source: Source, loaded: Loaded, diagnostic: Diagnostic) -> Diagnostic:
    """Located in the file; a finding about an expanded entry at the part of `coordination.standard`
    that asked for it, its path still naming the entry as `hapticop expand` prints it."""
    origin = loaded.expansion.origin_of(diagnostic.path)
    if origin is None:
        return source.place(diagnostic)
    at = source.place(replace(diagnostic, path=origin))
    note = f"written out from {'.'.join(map(str, origin))}: `hapticop expand FILE` prints it"
    return replace(at, path=diagnostic.path, hint=f"{diagnostic.hint} ({note})" if diagnostic.hint else note)
