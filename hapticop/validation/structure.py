"""Checks of deployment and dataflow: threads, schedules, activities, ports and streams.

Each check reads the composition graph and yields diagnostics; none raises, so a file's
mistakes are all reported in one run.
"""

from __future__ import annotations

import difflib
from collections import defaultdict
from collections.abc import Iterator

import networkx as nx

from hapticop.composition import graph as G
from hapticop.composition.description import RESERVED_NAMES
from hapticop.composition.diagnostics import Diagnostic, Severity
from hapticop.composition.units import format_duration

Check = Iterator[Diagnostic]


def _suggest(name: str, candidates) -> str:
    close = difflib.get_close_matches(name, list(candidates), n=1, cutoff=0.6)
    return f"did you mean '{close[0]}'?" if close else ""


def unknown_activities(cg: G.CompositionGraph) -> Check:
    declared = [n[1] for n, _ in cg.nodes_of("activity")]
    for node, _ in cg.nodes_of("activity", declared=False):
        for u, v, data in list(cg.g.in_edges(node, data=True)) + list(cg.g.out_edges(node, data=True)):
            if data["kind"] in ("schedules",):
                yield Diagnostic("unknown-activity", f"unknown activity '{node[1]}'", data["path"],
                                 hint=_suggest(node[1], declared) or "declare it under 'activities'")
        for pnode in cg.g.nodes:
            if pnode[0] == "port" and pnode[1] == node[1]:
                for _, _, data in list(cg.g.in_edges(pnode, data=True)) + list(cg.g.out_edges(pnode, data=True)):
                    yield Diagnostic("unknown-activity", f"unknown activity '{node[1]}' in port reference "
                                     f"'{node[1]}.{pnode[2]}'", data["path"],
                                     hint=_suggest(node[1], declared) or "declare it under 'activities'")


def needs(cg: G.CompositionGraph) -> Check:
    """An activity that names another it needs (a device's simulator, a simulator's world) names
    a declared activity whose block provides that: otherwise it would wait for it forever."""
    for u, v, data in cg.edges_of("needs"):
        need = data["need"]
        providers = sorted(n[1] for n, d in cg.nodes_of("activity")
                           if need.provides in d["resolved"].interface.provides)
        why = f" ({need.why})" if need.why else ""
        if not cg.g.nodes[v].get("declared", True):
            hint = _suggest(need.activity, providers) or (
                f"activities that provide it: {', '.join(providers)}" if providers else
                f"declare an activity whose block provides '{need.provides}' ({_builtin_providers(need.provides)})")
            yield Diagnostic("missing-need", f"'{u[1]}' needs an activity '{need.activity}' that provides "
                             f"'{need.provides}'{why}, and none is declared", data["path"], hint=hint)
        elif need.provides not in cg.g.nodes[v]["resolved"].interface.provides:
            hint = f"activities that provide it: {', '.join(providers)}" if providers else (
                f"declare an activity whose block provides '{need.provides}' ({_builtin_providers(need.provides)})")
            yield Diagnostic("missing-need", f"'{u[1]}' needs '{need.activity}' to provide '{need.provides}'{why}, "
                             f"but its block '{cg.g.nodes[v]['spec'].block}' does not", data["path"], hint=hint)
        elif (cg.threads_of(u[1]) and not cg.threads_of(need.activity)  # it runs, and would wait forever
              and not cg.loaded.scheduled_elsewhere(need.activity)):
            yield Diagnostic("missing-need", f"'{u[1]}' needs '{need.activity}'{why}, which is in no thread's "
                             "schedule: it would wait for it forever", data["path"],
                             hint=f"schedule '{need.activity}' on a thread (beside '{u[1]}' for identical reruns)")


def _builtin_providers(kind: str) -> str:
    """The built-in blocks that provide `kind`, for a hint (imports the built-in blocks only)."""
    from hapticop.blocks.registry import BUILTIN, resolve

    names = [name for name in BUILTIN if kind in resolve(name).provides]
    return "built-in: " + ", ".join(names) if names else "no built-in block does"


def reserved_names(cg: G.CompositionGraph) -> Check:
    for node, data in cg.nodes_of("activity"):
        if node[1] in RESERVED_NAMES:
            yield Diagnostic("reserved-name", f"'{node[1]}' cannot name an activity: it begins the names of "
                             f"{'thread' if node[1] == 'threads' else node[1]} flags", data["path"],
                             hint="rename the activity")


