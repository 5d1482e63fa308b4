"""Checks of coordination: nets, places, flag maps and the flags they bind.

Every flag must have exactly one writer and at least one reader; a flag map source reads
a flag, a sink writes one. A schedule nobody selects is a warning, a thread the nets start
but never clean an error. Each net is then explored for unbounded places, dead markings
and livelocks (see `reachability`).
"""

from __future__ import annotations

import difflib
from collections import defaultdict
from collections.abc import Iterator

from hapticop.composition import graph as G
from hapticop.composition.diagnostics import Diagnostic, Severity
from hapticop.coordination.petri import Net
from hapticop.validation.reachability import DEFAULT_STATE_LIMIT, Environment, explore

Check = Iterator[Diagnostic]


def _suggest(name: str, candidates) -> str:
    close = difflib.get_close_matches(name, list(candidates), n=1, cutoff=0.6)
    return f"did you mean '{close[0]}'?" if close else ""


def nets_and_places(cg: G.CompositionGraph) -> Check:
    """Flag maps name declared nets; arcs, markings and flag maps name declared places."""
    for node, data in cg.nodes_of("net", declared=False):
        declared = [n[1] for n, _ in cg.nodes_of("net")]
        path = data.get("referenced_at", ("coordination", "flag_maps"))
        yield Diagnostic("unknown-net", f"unknown net '{node[1]}'", path,
                         hint=_suggest(node[1], declared) or "declare it under 'coordination.nets'")
    for node, _ in cg.nodes_of("place", declared=False):
        net_name, place_name = node[1], node[2]
        if cg.g.nodes.get(G.net(net_name), {}).get("declared") is False:
            continue  # the unknown net was reported
        if cg.loaded.is_broken("coordination.nets", net_name):
            continue
        places = [n[2] for n, _ in cg.nodes_of("place") if n[1] == net_name]
        for u, v, data in list(cg.g.in_edges(node, data=True)) + list(cg.g.out_edges(node, data=True)):
            what = {"arc": "arc to", "inhibitor": "inhibitor arc from", "marking": "initial marking of",
                    "terminal": "terminal",
                    "source": "flag map binding to", "sink": "flag map binding to"}[data["kind"]]
            yield Diagnostic("unknown-place", f"{what} undeclared place '{place_name}' of net '{net_name}'",
                             data["path"], hint=_suggest(place_name, places) or "declare it under 'places'")
    for node, data in cg.nodes_of("transition"):
        if not data["spec"].inputs:
            yield Diagnostic("transition-no-input", f"transition '{node[2]}' has no input place, so it is always "
                             "enabled and the net never reaches a steady state", data["path"] + ("in",))
    for node, data in cg.nodes_of("place"):
        if cg.g.degree(node) == 1:  # only the net's 'contains' edge
            yield Diagnostic("place-unused", f"place '{node[2]}' of net '{node[1]}' has no arcs and no flags",
                             data["path"], severity=Severity.WARNING)


def _party_broken(cg: G.CompositionGraph, flag_name: str) -> bool:
    parts = flag_name.split(".")
    if parts[0] == "threads" and len(parts) > 1:
        return cg.loaded.is_broken("threads", parts[1])
    if parts[0] == "flags" and len(parts) > 1:
        return cg.loaded.is_broken("coordination.flags", parts[1])
    return cg.loaded.is_broken("activities", parts[0])


