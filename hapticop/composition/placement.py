"""Hosts: which machine runs what, which streams cross the network, and one host's own composition.

A composition with `hosts:` is one system on several machines. Each host runs a runtime of its
own on the composition `for_host` writes: its threads and their activities, the streams between
them, and a bridge (block `zenoh_bridge`, activity `bridge`, in a process of normal scheduling)
standing in for every port on another host. The coordination is split the same way: a flag the
standard coordination mirrors from another host's activity arrives as one of the bridge's flags,
and the other host's bridge exports the place it tracks (docs/teleop.md).
"""

from __future__ import annotations

import copy
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from hapticop.composition.description import Composition
from hapticop.network.keys import files

BRIDGE = "bridge"
BRIDGE_THREAD = "bridge"
LINK_FIGURES = ("rtt", "jitter", "loss", "offset", "offset_error", "health", "refused", "sessions")
"""The bridge's outputs that tell how the link does: each host's composition gives each a stream of its own
that nobody needs to read (`link_stream`), so they are recorded, plotted and shown by `hapticop status`."""

HEALTH = ("waiting", "up", "degraded", "lost")
"""The bridge's `health` stream: the index of the worst that holds (waiting: the clocks not yet compared)."""


def link_stream(figure: str) -> str:
    """The stream of one of the bridge's link figures: 'bridge_rtt'."""
    return f"{BRIDGE}_{figure}"


@dataclass
class NetworkStream:
    """A stream whose writer and some reader are on different hosts."""

    name: str
    writer_host: str
    reader_hosts: frozenset[str]


@dataclass
class Placement:
    """Every thread's, activity's and stream's host (activities on several hosts are listed apart)."""

    thread_hosts: dict[str, str] = field(default_factory=dict)
    activity_hosts: dict[str, set[str]] = field(default_factory=dict)
    network: dict[str, NetworkStream] = field(default_factory=dict)

    def host_of(self, activity: str) -> str | None:
        hosts = self.activity_hosts.get(activity, set())
        return next(iter(hosts)) if len(hosts) == 1 else None

    def port_host(self, ref: str) -> str | None:
        return self.host_of(ref.split(".", 1)[0])

    def elsewhere(self, activity: str, host: str) -> bool:
        """The activity runs on another host than `host` (so `host`'s composition lacks it)."""
        hosts = self.activity_hosts.get(activity, set())
        return bool(hosts) and host not in hosts


def place(composition: Composition) -> Placement:
    """Where each part of a composition with hosts runs (threads without a host are left out)."""
    placement = Placement()
    for name, thread in composition.threads.items():
        if thread.host is None:
            continue
        placement.thread_hosts[name] = thread.host
        for members in thread.schedules.values():
            for activity in members:
                placement.activity_hosts.setdefault(activity, set()).add(thread.host)
    for name, stream in composition.streams.items():
        writer = placement.port_host(stream.writer)
        readers = frozenset(h for h in map(placement.port_host, stream.readers) if h is not None)
        if writer is not None and readers - {writer}:
            placement.network[name] = NetworkStream(name, writer, readers)
    return placement


def bridge_flag(direction: str, place_name: str) -> str:
    """The bridge's flag carrying a mediator place across: 'in_wheel_fault', 'out_wheel_fault'."""
    return f"{direction}_{place_name.lower()}"