def schedules(cg: G.CompositionGraph) -> Check:
    """Schedule 0 exists on every thread; no activity twice in a schedule or on two threads."""
    for node, data in cg.nodes_of("thread"):
        spec = data["spec"]
        if 0 not in spec.schedules:
            yield Diagnostic("schedule-0", f"thread '{node[1]}' has no schedule 0, the one selected at start",
                             data["path"] + ("schedules",), hint="add '0: []' to start with its activities disabled")
        for sid, members in spec.schedules.items():
            seen = set()
            for index, member in enumerate(members):
                if member in seen:
                    yield Diagnostic("schedule-repeat", f"activity '{member}' appears twice in schedule {sid}",
                                     data["path"] + ("schedules", sid, index))
                seen.add(member)
    placed: dict[str, list[tuple[str, tuple]]] = defaultdict(list)
    for u, v, data in cg.edges_of("schedules"):
        placed[v[1]].append((u[1], data["path"]))
    mediators = {name for name, r in cg.loaded.activities.items() if r.spec.block == "mediator"}
    for activity_name, uses in placed.items():
        threads = sorted({t for t, _ in uses})
        if len(threads) > 1 and activity_name not in mediators:  # the mediator has its own rule
            second = next(path for t, path in uses if t == threads[1])
            yield Diagnostic("activity-two-threads",
                             f"activity '{activity_name}' is scheduled on threads '{threads[0]}' and '{threads[1]}'",
                             second, hint="an activity belongs to one thread; its state is not shared between them")
    for node, data in cg.nodes_of("activity"):
        if node[1] not in placed and not cg.loaded.scheduled_elsewhere(node[1]):  # not a follow-on finding
            yield Diagnostic("activity-unscheduled",
                             f"activity '{node[1]}' is in no thread's schedule, so it never runs",
                             data["path"], severity=Severity.WARNING)


def main_thread_and_mediator(cg: G.CompositionGraph) -> Check:
    comp = cg.loaded.composition
    mains = [name for name, spec in comp.threads.items() if spec.deploy == "main"]
    if not mains and not any(cg.loaded.is_broken("threads", n) for n in comp.threads) and not any(
        c == "threads" for c, _ in cg.loaded.broken
    ):
        yield Diagnostic("main-thread", "no thread has 'deploy: main'; the main thread runs the application mediator",
                         ("threads",), hint="mark the mediator's thread with 'deploy: main'")
    for extra in mains[1:]:
        yield Diagnostic("main-thread", f"threads '{mains[0]}' and '{extra}' both have 'deploy: main'; a process has "
                         "one main thread", ("threads", extra, "deploy"))
    mediators = [name for name, r in cg.loaded.activities.items() if r.spec.block == "mediator"]
    if not mediators and not any(c == "activities" for c, _ in cg.loaded.broken):
        yield Diagnostic("mediator", "no activity uses block 'mediator'; every composition has one application "
                         "mediator to own its coordination", ("activities",))
    for extra in mediators[1:]:
        yield Diagnostic("mediator", f"activities '{mediators[0]}' and '{extra}' are both mediators; "
                         "decisions have one owner", ("activities", extra, "block"))
    if len(mains) == 1 and mediators:
        spec = comp.threads[mains[0]]
        for sid, members in spec.schedules.items():
            if mediators[0] not in members:
                yield Diagnostic("mediator", f"schedule {sid} of main thread '{mains[0]}' lacks the mediator "
                                 f"'{mediators[0]}'; it must run in every schedule of the main thread",
                                 ("threads", mains[0], "schedules", sid))
        for u, v, data in cg.g.in_edges(G.activity(mediators[0]), data=True):
            if data["kind"] == "schedules" and u[1] != mains[0]:
                yield Diagnostic("mediator", f"the mediator '{mediators[0]}' is scheduled on thread '{u[1]}'; it "
                                 f"runs only on the main thread '{mains[0]}'", data["path"])