def flags(cg: G.CompositionGraph) -> Check:
    """Known names; one writer each; sources read written flags, sinks write read flags."""
    known = [n[1] for n, _ in cg.nodes_of("flag")]
    writers: dict[str, list] = defaultdict(list)
    readers: dict[str, list] = defaultdict(list)
    for node, data in cg.nodes_of("flag", declared=None):
        for u, _, d in cg.g.in_edges(node, data=True):
            writers[node[1]].append((u, d))
        for _, v, d in cg.g.out_edges(node, data=True):
            readers[node[1]].append((v, d))

    for node, _ in cg.nodes_of("flag", declared=False):
        if _party_broken(cg, node[1]):
            continue
        for _, d in writers[node[1]] + readers[node[1]]:
            yield Diagnostic("unknown-flag", f"unknown flag '{node[1]}'", d["path"],
                             hint=_suggest(node[1], known) or _flag_name_help(node[1]))

    for node, data in cg.nodes_of("flag"):
        name = node[1]
        owner_writes = [u for u, d in writers[name] if d["kind"] == "owns_write"]
        sink_writes = [(u, d) for u, d in writers[name] if d["kind"] == "sink"]
        owner_reads = [v for v, d in readers[name] if d["kind"] == "owns_read"]
        source_reads = [(v, d) for v, d in readers[name] if d["kind"] == "source"]
        info = data.get("info")
        if owner_writes and sink_writes:
            for _, d in sink_writes:
                yield Diagnostic("flag-two-writers", f"flag '{name}' is written by {info.declared_by}; a flag map sink "
                                 "may not write it too", d["path"], hint="sinks write request or coupling flags")
        elif len(sink_writes) > 1:
            for _, d in sink_writes[1:]:
                other = sink_writes[0][1]["flag_map"]
                yield Diagnostic("flag-two-writers", f"flag '{name}' is already written by flag map '{other}'; "
                                 "a flag has one writer", d["path"])
        if source_reads and not owner_writes and not sink_writes:
            for _, d in source_reads:
                who = f"read by {info.declared_by}" if owner_reads else "never written"
                effect = "the mode never holds" if d["mode"] == "mode" else "this source never sees it change"
                yield Diagnostic("flag-no-writer", f"flag '{name}' is {who}: no one writes it, so {effect}",
                                 d["path"])
        if sink_writes and not owner_reads and not source_reads and not owner_writes:
            for _, d in sink_writes:
                yield Diagnostic("flag-no-reader", f"flag '{name}' is read by no one: setting it from a sink "
                                 "has no effect", d["path"])
        converting = [d for _, d in source_reads if d["mode"] == "converting_sources"]
        for d in converting[1:]:
            yield Diagnostic("flag-consumed-twice", f"flag '{name}' is consumed by two converting sources; only one "
                             "would see each event", d["path"], hint="use a tracking source for the second reader")
        if name.startswith("flags.") and not (owner_writes or sink_writes or owner_reads or source_reads):
            yield Diagnostic("flag-unused", f"coupling flag '{name}' is declared but no flag map uses it",
                             data["path"], severity=Severity.WARNING)
        coordination_broken = any(c.startswith("coordination") for c, _ in cg.loaded.broken)
        if owner_reads and not owner_writes and not sink_writes and info and info.declared_by.startswith("activity") \
                and not name.split(".")[1] == "lcsm" and not coordination_broken:
            activity_name, flag_name = name.split(".", 1)
            resolved = cg.loaded.activities.get(activity_name)
            if resolved is not None and flag_name in resolved.block.optional_flags:
                pass  # the block reads it only where there is something to say (see its declaration)
            elif resolved is not None and flag_name in resolved.block.awaits:
                yield Diagnostic("flag-no-writer", f"activity '{activity_name}' waits for flag '{name}' but no flag "
                                 "map writes it, so it would wait for ever", ("activities", activity_name),
                                 hint=f"add a sink for '{name}' to a flag map")
            else:
                yield Diagnostic("flag-no-writer", f"activity '{activity_name}' reads flag '{name}' but no flag map "
                                 "writes it, so it stays false", ("activities", activity_name),
                                 severity=Severity.WARNING, hint=f"add a sink for '{name}' to a flag map")


def start_on_request(cg: G.CompositionGraph) -> Check:
    """An owner that waits for 'request_running' needs a flag map that sends it."""
    if any(c.startswith("coordination") for c, _ in cg.loaded.broken):
        return
    owners = [(f"threads.{n[1]}", d["spec"], d["path"]) for n, d in cg.nodes_of("thread")]
    owners += [(n[1], d["spec"], d["path"]) for n, d in cg.nodes_of("activity")]
    for prefix, spec, path in owners:
        name = f"{prefix}.lcsm.request_running"
        if spec.start == "on_request" and not any(
            d["kind"] == "sink" for _, _, d in cg.g.in_edges(G.flag(name), data=True)
        ):
            yield Diagnostic("start-never-requested", f"'{prefix}' starts on request, but no flag map writes "
                             f"'{name}', so it would never run", path + ("start",),
                             hint=f"add a sink for '{name}', or use 'start: auto'")


def _written_by_sink(cg: G.CompositionGraph, name: str) -> list[dict]:
    node = G.flag(name)
    return [d for _, _, d in cg.g.in_edges(node, data=True) if d["kind"] == "sink"] if node in cg.g else []


def schedules_selected(cg: G.CompositionGraph) -> Check:
    """A schedule other than 0 that no flag map selects: its activities never run.

    A warning, not a refusal: the file is sound otherwise, and a variant may keep a thread
    parked on purpose (a desk keeps the robot's), which `coordination.standard` says with
    `select: {thread: 0}`; the warning is there because the same file is usually a mistake."""
    comp = cg.loaded.composition
    if any(c.startswith("coordination") for c, _ in cg.loaded.broken):
        return
    parked = {t for t, sid in comp.coordination.standard.select.items() if sid == 0} \
        if comp.coordination.standard else set()
    for node, data in cg.nodes_of("thread"):
        name = node[1]
        for sid in sorted(data["spec"].schedules):
            if sid == 0 or name in parked or _written_by_sink(cg, f"threads.{name}.select_schedule.{sid}"):
                continue
            yield Diagnostic("schedule-never-selected", f"schedule {sid} of thread '{name}' is never selected: no flag "
                             f"map writes 'threads.{name}.select_schedule.{sid}', so its activities never run",
                             data["path"] + ("schedules", sid), severity=Severity.WARNING,
                             hint=f"select it from a net (coordination.standard selects schedule 1 of every thread), "
                             f"or say 'select: {{{name}: 0}}' under coordination.standard to keep it parked")


