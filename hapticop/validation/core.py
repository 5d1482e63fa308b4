"""Every check of one source, without replaying its scripted patches (they need this to run)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from pathlib import Path

from hapticop.composition.description import Composition
from hapticop.composition.diagnostics import Diagnostic, Report
from hapticop.composition.graph import CompositionGraph
from hapticop.composition.loader import Loaded, load_tree
from hapticop.composition.placement import for_host, place
from hapticop.composition.yamlsource import Source
from hapticop.validation import coordination, hosts, modes, ros2, security, structure
from hapticop.validation.reachability import DEFAULT_STATE_LIMIT


@dataclass
class Validated:
    """The outcome for one file: the report, and the graph when the file could be read.

    A valid one is what the runtime starts from: its source tree and graph are not read or
    built again."""

    report: Report
    source: Source | None = None
    graph: CompositionGraph | None = None
    hosts: dict[str, Validated] = field(default_factory=dict)  # with 'hosts:', each host's own composition

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
    if loaded.composition is not None and loaded.composition.hosts:
        return _check_hosts(source, loaded, cg, report, state_limit)
    if loaded.composition is not None:
        for check in structure.CHECKS + ros2.CHECKS + coordination.CHECKS + modes.CHECKS:
            found = check(cg, state_limit) if check is coordination.reachability else check(cg)
            report.extend(placed(source, loaded, d) for d in found)
        report.extend(_block_findings(source, loaded))
    return Validated(report, source, cg)


def _block_findings(source: Source, loaded: Loaded) -> list[Diagnostic]:
    """Each activity's block on what its parameters name outside the composition (a scene file)."""
    folder = Path(source.file).resolve().parent if source.file and not source.file.startswith("<") else None
    found = []
    for name, activity in loaded.activities.items():
        try:
            findings = activity.block.findings(activity.params, folder)
        except Exception as error:  # noqa: BLE001 - an author's block: its failure is a finding, not a crash
            findings = [Diagnostic("block-findings", f"block '{activity.spec.block}' failed to check its "
                                   f"parameters: {type(error).__name__}: {error}", ("block",))]
        for d in findings:
            if d.file:  # located in the file it blames
                found.append(d)
            else:
                found.append(placed(source, loaded, replace(d, path=("activities", name) + tuple(d.path))))
    return found


def placed(source: Source, loaded: Loaded, diagnostic: Diagnostic) -> Diagnostic:
    """Located in the file; a finding about an expanded entry at the part of `coordination.standard`
    that asked for it, its path still naming the entry as `hapticop expand` prints it."""
    origin = loaded.expansion.origin_of(diagnostic.path)
    if origin is None:
        return source.place(diagnostic)
    at = source.place(replace(diagnostic, path=origin))
    note = f"written out from {'.'.join(map(str, origin))}: `hapticop expand FILE` prints it"
    return replace(at, path=diagnostic.path, hint=f"{diagnostic.hint} ({note})" if diagnostic.hint else note)


def _check_hosts(source: Source, loaded: Loaded, cg: CompositionGraph, report: Report, state_limit: int) -> Validated:
    """The whole file's placement and network streams, then each host's composition with every check."""
    for check in hosts.CHECKS:
        report.extend(source.place(d) for d in check(loaded.composition))
    report.extend(source.place(d) for d in security.check(source, loaded.composition))
    validated = Validated(report, source, cg)
    if not report.ok:
        return validated
    ports = _with_ranges(hosts.port_specs(loaded), loaded)
    directory = security.key_directory(source, loaded.composition)
    for host in loaded.composition.hosts:
        tree = for_host(source.tree, loaded.composition, host, ports, directory)
        part = check_source(hosts.HostSource(file=source.file, tree=tree, text="", origin=source), state_limit)
        part.report.diagnostics = [d for d in part.report.diagnostics
                                   if not _needs_elsewhere(d, loaded.composition, host)]
        report.extend(d for d in part.report.diagnostics if d not in report.diagnostics)
        validated.hosts[host] = part
    return validated


def _with_ranges(ports: dict[str, dict], loaded: Loaded) -> dict[str, dict]:
    """Each network stream's spec with the range all its readers declare (the intersection), if any: the
    receiving bridge refuses a sample outside it before any reader sees it."""
    for name, spec in ports.items():
        low, high = -math.inf, math.inf
        for ref in loaded.composition.streams[name].readers:
            activity, port = ref.split(".")
            resolved = loaded.activities.get(activity)
            declared = resolved.interface.inputs.get(port) if resolved else None
            if declared is not None and declared.range is not None:
                low, high = max(low, declared.range[0]), min(high, declared.range[1])
        if math.isfinite(low) and math.isfinite(high):
            spec["range"] = [low, high]
    return ports


def _needs_elsewhere(diagnostic, composition, host: str) -> bool:
    """A simulator's need met by an activity on another host: the hosts run beside each other in one
    run directory when simulated, so its published facts reach it."""
    path = diagnostic.path
    if diagnostic.rule != "missing-need" or len(path) != 4 or path[0] != "activities":
        return False
    named = composition.activities[path[1]].params.get(path[3])
    return isinstance(named, str) and place(composition).elsewhere(named, host)