def own_processes(cg: G.CompositionGraph) -> Check:
    """A block that asks for a process of its own (a network session) gets one: 'deploy: process', normal
    scheduling, and no other activity in that process."""
    comp = cg.loaded.composition
    for u, v, data in cg.edges_of("schedules"):
        resolved = cg.loaded.activities.get(v[1])
        why = resolved.block.own_process if resolved is not None else None
        if why is None:
            continue
        spec = comp.threads[u[1]]
        process = spec.process_name(u[1])
        others = sorted({m for t, s in comp.threads.items() if s.process_name(t) == process
                         for members in s.schedules.values() for m in members} - {v[1]}) if process else []
        if process is None or spec.priority is not None or others:
            found = ("it runs in the main process" if process is None else
                     f"thread '{u[1]}' has priority {spec.priority}" if spec.priority is not None else
                     f"its process also runs {', '.join(repr(o) for o in others)}")
            yield Diagnostic("own-process", f"activity '{v[1]}' ({resolved.spec.block}) must run alone in a process "
                             f"of its own at normal scheduling: {found}", data["path"],
                             hint=f"give it a thread with 'deploy: process' and no priority ({why})")


def rates(cg: G.CompositionGraph) -> Check:
    for u, v, data in cg.edges_of("schedules"):
        if cg.g.nodes[v].get("declared") is False:
            continue
        resolved = cg.g.nodes[v]["resolved"]
        rate = resolved.interface.rate
        period = cg.g.nodes[u]["spec"].period
        if rate is not None and not rate.admits(period):
            yield Diagnostic(
                "rate", f"activity '{v[1]}' ({resolved.spec.block}) cannot run at {1e9 / period:.6g} Hz "
                f"(thread '{u[1]}' period {format_duration(period)})", data["path"],
                expected=f"a thread rate of {rate.describe()}", hint=rate.why,
            )
        yield from _period_params(v[1], resolved, u[1], period)


def _period_params(name: str, resolved, thread: str, period_ns: int) -> Check:
    """A parameter that restates the thread's period (a discretisation step in seconds) must agree
    with it: a 1 ms filter run every 2 ms is wrong by a factor of two, silently."""
    for dotted in sorted(resolved.block.period_params):
        value = resolved.params
        for part in dotted.split("."):
            value = getattr(value, part, None)
        if not isinstance(value, (int, float)) or abs(value * 1e9 - period_ns) <= 1e-6 * period_ns:
            continue  # absent with this choice (a force model without it), or right
        yield Diagnostic(
            "period-mismatch", f"activity '{name}': parameter '{dotted}' is {value:g} s, but thread '{thread}' runs "
            f"it every {format_duration(period_ns)}", ("activities", name, "params", *dotted.split(".")),
            expected=f"{period_ns / 1e9:g}", hint=f"set '{dotted}: {period_ns / 1e9:g}', the thread's period")