def for_host(tree: Any, composition: Composition, host: str, ports: dict[str, dict],
             keys: Path | None = None) -> Any:
    """The composition `host` runs, as a YAML tree (nodes kept from `tree`, so findings stay located).

    `ports` maps each network stream's name to its writer port's `{dtype, shape, unit}` and, when its
    readers declare one, the `range` they all accept (the receiving bridge refuses samples outside it);
    `keys` is the directory of the link's keys (none: an insecure link)."""
    placement = place(composition)
    out = copy.deepcopy(tree)
    out.pop("hosts", None)
    if isinstance(out.get("ros2"), dict) and out["ros2"].get("host") != host:
        del out["ros2"]  # the ROS 2 node is another host's: its streams come and go over the link (ros2streams)
    if composition.name:
        out["name"] = f"{composition.name}_{host}"
    local_threads = {n for n, h in placement.thread_hosts.items() if h == host}
    for name in list(out.get("threads", {})):
        if name not in local_threads:
            del out["threads"][name]
        else:
            out["threads"][name].pop("host", None)
    local = {a for a, hosts in placement.activity_hosts.items() if host in hosts}
    for name in list(out.get("activities", {})):
        if name not in local:
            del out["activities"][name]

    def is_local(ref: str) -> bool:
        return ref.split(".", 1)[0] in local

    sends, receives = [], []
    for name in list(out.get("streams", {})):
        entry, spec = out["streams"][name], composition.streams[name]
        readers = [r for r in spec.readers if is_local(r)]
        net = placement.network.get(name) if name in ports else None  # no port known: each host checks its part
        if net is None or (net.writer_host != host and host not in net.reader_hosts):
            if is_local(spec.writer):
                entry["to"] = readers
            else:
                del out["streams"][name]
            if is_local(spec.writer) and spec.readers and not readers:
                del out["streams"][name]
            continue
        qos = spec.network.model_dump(mode="json", exclude={"doc"}) if spec.network else {}
        wire = {"stream": name, "host": net.writer_host, "readers": sorted(net.reader_hosts - {net.writer_host}),
                **ports[name], **{k: qos.get(k) for k in
                                                  ("priority", "keep", "depth", "reliability", "congestion")}}
        entry.pop("network", None)
        if net.writer_host == host:
            sends.append(wire)
            entry["to"] = readers + [f"{BRIDGE}.out_{name}"]
        else:
            receives.append(wire)
            entry["from"] = f"{BRIDGE}.in_{name}"
            entry["to"] = readers
            if spec.network is not None and spec.network.stale == "zero":
                deadline = spec.network.deadline
                entry["max_age"] = f"{min(deadline, spec.max_age) if spec.max_age else deadline}ns"
            elif spec.network is not None:
                entry.pop("max_age", None)  # 'hold': the last sample stays in use however old
    exports, imports, ended = _split_standard(out, composition, placement, host, local)
    peers = [e for h, spec in composition.hosts.items() if h != host for e in spec.endpoints]
    emulate = tree["hosts"][host].get("emulate")
    out.setdefault("activities", {})[BRIDGE] = {
        "block": "zenoh_bridge",
        "doc": f"host '{host}': the network streams and coordination flags to and from the other hosts",
        "params": {"host": host, "system": composition.name or "hapticop",
                   "peers": [h for h in composition.hosts if h != host],
                   "listen": list(composition.hosts[host].endpoints), "connect": peers,
                   "send": sends, "receive": receives, "export_flags": exports, "import_flags": imports,
                   "peer_end": ended, "hold_when_lost": list(composition.hosts[host].on_link_lost),
                   "low_latency": composition.hosts[host].transport == "low_latency",
                   **({"tls": {k: str(v) for k, v in vars(files(keys, host)).items()}} if keys is not None else {}),
                   **({"emulate": copy.deepcopy(emulate)} if emulate is not None else {})},
    }
    for figure in LINK_FIGURES:
        out.setdefault("streams", {})[link_stream(figure)] = {
            "from": f"{BRIDGE}.{figure}", "doc": f"the link's {figure.replace('_', ' ')}, as host '{host}' sees it"}
    out.setdefault("threads", {})[BRIDGE_THREAD] = {
        "period": f"{composition.hosts[host].bridge_period}ns", "deploy": "process", "schedules": {0: [BRIDGE]},
        "doc": "normal scheduling: the network never reaches a real-time loop"}
    cpus = composition.hosts[host].bridge_cpus
    if cpus is not None:  # Zenoh's threads start in the bridge's process and keep its cores
        out["threads"][BRIDGE_THREAD]["cpus"] = list(cpus)
    for latency in list(out.get("latencies", {}) or {}):
        spec = composition.latencies[latency]
        if not (is_local(spec.source) and is_local(spec.sink)):
            del out["latencies"][latency]
    for mode in (out.get("modes") or {}).values():
        for activity in list(mode.get("params", {})):
            if activity not in local:
                del mode["params"][activity]
    record = out.get("record")
    if record and isinstance(record.get("streams"), list):
        # the link's figures are recorded whenever the run records, as they were before they were streams
        record["streams"] = [s for s in record["streams"] if s in out["streams"]] + [
            link_stream(f) for f in LINK_FIGURES]
    return out


def _split_standard(out: Any, composition: Composition, placement: Placement, host: str,
                    local: set[str]) -> tuple[list[str], list[str], bool]:
    """Keep this host's part of `coordination.standard`; remote flags become the bridge's.

    Returns the places this host exports, the ones it imports, and whether a peer's end ends it."""
    standard = (out.get("coordination") or {}).get("standard")
    spec = composition.coordination.standard
    if standard is None or spec is None:
        return [], [], False

    def remote(flag: str) -> bool:
        activity = flag.split(".", 1)[0]
        return activity != BRIDGE and activity not in local

    exports: list[str] = []
    imports: list[str] = []
    sources = {}
    for flag, place_name in spec.sources.items():
        if not remote(flag):
            sources[flag] = place_name
            if placement.host_of(flag.split(".", 1)[0]) is not None and flag.split(".", 1)[0] != BRIDGE:
                exports.append(place_name)
        else:
            sources[f"{BRIDGE}.{bridge_flag('in', place_name)}"] = place_name
            imports.append(place_name)
    sinks = {flag: p for flag, p in spec.sinks.items() if not remote(flag)}
    for place_name in exports:
        sinks[f"{BRIDGE}.{bridge_flag('out', place_name)}"] = place_name
    ends = {flag: p for flag, p in spec.ends.items() if not remote(flag)}
    remote_ends = [p for flag, p in spec.ends.items() if remote(flag)]
    if remote_ends:
        ends[f"{BRIDGE}.peer_ended"] = remote_ends[0]
    standard["sources"], standard["sinks"], standard["ends"] = sources, sinks, ends
    standard["wait_for"] = [a for a in spec.wait_for if a in local] + [BRIDGE]
    clean = {stage: [a for a in members if a in local] for stage, members in spec.clean.items()}
    standard["clean"] = {stage: members for stage, members in clean.items() if members}
    standard["clean"]["link"] = [BRIDGE]
    if spec.threads is not None:
        standard["threads"] = [t for t in spec.threads if placement.thread_hosts.get(t) == host]
    standard["select"] = {t: s for t, s in spec.select.items() if placement.thread_hosts.get(t) == host}
    return exports, imports, bool(remote_ends)