def threads_cleaned(cg: G.CompositionGraph) -> Check:
    """A thread the nets start (a sink writes its 'request_running') but never clean.

    Refused: by starting it the nets took its life cycle over, so its end is theirs too. A
    shutdown that never asks it to clean either waits for it for ever (the run is then stopped
    by force) or leaves it to the runtime once the nets are done, outside the order they were
    written to keep; such a run can end without the results its activities write as they clean
    (the metrics, the picture)."""
    if any(c.startswith("coordination") for c, _ in cg.loaded.broken):
        return
    for node, _ in cg.nodes_of("thread"):
        prefix = f"threads.{node[1]}.lcsm"
        starts = _written_by_sink(cg, f"{prefix}.request_running")
        if starts and not _written_by_sink(cg, f"{prefix}.request_cleaning"):
            yield Diagnostic("thread-never-cleaned", f"the nets start thread '{node[1]}' but never clean it: no flag "
                             f"map writes '{prefix}.request_cleaning', so the nets' shutdown never ends it",
                             starts[0]["path"],
                             hint=f"add a converting sink for '{prefix}.request_cleaning' to the net that cleans the "
                             "threads (coordination.standard does it for the threads it starts)")


def _flag_name_help(name: str) -> str:
    return ("flags are '<activity>.lcsm.<state|progress|request>', '<activity>.<declared flag>', "
            "'threads.<thread>.lcsm.*', 'threads.<thread>.schedule.<id>', "
            "'threads.<thread>.select_schedule.<id>', 'system.shutdown_requested', 'system.exit', "
            f"or 'flags.<name>' declared under coordination.flags (got '{name}')")


def reachability(cg: G.CompositionGraph, state_limit: int = DEFAULT_STATE_LIMIT) -> Check:
    comp = cg.loaded.composition
    if any(c.startswith("coordination") for c, _ in cg.loaded.broken) or any(cg.nodes_of("net", declared=False)):
        return  # with a net or flag map set aside, the others' environment is unknown
    for name, spec in comp.coordination.nets.items():
        referenced = {p for t in spec.transitions.values() for p in (*t.inputs, *t.outputs, *t.inhibitors)}
        referenced |= set(spec.marking) | set(spec.terminal)
        if not referenced <= set(spec.places):
            continue  # the undeclared place was reported; the net cannot be compiled
        if any(not t.inputs for t in spec.transitions.values()):
            continue
        compiled = Net.from_spec(spec, name)
        env = _environment(cg, name)
        analysis = explore(compiled, env, frozenset(spec.terminal), state_limit)
        path = ("coordination", "nets", name)
        if not analysis.complete and not analysis.findings:
            yield Diagnostic("net-state-limit", f"net '{name}': exploration stopped at {analysis.states} markings, "
                             "so boundedness and dead markings are not proven", path, severity=Severity.WARNING,
                             hint="raise --state-limit, or split the net")
        for finding in analysis.findings:
            trace = ", ".join(finding.trace)
            after = f"after [{trace}]" if trace else "in the initial marking"
            marking = _marking_text(finding.marking)
            if finding.kind == "unbounded":
                yield Diagnostic("net-unbounded", f"net '{name}': place '{finding.place}' is unbounded; the steps "
                                 f"[{trace}] reach {marking}, which covers an earlier marking and can repeat",
                                 path + ("places", finding.place),
                                 hint="consume the token again, or guard the producing transition "
                                      "with a place it empties")
            elif finding.kind == "dead":
                yield Diagnostic("net-dead-marking", f"net '{name}': dead marking {marking} {after}; no "
                                 "transition can fire again and no terminal place is marked", path,
                                 hint="add the missing transition, or list the place under 'terminal' if the net "
                                 "is meant to end there")
            elif finding.kind == "stuck":
                yield Diagnostic("net-terminal-unreachable", f"net '{name}': {after}, the marking {marking} "
                                 f"can never reach a terminal place ({', '.join(spec.terminal)})", path,
                                 hint="the net can still fire, but never finishes: check the transitions that "
                                 "lead to the terminal places")
            else:
                yield Diagnostic("net-livelock", f"net '{name}': transitions [{trace}] can fire in a cycle from "
                                 f"{marking} without input, so a coordination step never reaches a steady state", path)


def _marking_text(marking: dict[str, int]) -> str:
    return "{" + ", ".join(f"{p}: {n}" for p, n in marking.items()) + "}" if marking else "{} (empty)"


def _environment(cg: G.CompositionGraph, net_name: str) -> Environment:
    tracking, converting, emits = set(), set(), set()
    labels: dict[str, str] = {}
    for u, v, data in cg.g.edges(data=True):
        if data["kind"] == "source" and v[1] == net_name:
            (tracking if data["mode"] == "tracking_sources" else converting).add(v[2])
            labels[v[2]] = u[1]
        elif data["kind"] == "sink" and u[1] == net_name:
            if data["mode"] == "converting_sinks":
                emits.add(u[2])
            labels[u[2]] = v[1]
    return Environment(frozenset(tracking), frozenset(converting - tracking), frozenset(emits), labels)


CHECKS = (nets_and_places, flags, start_on_request, schedules_selected, threads_cleaned, reachability)