def streams(cg: G.CompositionGraph) -> Check:
    """Ports exist with the right direction, types agree, one writer per input."""
    for pnode, _ in cg.nodes_of("port", declared=False):
        if cg.g.nodes.get(G.activity(pnode[1]), {}).get("declared") is False:
            continue  # reported as an unknown activity
        ports = cg.loaded.activities[pnode[1]].interface
        for u, v, data in list(cg.g.in_edges(pnode, data=True)) + list(cg.g.out_edges(pnode, data=True)):
            candidates = ports.outputs if data["kind"] == "writes" else ports.inputs
            yield Diagnostic("unknown-port", f"activity '{pnode[1]}' ({cg.loaded.activities[pnode[1]].spec.block}) "
                             f"has no {'output' if data['kind'] == 'writes' else 'input'} port '{pnode[2]}'",
                             data["path"], expected=", ".join(candidates) or "(none)",
                             hint=_suggest(pnode[2], candidates))

    for snode, sdata in cg.nodes_of("stream"):
        spec = sdata["spec"]
        writers = [(u, d) for u, _, d in cg.g.in_edges(snode, data=True) if cg.g.nodes[u].get("declared", True)]
        readers = [(v, d) for _, v, d in cg.g.out_edges(snode, data=True) if cg.g.nodes[v].get("declared", True)]
        writer_port = None
        for wnode, wdata in writers:
            if cg.g.nodes[wnode]["direction"] != "output":
                yield Diagnostic("port-direction", f"'{wnode[1]}.{wnode[2]}' is an input port; a stream is written "
                                 "by an output port", wdata["path"])
            else:
                writer_port = (wnode, cg.g.nodes[wnode]["port"])
        seen = set()
        for rnode, rdata in readers:
            if rnode in seen:
                yield Diagnostic("stream-reader-twice", f"'{rnode[1]}.{rnode[2]}' is listed twice", rdata["path"])
            seen.add(rnode)
            if cg.g.nodes[rnode]["direction"] != "input":
                yield Diagnostic("port-direction", f"'{rnode[1]}.{rnode[2]}' is an output port; a stream is read "
                                 "by input ports", rdata["path"])
                continue
            if writer_port is None:
                continue
            wnode, wport = writer_port
            if spec.ros2 is not None:  # the message, not the generated port, is the reference: validation/ros2.py
                yield from _thread_safety(cg, snode, spec, wnode, rnode, rdata)
                continue
            rport = cg.g.nodes[rnode]["port"]
            for what, a, b in (("dtype", wport.dtype, rport.dtype), ("shape", wport.shape, rport.shape),
                               ("unit", wport.unit, rport.unit)):
                if a != b:
                    yield Diagnostic(
                        f"stream-{what}", f"{what} mismatch: '{wnode[1]}.{wnode[2]}' writes {wport.describe()}, "
                        f"'{rnode[1]}.{rnode[2]}' reads {rport.describe()}", rdata["path"],
                        expected=f"{what} {b!r} as the reader declares", hint="connect ports of the same kind",
                    )
                    break
            yield from _thread_safety(cg, snode, spec, wnode, rnode, rdata)

    for pnode, pdata in cg.nodes_of("port"):
        if pdata["direction"] != "input":
            continue
        incoming = [(u, d) for u, _, d in cg.g.in_edges(pnode, data=True) if d["kind"] == "reads"]
        incoming = list({u: (u, d) for u, d in incoming}.values())  # a reader listed twice is one writer
        if len(incoming) > 1:
            names = sorted(u[1] for u, _ in incoming)
            for u, data in incoming[1:]:
                yield Diagnostic("port-writers", f"input '{pnode[1]}.{pnode[2]}' is written by {len(incoming)} "
                                 f"streams ({', '.join(names)}); an input has one writer", data["path"])
        port_spec = pdata["port"]
        if not incoming and port_spec.required and cg.g.nodes[G.activity(pnode[1])].get("declared", True):
            if any(c == "streams" for c, _ in cg.loaded.broken):
                continue  # the stream that fed it may be the broken one
            yield Diagnostic("input-unconnected", f"required input '{pnode[1]}.{pnode[2]}' "
                             f"({port_spec.describe()}) is not connected", ("activities", pnode[1]),
                             hint="add a stream whose 'to' lists it")


def alternative_inputs(cg: G.CompositionGraph) -> Check:
    """Of inputs declared as alternatives (``Interface.one_of``) exactly one is connected, and a
    parameter that configures one input alone (``Interface.input_params``) is not set while that
    input is unconnected: it would do nothing, and the value that counts is declared elsewhere."""
    if any(c == "streams" for c, _ in cg.loaded.broken):
        return  # the stream that fed an input may be the broken one
    for node, data in cg.nodes_of("activity"):
        name, resolved = node[1], data["resolved"]
        iface = resolved.interface
        for group in iface.one_of:
            connected = [(p, path) for p in group if (path := _fed_by(cg, name, p)) is not None]
            names = " or ".join(f"'{name}.{p}'" for p in group)
            if not connected:
                yield Diagnostic("input-unconnected", f"'{name}' needs one of {names} connected, and none is",
                                 ("activities", name), hint="add a stream whose 'to' lists one of them")
            for p, path in connected[1:]:
                yield Diagnostic("inputs-alternative", f"'{name}.{p}' and '{name}.{connected[0][0]}' are "
                                 f"alternatives (the same input in two forms): connect one of {names}", path)
        for param, port in iface.input_params.items():
            if getattr(resolved.params, param, None) is not None and _fed_by(cg, name, port) is None:
                yield Diagnostic("param-unused", f"'{name}.params.{param}' configures the input '{port}' alone, "
                                 "which is not connected: it would do nothing", ("activities", name, "params", param),
                                 hint=f"declare it on the activity that feeds '{name}' in place of '{port}' "
                                 f"(once), or connect '{name}.{port}'")


def _fed_by(cg: G.CompositionGraph, activity: str, port: str) -> tuple | None:
    """The path of the stream entry that feeds this input, or None."""
    node = G.port(activity, port)
    if node not in cg.g:
        return None
    for _, _, data in cg.g.in_edges(node, data=True):
        if data["kind"] == "reads":
            return data["path"]
    return None


