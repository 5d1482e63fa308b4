"""Checks of a composition on several hosts: placement, each network stream's QoS, loops through the network.

A composition with `hosts:` is checked twice: here as a whole (what only the whole shows: a
thread's host, a stream crossing hosts without its QoS, a loop closing through the network), and
then each host's own composition (`hapticop.composition.placement.for_host`) with every ordinary
check, its findings placed in the file that wrote them.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass
from typing import Any

import networkx as nx

from hapticop.composition.description import Composition
from hapticop.composition.diagnostics import Diagnostic
from hapticop.composition.loader import Loaded
from hapticop.composition.placement import BRIDGE, BRIDGE_THREAD, LINK_FIGURES, link_stream, place
from hapticop.composition.units import format_duration
from hapticop.composition.yamlsource import Source

Check = Iterator[Diagnostic]
LOOP_LENGTH = 8  # cycles of the dataflow longer than this are not looked for (their count grows fast)


@dataclass
class HostSource(Source):
    """One host's composition, its findings placed where the whole file wrote them."""

    origin: Source | None = None

    def place(self, diagnostic: Diagnostic, *, key: bool = False) -> Diagnostic:
        return self.origin.place(diagnostic, key=key) if self.origin is not None else super().place(diagnostic)


def placement(composition: Composition) -> Check:
    """Every thread on a declared host, every activity on one host (the mediator on each)."""
    hosts = composition.hosts
    for name, thread in composition.threads.items():
        if thread.host is None:
            yield Diagnostic("host-missing", f"thread '{name}' names no host; with 'hosts:' every thread runs on one",
                             ("threads", name), hint=f"add 'host:' ({', '.join(hosts)})")
        elif thread.host not in hosts:
            yield Diagnostic("host-unknown", f"thread '{name}' is placed on host '{thread.host}', which 'hosts:' "
                             "does not declare", ("threads", name, "host"), hint=f"hosts: {', '.join(hosts)}")
    reserved = {"activities": {BRIDGE}, "threads": {BRIDGE_THREAD}, "streams": set(map(link_stream, LINK_FIGURES))}
    for kind, names in reserved.items():
        for name in sorted(names & set(getattr(composition, kind))):
            yield Diagnostic("host-reserved-name", f"{kind[:-1].replace('ie', 'y')} '{name}' has the name the host "
                             "split gives each host's network bridge (docs/teleop.md): it would be replaced",
                             (kind, name), hint=f"rename it; taken with 'hosts:': {', '.join(sorted(names))}")
    standard = composition.coordination.standard
    shared = set(standard.sources.values()) if standard is not None else set()
    for name, host in hosts.items():
        for i, held in enumerate(host.on_link_lost):
            if held not in shared:
                yield Diagnostic("host-unknown-place", f"host '{name}' would hold place '{held}' while the link is "
                                 "lost, but no flag of another host's activity reaches it", ("hosts", name,
                                 "on_link_lost", i), hint="name a place of coordination.standard.sources"
                                 + (f" ({', '.join(sorted(shared))})" if shared else ""))
    prioritised = sorted(name for name, host in hosts.items() if host.transport == "prioritised")
    for name, host in hosts.items():
        if host.transport == "low_latency" and prioritised:
            yield Diagnostic("host-transport", f"host '{name}' asks for the low-latency transport but host "
                             f"'{prioritised[0]}' does not: Zenoh would use the prioritised one between them "
                             "without a word", ("hosts", name, "transport"),
                             hint="the same 'transport:' on every host")
    where = place(composition)
    for activity, on in where.activity_hosts.items():
        spec = composition.activities.get(activity)
        if len(on) > 1 and (spec is None or spec.block != "mediator"):
            yield Diagnostic("host-split-activity", f"activity '{activity}' is scheduled on hosts "
                             f"{', '.join(sorted(on))}; an activity's state lives on one host",
                             ("activities", activity), hint="schedule it on threads of one host")