def _thread_safety(cg, snode, spec, wnode, rnode, rdata) -> Check:
    writer_threads = cg.threads_of(wnode[1])
    reader_threads = cg.threads_of(rnode[1])
    if not writer_threads or not reader_threads:
        return
    if writer_threads != reader_threads and spec.policy.sync == "none":
        yield Diagnostic(
            "stream-thread-safety",
            f"stream '{snode[1]}' crosses from thread '{min(writer_threads)}' to '{min(reader_threads)}' "
            "with 'sync: none', which is only safe within one thread",
            ("streams", snode[1], "policy", "sync"), hint="use 'sync: lock_free' (the default)",
        )


def cpus(cg: G.CompositionGraph) -> Check:
    import os

    available = os.cpu_count() or 1
    for node, data in cg.nodes_of("thread"):
        for index, cpu in enumerate(data["spec"].cpus or []):
            if cpu >= available:
                yield Diagnostic("cpu-affinity", f"CPU {cpu} does not exist on this machine ({available} CPUs)",
                                 data["path"] + ("cpus", index), severity=Severity.WARNING)


def dataflow(cg: G.CompositionGraph) -> nx.DiGraph:
    """Where samples can travel: output port -> stream -> input port -> its activity -> its outputs."""
    flow = nx.DiGraph()
    for u, v, _ in list(cg.edges_of("writes")) + list(cg.edges_of("reads")):
        flow.add_edge(u, v)
    for act, pnode, _ in cg.edges_of("has_port"):
        direction = cg.g.nodes[pnode].get("direction")
        if direction == "input":
            flow.add_edge(pnode, act)
        elif direction == "output":
            flow.add_edge(act, pnode)
    return flow


def latencies(cg: G.CompositionGraph) -> Check:
    """Each measured latency runs from an output port to an input port that data can reach."""
    flow = None
    for name, spec in cg.loaded.composition.latencies.items():
        ends = []
        for key, ref, direction in (("from", spec.source, "output"), ("to", spec.sink, "input")):
            path = ("latencies", name, key)
            act, pname = ref.split(".")
            if act not in cg.loaded.activities:
                if act not in cg.loaded.composition.activities:
                    yield Diagnostic("unknown-activity", f"no activity '{act}'", path,
                                     hint=_suggest(act, cg.loaded.composition.activities))
                continue
            ports = getattr(cg.loaded.activities[act].interface, f"{direction}s")
            if pname not in ports:
                yield Diagnostic("unknown-port", f"activity '{act}' has no {direction} port '{pname}'", path,
                                 expected=", ".join(ports) or "(none)", hint=_suggest(pname, ports))
                continue
            ends.append(G.port(act, pname))
        if len(ends) == 2:
            flow = dataflow(cg) if flow is None else flow
            if not (ends[0] in flow and ends[1] in flow and nx.has_path(flow, ends[0], ends[1])):
                yield Diagnostic("latency-unreachable", f"no stream path carries data from '{spec.source}' to "
                                 f"'{spec.sink}', so this latency could never be measured", ("latencies", name),
                                 hint="check the streams between the two activities")


def busy_waits(cg: G.CompositionGraph) -> Check:
    """Spinning holds the GIL: only a loop alone in its process may busy-wait."""
    threads = cg.loaded.composition.threads
    processes: dict[str | None, list[str]] = defaultdict(list)
    for name, spec in threads.items():
        processes[spec.process_name(name)].append(name)
    for name, spec in threads.items():
        mates = [n for n in processes[spec.process_name(name)] if n != name]
        if spec.busy_wait and mates:
            yield Diagnostic("busy-wait-shared", f"thread '{name}' busy-waits in a process it shares with "
                             f"{', '.join(mates)}: the spinning holds the GIL and delays them",
                             ("threads", name, "busy_wait"), severity=Severity.WARNING,
                             hint="a process of its own, or busy_wait: 0")


def recording(cg: G.CompositionGraph) -> Check:
    """The streams `record:` names exist."""
    composition = cg.loaded.composition
    record = composition.record
    if record is None:
        return
    named = [(("record", "streams", i), name) for i, name in enumerate(record.streams)] if isinstance(
        record.streams, list) else []
    named += [(("record", "decimate", name), name) for name in record.decimate]
    for path, name in named:
        if name not in composition.streams:
            yield Diagnostic("unknown-stream", f"'record' names stream '{name}', which is not declared", path,
                             hint=_suggest(name, composition.streams) or "record one of the streams under 'streams'")


CHECKS = (unknown_activities, needs, reserved_names, schedules, main_thread_and_mediator, own_processes, rates,
          streams, alternative_inputs, cpus, latencies, busy_waits, recording)