def network_qos(composition: Composition) -> Check:
    """A stream between hosts states how it crosses: deadline, what a stale reader does, a bounded queue,
    and never a link that would hold a real-time thread's samples."""
    where = place(composition)
    for name, net in where.network.items():
        stream = composition.streams[name]
        path = ("streams", name)
        qos = stream.network
        readers = ", ".join(f"'{h}'" for h in sorted(net.reader_hosts - {net.writer_host}))
        crossing = f"stream '{name}' crosses from host '{net.writer_host}' to {readers}"
        if qos is None:
            yield Diagnostic("network-qos", f"{crossing} and states no 'network:' QoS", path,
                             hint="add 'network: {deadline: 100ms, stale: zero}' (docs/teleop.md)")
            continue
        if qos.deadline is None:
            yield Diagnostic("network-deadline", f"{crossing} without a 'deadline': a sample delayed without bound "
                             "would be used as if fresh", path + ("network",), hint="e.g. 'deadline: 100ms'")
        if qos.stale is None:
            yield Diagnostic("network-deadline", f"{crossing} without saying what a stale reader does", path +
                             ("network",), hint="'stale: zero' (no sample: a setpoint stops the robot) or 'hold'")
        if qos.keep == "queue" and qos.depth is None:
            yield Diagnostic("network-unbounded", f"{crossing} as a queue without 'depth': it would grow without "
                             "bound while its reader lags", path + ("network", "keep"),
                             hint="'keep: newest' for a state, or a 'depth:'")
        if qos.congestion == "block":
            realtime = sorted(t for a in _activities_of(stream) for t in _threads_of(composition, a)
                              if composition.threads[t].priority is not None)
            if realtime:
                yield Diagnostic("network-blocking", f"{crossing} with 'congestion: block': a full link would hold "
                                 f"the samples of real-time thread '{realtime[0]}' behind it", path +
                                 ("network", "congestion"), hint="'congestion: drop' (keep newest)")


def network_loops(composition: Composition) -> Check:
    """A feedback loop through the network must not need its samples back within one period: a
    network stream on a cycle across hosts whose deadline is no longer than its reader's period
    closes the loop through the network, which only the handle and wheel loops may do, each on its host."""
    where = place(composition)
    flow = nx.DiGraph()
    for name, stream in composition.streams.items():
        for reader in stream.readers:
            flow.add_edge(stream.writer.split(".")[0], reader.split(".")[0], stream=name)
    seen = set()
    for cycle in nx.simple_cycles(flow, length_bound=LOOP_LENGTH):
        first = cycle.index(min(cycle))  # told the same way whichever node the search began at
        cycle = cycle[first:] + cycle[:first]
        for u, v in zip(cycle, cycle[1:] + cycle[:1]):
            name = flow.edges[u, v]["stream"]
            qos = composition.streams[name].network
            if name not in where.network or name in seen or qos is None or qos.deadline is None:
                continue
            periods = [composition.threads[t].period for t in _threads_of(composition, v)]
            if periods and qos.deadline <= max(periods):
                seen.add(name)
                yield Diagnostic(
                    "network-loop", f"the loop {' -> '.join(cycle + cycle[:1])} closes through the network within "
                    f"one period: stream '{name}' must arrive within {format_duration(qos.deadline)}, no longer than "
                    f"the {format_duration(max(periods))} period of '{v}'", ("streams", name, "network", "deadline"),
                    hint="keep the loop's activities on one host; only slower, delay-tolerant loops cross")


def _activities_of(stream: Any) -> set[str]:
    return {stream.writer.split(".")[0], *(r.split(".")[0] for r in stream.readers)}


def _threads_of(composition: Composition, activity: str) -> list[str]:
    return [t for t, spec in composition.threads.items() if any(activity in m for m in spec.schedules.values())]


CHECKS = (placement, network_qos, network_loops)


def port_specs(loaded: Loaded) -> dict[str, dict]:
    """Each network stream's samples as the bridges carry them (dtype, shape, unit): its writer port's,
    or a reader's when the writer names no port it has (that host's own checks then say so)."""
    specs = {}
    for name in place(loaded.composition).network:
        stream = loaded.composition.streams[name]
        for ref, side in ((stream.writer, "outputs"), *((r, "inputs") for r in stream.readers)):
            activity, port = ref.split(".")
            resolved = loaded.activities.get(activity)
            spec = getattr(resolved.interface, side).get(port) if resolved else None
            if spec is not None:
                specs[name] = {"dtype": spec.dtype, "shape": list(spec.shape), "unit": spec.unit}
                break
    return specs
